"""Checks the motions an export folder wrote onto a user's rig (`mogen ... --rig RIG.bvh`) in
Blender.

Run:

    blender -b --factory-startup --python tests/blender/check_rig_bvh.py -- <export_dir> <rig.bvh|rig.glb>

`<export_dir>/export.json` gives per sample a `rig` entry: the BVH on the rig (`bvh`), its unit
(`units_per_metre`), whether it is Z-up (`z_up`), and probes: the rig node carrying one of our
joints at a few frames, `position_m` in our axes (metres, y up, facing +z, +x the character's
left).

Each file is imported with Blender's own BVH importer, scaled to metres, with axes that put our
(x, y, z) at Blender's (x, -z, y) whatever the file's up axis: forward -Z, up Y for a Y-up file
(the importer's defaults), forward Y, up Z (no turn) for a Z-up one, whose file axes already are
(x, -z, y). The script checks that the armature's bones are the rig's nodes under the same names
with the same parents (the hierarchy a BVH rig declares, or a glTF character's skin joints, each
under its nearest joint ancestor), that the action is keyed on every frame, and that every probed
bone's head is within 1 cm of its probe. It exits 1 with one line per failure, or prints a summary
and exits 0.
"""

import json
import sys
from pathlib import Path

import bpy

sys.path.insert(0, str(Path(__file__).parent))
from check_bvh import TOLERANCE_M, exit_with, finish, import_bvh, read_glb, script_args, to_blender  # noqa: E402


def hierarchy(path):
    """{node name: parent name or None} of a BVH file's HIERARCHY (End Sites left out)."""
    parents, stack, pending = {}, [], None
    for line in Path(path).read_text().splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] == "MOTION":
            break
        if words[0] in ("ROOT", "JOINT"):
            pending = words[1]
            parents[pending] = stack[-1] if stack else None
        elif words[0] == "End":
            pending = None
        elif words[0] == "{":
            stack.append(pending)
        elif words[0] == "}":
            stack.pop()
    return parents


def skin_joints(gltf):
    """The indices of the nodes that a skin of `gltf` names as a joint, in file order."""
    return sorted({j for skin in gltf.get("skins", []) for j in skin["joints"]})


def node_parents(gltf):
    """{node index: its parent's index} of `gltf`'s node tree."""
    return {c: i for i, node in enumerate(gltf["nodes"]) for c in node.get("children", [])}


def skin_hierarchy(gltf):
    """{joint name: parent name or None} of `gltf`'s skin joints, each under its nearest ancestor
    that is a joint (the armature's node above them, and nodes between joints, left out)."""
    joints, up, nodes = set(skin_joints(gltf)), node_parents(gltf), gltf["nodes"]

    def joint_parent(i):
        i = up.get(i)
        while i is not None and i not in joints:
            i = up.get(i)
        return None if i is None else nodes[i].get("name", f"node {i}")

    return {nodes[j].get("name", f"node {j}"): joint_parent(j) for j in skin_joints(gltf)}


def rig_hierarchy(path):
    """{node name: parent name or None} of the rig file `path`: a BVH's HIERARCHY, or the skin
    joints of a glTF character (.glb)."""
    return skin_hierarchy(read_glb(path)) if Path(path).suffix.lower() == ".glb" else hierarchy(path)


def bone_tree_failures(where, arm, rig_tree):
    """A failure (a list of at most one) unless the bones of `arm` are the nodes of `rig_tree`
    ({name: parent name}) under the same names with the same parents."""
    bones = {b.name: (b.parent.name if b.parent else None) for b in arm.data.bones}
    if bones == rig_tree:
        return []
    missing = sorted(set(rig_tree) - set(bones))
    extra = sorted(set(bones) - set(rig_tree))
    moved = sorted(n for n in set(bones) & set(rig_tree) if bones[n] != rig_tree[n])
    return [f"{where}: bones differ from the rig's nodes (missing {missing}, extra {extra}, other parent {moved})"]


def probe_failures(where, arm, probes, go_to_frame):
    """Failures of the rig probes whose bone head in `arm` is over 1 cm from `position_m` (our
    axes) at the probe's frame, which `go_to_frame(frame)` sets; and the largest distance, m."""
    failures, worst = [], 0.0
    for probe in probes:
        bone = arm.pose.bones.get(probe["node"])
        if bone is None:
            failures.append(f"{where}: no bone {probe['node']!r}")
            continue
        go_to_frame(probe["frame"])
        error = ((arm.matrix_world @ bone.head) - to_blender(probe["position_m"])).length
        worst = max(worst, error)
        if error > TOLERANCE_M:
            failures.append(f"{where}: {probe['node']} ({probe['joint']}) at frame {probe['frame']} is "
                            f"{error * 100:.2f} cm from the probe")
    return failures, worst


def check_sample(root, sample, rig_tree):
    rig = sample.get("rig")
    if rig is None:
        return [f"sample {sample['bvh']}: export.json has no rig entry"], 0.0
    where = rig["bvh"]
    arm = import_bvh(root / rig["bvh"], 1.0 / rig["units_per_metre"], rig["z_up"])
    failures = bone_tree_failures(where, arm, rig_tree)
    frames = sample["frames"]
    action = arm.animation_data.action if arm.animation_data else None
    keys = [k.co[0] for c in action.fcurves for k in c.keyframe_points] if action else []
    if not keys or (min(keys), max(keys)) != (1.0, float(frames)):
        failures.append(f"{where}: keyed on frames {keys and (min(keys), max(keys))}, expected 1..{frames}")
    found, worst = probe_failures(where, arm, rig["probes"], lambda frame: bpy.context.scene.frame_set(frame + 1))
    return failures + found, worst


def check_samples(samples, kind, check):
    """Runs `check(sample)` -> (failures, largest probe error in metres) on every sample: all the
    failures, and one line per sample naming its rig file of `kind` ("bvh" or "glb")."""
    failures, lines = [], []
    for sample in samples:
        sample_failures, worst = check(sample)
        failures += sample_failures
        lines.append(f"  {sample.get('rig', {}).get(kind)}: {sample['frames']} frames, largest probe error "
                     f"{worst * 1000:.3f} mm")
    return failures, lines


def main(argv):
    args = script_args(argv, "check_rig_bvh.py", ["<export_dir>", "<rig.bvh|rig.glb>"])
    if args is None:
        return 2
    root, rig_file = args
    rig_tree = rig_hierarchy(rig_file)
    samples = json.loads((root / "export.json").read_text())["samples"]
    failures, lines = check_samples(samples, "bvh", lambda sample: check_sample(root, sample, rig_tree))
    return finish(failures, f"OK: {len(samples)} samples on the rig {rig_file.name} ({len(rig_tree)} bones, its "
                            f"names and parents) import into Blender {bpy.app.version_string}; every probe within "
                            f"{TOLERANCE_M * 100:g} cm:", lines)


if __name__ == "__main__":
    exit_with(main)
