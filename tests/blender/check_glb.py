"""Checks the GLB files of a `mogen export` folder in Blender.

Run:
    blender -b --factory-startup --python tests/blender/check_glb.py -- <export_dir>

For every sample listed in `<export_dir>/export.json` it imports the GLB with Blender's own glTF
importer into an empty scene whose frame rate is the export's, and checks:
- the armature has 22 bones, one per joint name, whose rest heads are the joints of the file's rest
  pose (node translations summed down the tree);
- the animation spans `frames` frames: the importer puts time t (s) at scene frame t * scene fps,
  so with the scene at the export's rate frame k of the export is scene frame k;
- every probe joint's world position at its frame is within 1 cm of `position_m` (the pelvis, hips,
  spine1, neck and collars have translation channels, so the probes below them check those too).

Axes: the export's are glTF's (metres, y up); Blender's importer turns them to z up, so a point
(x, y, z) of the export is (x, -z, y) in Blender.

Exits 1 with one line per failure, or prints a summary and exits 0.
"""

import json
import math
import sys
from pathlib import Path

import bpy

sys.path.insert(0, str(Path(__file__).parent))
from check_bvh import read_glb, script_args  # noqa: E402

try:
    import numpy
except ImportError:
    sys.exit("GLB check FAILED: Blender's glTF importer needs NumPy in Blender's Python (Debian: apt-get install python3-numpy)")
# Blender 3.4's glTF importer uses `numpy.bool`, which NumPy 1.24 removed (Debian ships the two together).
if "bool" not in vars(numpy):
    numpy.bool = bool

JOINTS = 22
TOLERANCE_M = 0.01


def to_blender(p):
    """A point in the export's axes (y up) in Blender's (z up)."""
    return (p[0], -p[2], p[1])


def distance(a, b):
    return math.dist(tuple(a), tuple(b))


def glb_rest_joints(path):
    """Rest position (export axes, m) of every node in the GLB's skin, by name."""
    gltf = read_glb(path)
    nodes = gltf["nodes"]
    parent = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}

    def position(i):
        own = nodes[i].get("translation", [0.0, 0.0, 0.0])
        if i not in parent:
            return own
        # Rest rotations are the identity, so positions add up along the tree.
        up = position(parent[i])
        return [a + b for a, b in zip(up, own)]

    return {nodes[j]["name"]: position(j) for j in gltf["skins"][0]["joints"]}


def import_glb(path, fps):
    """Imports the GLB `path` with Blender's glTF importer into an empty scene running at the
    export's `fps`; returns its one armature and the scene frames per export frame. The importer
    puts time t (s) at scene frame t * the scene's integer `render.fps`, so export frame k is
    scene frame k at a whole rate."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = round(fps)
    scene.render.fps_base = 1.0
    result = bpy.ops.import_scene.gltf(filepath=str(path), bone_heuristic="TEMPERANCE")
    if "FINISHED" not in result:
        raise RuntimeError(f"importing {path} failed: {result}")
    armatures = [o for o in scene.objects if o.type == "ARMATURE"]
    if len(armatures) != 1:
        raise RuntimeError(f"{len(armatures)} armatures in {path}, expected 1")
    return armatures[0], scene.render.fps / fps


def animation_span(armature, frames, frame_per_export_frame):
    """The scene frames `armature`'s action spans and a failure (or None) unless it spans the
    export's `frames` frames."""
    action = armature.animation_data.action if armature.animation_data else None
    if action is None:
        return None, "the armature has no animation"
    start, end = action.frame_range
    expected_end = (frames - 1) * frame_per_export_frame
    if abs(start) > 1e-3 or abs(end - expected_end) > 1e-3:
        return (start, end), f"animation spans scene frames {start:g}-{end:g}, expected 0-{expected_end:g} ({frames} frames)"
    return (start, end), None


def go_to_export_frame(frame, frame_per_export_frame):
    """Sets the scene to export frame `frame` (from 0), between scene frames where it falls there."""
    at = frame * frame_per_export_frame
    bpy.context.scene.frame_set(int(math.floor(at)), subframe=at - math.floor(at))


def check_sample(export_dir, fps, sample):
    """Failures (strings) and a summary line of one sample."""
    label = sample["label"]
    path = export_dir / sample["glb"]
    failures = []
    try:
        armature, frame_per_export_frame = import_glb(path, fps)
    except RuntimeError as error:
        return [f"{label}: {error}"], ""
    bones = armature.data.bones
    if len(bones) != JOINTS:
        failures.append(f"{label}: {len(bones)} bones, expected {JOINTS}")

    rest_error = 0.0
    for name, position in glb_rest_joints(path).items():
        bone = bones.get(name)
        if bone is None:
            failures.append(f"{label}: no bone `{name}`")
            continue
        head = armature.matrix_world @ bone.head_local
        rest_error = max(rest_error, distance(head, to_blender(position)))
    if rest_error > TOLERANCE_M:
        failures.append(f"{label}: rest bone heads are up to {rest_error:.4f} m from the file's joints")

    frames = sample["frames"]
    span, failure = animation_span(armature, frames, frame_per_export_frame)
    if span is None:
        return failures + [f"{label}: {failure}"], ""
    if failure:
        failures.append(f"{label}: {failure} at {fps:g} fps")
    start, end = span

    probe_error = 0.0
    for probe in sample["probes"]:
        bone = armature.pose.bones.get(probe["joint"])
        if bone is None:
            failures.append(f"{label}: no pose bone `{probe['joint']}`")
            continue
        go_to_export_frame(probe["frame"], frame_per_export_frame)
        head = armature.matrix_world @ bone.head
        error = distance(head, to_blender(probe["position_m"]))
        probe_error = max(probe_error, error)
        if error > TOLERANCE_M:
            failures.append(
                f"{label}: `{probe['joint']}` at frame {probe['frame']} is at {tuple(round(x, 4) for x in head)} "
                f"in Blender, expected {tuple(round(x, 4) for x in to_blender(probe['position_m']))} "
                f"({error:.4f} m apart)"
            )
    summary = (
        f"{label}: {len(bones)} bones, scene frames {start:g}-{end:g} ({frames} frames), rest heads within "
        f"{rest_error:.1e} m, {len(sample['probes'])} probes within {probe_error:.1e} m"
    )
    return failures, summary


def main():
    args = script_args(sys.argv, "check_glb.py", ["<export_dir>"])
    if args is None:
        sys.exit(2)
    [export_dir] = args
    manifest = json.loads((export_dir / "export.json").read_text())
    fps = float(manifest["fps"])
    failures, summaries = [], []
    for sample in manifest["samples"]:
        found, summary = check_sample(export_dir, fps, sample)
        failures.extend(found)
        summaries.append(summary)
    if not manifest["samples"]:
        failures.append(f"{export_dir / 'export.json'} lists no samples")
    if failures:
        print("GLB check FAILED:")
        for line in failures:
            print("  " + line)
        sys.exit(1)
    print(f"GLB check passed: {len(summaries)} samples at {fps:g} fps (Blender {bpy.app.version_string})")
    for line in summaries:
        print("  " + line)


if __name__ == "__main__":
    try:
        main()
    except SystemExit:
        raise
    except Exception as error:  # Blender exits 0 after an uncaught script error; make it fail.
        print(f"GLB check FAILED: {type(error).__name__}: {error}")
        sys.exit(1)
