"""Checks the GLB files an export folder wrote onto a user's rig (`mogen ... --rig RIG.bvh` or
`--rig CHARACTER.glb`) in Blender.

Run:

    blender -b --factory-startup --python tests/blender/check_rig_glb.py -- <export_dir> <rig.bvh|rig.glb>

`<export_dir>/export.json` gives per sample a `rig` entry with the GLB on the rig (`glb`) and
probes: the rig node carrying one of our joints at a few frames, `position_m` in our axes
(metres, y up, facing +z, +x the character's left). A GLB is metres and y up whatever the rig's
BVH unit and up axis.

Each file is imported with Blender's own glTF importer into an empty scene at the export's frame
rate (`check_glb.py`'s `import_glb`: export frame k is scene frame k, the skinned body's
armature the one armature), which puts our (x, y, z) at Blender's (x, -z, y). The script checks
that the armature's bones are the rig's nodes under the same names with the same parents (the
hierarchy a BVH rig declares, or a glTF character's skin joints, each under its nearest joint
ancestor), that the animation spans the sample's frames, and that every probed bone's head is
within 1 cm of its probe at its frame.

For a glTF character it also checks that the file carries the character: for each of the
character's skinned meshes a mesh object with as many vertices, deformed by the armature (an
Armature modifier on it, or the armature as its parent), and the character's bind pose: every
bone's rest head within 1 cm of its joint's rest position in the character (node transforms
composed down the tree, the skin's mesh lining up with the bones only there).

It exits 1 with one line per failure, or prints a summary and exits 0.
"""

import json
import sys
from pathlib import Path

import bpy
from mathutils import Matrix, Quaternion, Vector

sys.path.insert(0, str(Path(__file__).parent))
from check_bvh import TOLERANCE_M, exit_with, finish, read_glb, script_args, to_blender  # noqa: E402
from check_glb import animation_span, go_to_export_frame, import_glb  # noqa: E402
from check_rig_bvh import (  # noqa: E402
    bone_tree_failures,
    check_samples,
    node_parents,
    probe_failures,
    rig_hierarchy,
    skin_joints,
)


class Character:
    """What a glTF character (`--rig CHARACTER.glb`) says an export on it must carry beyond its
    bones: their rest positions and its skinned meshes' vertex counts."""

    def __init__(self, path):
        gltf = read_glb(path)
        self.rest = rest_positions(gltf)
        self.meshes = skinned_meshes(gltf)


def node_matrix(node):
    """A glTF node's local transform: its `matrix` (column-major) or its TRS."""
    if "matrix" in node:
        m = node["matrix"]
        return Matrix([m[0:4], m[4:8], m[8:12], m[12:16]]).transposed()
    x, y, z, w = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
    translation, scale = node.get("translation", [0.0, 0.0, 0.0]), node.get("scale", [1.0, 1.0, 1.0])
    return Matrix.LocRotScale(Vector(translation), Quaternion((w, x, y, z)), Vector(scale))


def rest_positions(gltf):
    """{joint name: rest position in the file's axes (m, y up)}: each joint's node transforms
    composed from the scene root down."""
    nodes, up = gltf["nodes"], node_parents(gltf)

    def world(i):
        local = node_matrix(nodes[i])
        return world(up[i]) @ local if i in up else local

    return {nodes[j].get("name", f"node {j}"): world(j).translation for j in skin_joints(gltf)}


def skinned_meshes(gltf):
    """(node name, vertex count) of every node that has a mesh and a skin: the POSITION counts of
    its mesh's primitives, each accessor counted once."""
    accessors, out = gltf["accessors"], []
    for node in gltf["nodes"]:
        if "mesh" in node and "skin" in node:
            positions = {p["attributes"]["POSITION"] for p in gltf["meshes"][node["mesh"]]["primitives"]}
            out.append((node.get("name", f"mesh {node['mesh']}"), sum(accessors[a]["count"] for a in positions)))
    return out


def rest_failures(where, arm, rest):
    """Failures of the bones whose rest head is over 1 cm from the character's rest position of
    their joint (the character's axes, turned to Blender's as the importer does)."""
    failures = []
    for name, position in rest.items():
        bone = arm.data.bones.get(name)
        if bone is None:
            continue  # bone_tree_failures names it
        head = arm.matrix_world @ bone.head_local
        error = (head - to_blender(position)).length
        if error > TOLERANCE_M:
            failures.append(f"{where}: {name}'s rest head is {error * 100:.2f} cm from the character's rest pose")
    return failures


def mesh_failures(where, arm, meshes):
    """Failures unless, for each of the character's skinned `meshes` ((name, vertex count)), the
    scene has its own mesh object with that many vertices deformed by `arm` (an Armature modifier
    on `arm`, or `arm` its parent)."""
    skinned = [
        o for o in bpy.context.scene.objects
        if o.type == "MESH"
        and (o.parent == arm or any(m.type == "ARMATURE" and m.object == arm for m in o.modifiers))
    ]
    counts = sorted(len(o.data.vertices) for o in skinned)
    unmatched = list(counts)
    failures = []
    for name, vertices in meshes:
        if vertices in unmatched:
            unmatched.remove(vertices)
        else:
            failures.append(f"{where}: no mesh deformed by the armature has the {vertices} vertices of the "
                            f"character's {name!r} (those deformed by it have {counts})")
    return failures


def check_sample(root, sample, fps, rig_tree, character):
    """Returns (failures, largest probe error in metres) of one sample's GLB on the rig; the
    `character` (None for a BVH rig) adds its mesh and bind-pose checks."""
    rig = sample.get("rig")
    if rig is None or "glb" not in rig:
        return [f"sample {sample['glb']}: export.json has no rig GLB"], 0.0
    where = rig["glb"]
    try:
        arm, frame_per_export_frame = import_glb(root / where, fps)
    except RuntimeError as error:
        return [f"{where}: {error}"], 0.0
    failures = bone_tree_failures(where, arm, rig_tree)
    if character is not None:
        failures += rest_failures(where, arm, character.rest) + mesh_failures(where, arm, character.meshes)
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
    args = script_args(argv, "check_rig_glb.py", ["<export_dir>", "<rig.bvh|rig.glb>"])
    if args is None:
        return 2
    root, rig_file = args
    rig_tree = rig_hierarchy(rig_file)
    character = Character(rig_file) if rig_file.suffix.lower() == ".glb" else None
    manifest = json.loads((root / "export.json").read_text())
    fps = float(manifest["fps"])
    samples = manifest["samples"]
    if not samples:
        print(f"FAIL: {root / 'export.json'} lists no samples", file=sys.stderr)
        return 1
    failures, lines = check_samples(samples, "glb", lambda sample: check_sample(root, sample, fps, rig_tree, character))
    carried = f", bind pose and skinned meshes of {[n for _, n in character.meshes]} vertices" if character else ""
    return finish(failures, f"OK: {len(samples)} GLB samples on the rig {rig_file.name} ({len(rig_tree)} bones, its "
                            f"names and parents{carried}) import into Blender {bpy.app.version_string} at {fps:g} "
                            f"fps; every probe within {TOLERANCE_M * 100:g} cm:", lines)


if __name__ == "__main__":
    exit_with(main)
