"""Checks the BVH files of an export folder in Blender.

Run:

    blender -b --factory-startup --python tests/blender/check_bvh.py -- <export_dir>

`<export_dir>/export.json` (written by `mogen export`) lists the samples:

    {"axes": "...", "fps": 20.0, "bvh_unit": "metres",
     "samples": [{"label": "...", "frames": 100, "bvh": "sample_0/motion.bvh", ...,
                  "probes": [{"joint": "left_wrist", "frame": 33, "position_m": [x, y, z]}]}]}

`position_m` is a joint of the solved track by forward kinematics, in the project's axes (metres,
y up, the character facing +z, +x its left); frames count from 0. `bvh_unit` ("metres" or
"centimetres") is optional, metres by default.

Each sample's BVH is imported with Blender's own importer (`bpy.ops.import_anim.bvh`) with its
default axes, forward -Z and up Y. That maps our (x, y, z) to Blender's (x, -z, y): y up becomes
Z up, the character faces -Y, and its left stays at +X. BVH frame k is keyed at Blender frame
k + 1 (the importer's `frame_start`). For every sample the script checks that the armature has 22
bones, that the action is keyed on frames 1..frames, that the scene runs at the export's frame rate,
that exactly the pelvis and the six joints with animated offsets (hips, spine1, neck, collars) have
location curves, and that the head of each probed bone (our joint is the bone's head) is within 1 cm
of the probe in world space. It exits 1 with one line per failure, or prints a summary and exits 0.

Those seven joints have position channels. Blender's importer reads them as the exporter means, as
replacing the joint's OFFSET for the frame: the pose location is (channels - OFFSET) in the bone's
rest frame, so the probes below them check the offset animation.

Debian bookworm's Blender 3.4 importer opens the file with mode 'rU', which Python 3.11 rejects;
the importer module's `open` is replaced, while importing, by one that drops the 'U'.
"""

import builtins
import contextlib
import json
import struct
import sys
from pathlib import Path

import bpy
from mathutils import Vector

TOLERANCE_M = 0.01
BONES = 22
TRANSLATED_BONES = {"pelvis", "left_hip", "right_hip", "spine1", "neck", "left_collar", "right_collar"}
METRES_PER_UNIT = {"metres": 1.0, "centimetres": 0.01}


def to_blender(p):
    """Our (x, y, z), y up, facing +z, to Blender's world under forward -Z, up Y: (x, -z, y)."""
    x, y, z = p
    return Vector((x, -z, y))


@contextlib.contextmanager
def open_without_universal_newlines(module):
    """Gives `module` an `open` that drops the mode flag 'U' (removed in Python 3.11)."""

    def patched(file, mode="r", *args, **kwargs):
        return builtins.open(file, mode.replace("U", ""), *args, **kwargs)

    had = "open" in vars(module)
    saved = vars(module).get("open")
    module.open = patched
    try:
        yield
    finally:
        if had:
            module.open = saved
        else:
            del module.open


def import_bvh(path, metres_per_unit, z_up=False):
    """Imports `path` as an armature at the file's frame rate; returns the new armature object.
    Our (x, y, z) lands at Blender's (x, -z, y) either way: a Y-up file with the importer's
    defaults (forward -Z, up Y), a Z-up one, whose axes already are (x, -z, y), unturned (forward
    Y, up Z)."""
    from io_anim_bvh import import_bvh as importer

    before = set(bpy.data.objects)
    with open_without_universal_newlines(importer):
        result = bpy.ops.import_anim.bvh(
            filepath=str(path),
            target="ARMATURE",
            global_scale=metres_per_unit,
            frame_start=1,
            use_fps_scale=False,
            update_scene_fps=True,
            update_scene_duration=True,
            rotate_mode="NATIVE",
            axis_forward="Y" if z_up else "-Z",
            axis_up="Z" if z_up else "Y",
        )
    if result != {"FINISHED"}:
        raise RuntimeError(f"{path}: the BVH importer returned {result}")
    armatures = [o for o in set(bpy.data.objects) - before if o.type == "ARMATURE"]
    if len(armatures) != 1:
        raise RuntimeError(f"{path}: expected one new armature, found {len(armatures)}")
    return armatures[0]


