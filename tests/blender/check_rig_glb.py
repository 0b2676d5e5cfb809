"""Checks the GLB files an export folder wrote onto a user's rig (`mogen ... --rig RIG.bvh`) in
Blender.

Run:

    blender -b --factory-startup --python tests/blender/check_rig_glb.py -- <export_dir> <rig.bvh>

`<export_dir>/export.json` gives per sample a `rig` entry with the GLB on the rig (`glb`) and
probes: the rig node carrying one of our joints at a few frames, `position_m` in our axes
(metres, y up, facing +z, +x the character's left). A GLB is metres and y up whatever the rig's
BVH unit and up axis.

Each file is imported with Blender's own glTF importer into an empty scene at the export's frame
rate (`check_glb.py`'s `import_glb`: export frame k is scene frame k, the skinned body's
armature the one armature), which puts our (x, y, z) at Blender's (x, -z, y). The script checks
that the armature's bones are the rig's nodes under the same names with the same parents (its
hierarchy as `<rig.bvh>` declares it), that the animation spans the sample's frames, and that
every probed bone's head is within 1 cm of its probe at its frame. It exits 1 with one line per
failure, or prints a summary and exits 0.
"""

import json
import sys
from pathlib import Path

import bpy

sys.path.insert(0, str(Path(__file__).parent))
from check_bvh import TOLERANCE_M, exit_with, finish, script_args  # noqa: E402
from check_glb import animation_span, go_to_export_frame, import_glb  # noqa: E402
from check_rig_bvh import bone_tree_failures, check_samples, hierarchy, probe_failures  # noqa: E402


def check_sample(root, sample, fps, rig_tree):
    """Returns (failures, largest probe error in metres) of one sample's GLB on the rig."""
    rig = sample.get("rig")
    if rig is None or "glb" not in rig:
        return [f"sample {sample['glb']}: export.json has no rig GLB"], 0.0
    where = rig["glb"]
    try:
        arm, frame_per_export_frame = import_glb(root / where, fps)
    except RuntimeError as error:
        return [f"{where}: {error}"], 0.0
    failures = bone_tree_failures(where, arm, rig_tree)
    span, failure = animation_span(arm, sample["frames"], frame_per_export_frame)
    if failure:
        failures.append(f"{where}: {failure}")
    if span is None:
        return failures, 0.0
    found, worst = probe_failures(
        where, arm, rig["probes"], lambda frame: go_to_export_frame(frame, frame_per_export_frame)
    )
    return failures + found, worst


def main(argv):
    args = script_args(argv, "check_rig_glb.py", ["<export_dir>", "<rig.bvh>"])
    if args is None:
        return 2
    root, rig_file = args
    rig_tree = hierarchy(rig_file)
    manifest = json.loads((root / "export.json").read_text())
    fps = float(manifest["fps"])
    samples = manifest["samples"]
    if not samples:
        print(f"FAIL: {root / 'export.json'} lists no samples", file=sys.stderr)
        return 1
    failures, lines = check_samples(samples, "glb", lambda sample: check_sample(root, sample, fps, rig_tree))
    return finish(failures, f"OK: {len(samples)} GLB samples on the rig {rig_file.name} ({len(rig_tree)} bones, its "
                            f"names and parents) import into Blender {bpy.app.version_string} at {fps:g} fps; every "
                            f"probe within {TOLERANCE_M * 100:g} cm:", lines)


if __name__ == "__main__":
    exit_with(main)