def check_sample(root, sample, fps, metres_per_unit):
    """Returns (failures, largest probe error in metres) of one sample."""
    label = sample.get("label", sample["bvh"])
    where = f"sample {label!r} ({sample['bvh']})"
    path = root / sample["bvh"]
    if not path.is_file():
        return [f"{where}: no file {path}"], 0.0
    arm = import_bvh(path, metres_per_unit)
    failures = []
    bones = arm.data.bones
    if len(bones) != BONES:
        failures.append(f"{where}: {len(bones)} bones, expected {BONES}")
    frames = sample["frames"]
    action = arm.animation_data.action if arm.animation_data else None
    keys = [k.co[0] for c in action.fcurves for k in c.keyframe_points] if action else []
    if not keys:
        failures.append(f"{where}: the armature has no keyframes")
    elif (min(keys), max(keys)) != (1.0, float(frames)):
        failures.append(f"{where}: keyed on frames {min(keys):g}..{max(keys):g}, expected 1..{frames}")
    translated = {c.data_path.split('"')[1] for c in action.fcurves if c.data_path.endswith(".location")} if action else set()
    if translated != TRANSLATED_BONES:
        failures.append(f"{where}: bones with location curves {sorted(translated)}, expected {sorted(TRANSLATED_BONES)}")
    scene = bpy.context.scene
    scene_fps = scene.render.fps / scene.render.fps_base
    if abs(scene_fps - fps) > 1e-3 * fps:
        failures.append(f"{where}: the scene runs at {scene_fps:g} fps, expected {fps:g}")
    worst = 0.0
    for probe in sample["probes"]:
        name, frame = probe["joint"], probe["frame"]
        bone = arm.pose.bones.get(name)
        if bone is None:
            failures.append(f"{where}: no bone {name!r}")
            continue
        if not 0 <= frame < frames:
            failures.append(f"{where}: probe frame {frame} is outside 0..{frames - 1}")
            continue
        scene.frame_set(frame + 1)
        head = arm.matrix_world @ bone.head
        error = (head - to_blender(probe["position_m"])).length
        worst = max(worst, error)
        if error > TOLERANCE_M:
            failures.append(
                f"{where}: {name} at frame {frame} is {error * 100:.2f} cm from the probe "
                f"(Blender {tuple(round(v, 4) for v in head)}, "
                f"expected {tuple(round(v, 4) for v in to_blender(probe['position_m']))})"
            )
    return failures, worst


def main(argv):
    args = script_args(argv, "check_bvh.py", ["<export_dir>"])
    if args is None:
        return 2
    [root] = args
    manifest = root / "export.json"
    if not manifest.is_file():
        print(f"FAIL: {manifest} does not exist", file=sys.stderr)
        return 1
    export = json.loads(manifest.read_text())
    fps = float(export["fps"])
    unit = export.get("bvh_unit", "metres")
    if unit not in METRES_PER_UNIT:
        print(f"FAIL: {manifest}: bvh_unit {unit!r} is not one of {sorted(METRES_PER_UNIT)}", file=sys.stderr)
        return 1
    samples = export["samples"]
    if not samples:
        print(f"FAIL: {manifest} lists no samples", file=sys.stderr)
        return 1
    failures, lines = [], []
    for sample in samples:
        sample_failures, worst = check_sample(root, sample, fps, METRES_PER_UNIT[unit])
        failures += sample_failures
        lines.append(
            f"  {sample.get('label', sample['bvh'])}: {sample['frames']} frames, {len(sample['probes'])} probes, "
            f"largest error {worst * 1000:.3f} mm"
        )
    return finish(failures, f"OK: {len(samples)} BVH samples in {root} import into Blender "
                            f"{bpy.app.version_string} at {fps:g} fps with {BONES} bones; every probe within "
                            f"{TOLERANCE_M * 100:g} cm:", lines)


def read_glb(path):
    """The glTF JSON of the GLB file `path` (a 12-byte header, then the JSON chunk)."""
    data = Path(path).read_bytes()
    magic, _version, _length = struct.unpack_from("<4sII", data, 0)
    json_length, kind = struct.unpack_from("<I4s", data, 12)
    if magic != b"glTF" or kind != b"JSON":
        raise ValueError(f"{path}: not a GLB file")
    return json.loads(data[20 : 20 + json_length])


def script_args(argv, script, names):
    """The arguments after `--` of `blender -b --factory-startup --python tests/blender/<script>
    -- <names>` as paths, or None after printing the usage when their number is not that of
    `names`."""
    args = argv[argv.index("--") + 1:] if "--" in argv else []
    if len(args) != len(names):
        print(f"usage: blender -b --factory-startup --python tests/blender/{script} -- {' '.join(names)}",
              file=sys.stderr)
        return None
    return [Path(a) for a in args]


def finish(failures, summary, lines):
    """Prints one line per failure and returns 1, or the summary and its lines and returns 0."""
    if failures:
        print("\n".join(f"FAIL: {f}" for f in failures), file=sys.stderr)
        return 1
    print(summary)
    print("\n".join(lines))
    return 0


def exit_with(main):
    """Exits with `main(sys.argv)`'s code; an exception is a failure (Blender would print the
    traceback and exit 0)."""
    try:
        code = main(sys.argv)
    except Exception as e:
        import traceback

        traceback.print_exc()
        print(f"FAIL: {type(e).__name__}: {e}", file=sys.stderr)
        code = 1
    sys.exit(code)


if __name__ == "__main__":
    exit_with(main)
