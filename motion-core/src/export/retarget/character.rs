//! A user's skinned character (glTF 2.0: a `.glb`, or a `.gltf` with its buffers and images
//! inline or in files beside it) as a rig: the joints of its skin at their bind pose, and its
//! document kept whole (meshes, materials, textures, extensions) to carry the motion as a new
//! animation.
//!
//! **Bind pose.** Joint `i`'s bind world matrix is `B_i = IBM_i⁻¹` (the inverse of its inverse
//! bind matrix), or its node's world matrix in the document when the skin has none;
//! `B_i = T(b_i) · A_i` with `b_i` its position (file units, glTF's axes, which are ours) and
//! `A_i` its linear part (its bone frame's rotation and any scale). The rig's nodes are the
//! joints of one tree (the skin's largest when it has several roots), parents first, each one's
//! rest offset `b_i − b_parent` with the rest frames the world's, as [`ArmatureNode`] takes them.
//!
//! **Animation** ([`Character::animated_glb`]). A node of the retargeted [`ArmatureTrack`] is at
//! `p_i(t)` (m) at frame `t`, turned from rest by `D_i(t)`, so its world matrix is
//! `W_i(t) = T(u · p_i(t)) · R(D_i(t)) · A_i`, `u` the file's units per metre. Every other node
//! keeps its local matrix under its parent (a prop on the hand moves with the hand), and a
//! joint's local transform `W_parent(t)⁻¹ · W_i(t)` is written as a translation and a rotation
//! channel (its scale stays the node's). The animation replaces any the file had; the skinned
//! meshes then deform as the joints move, by the file's own skin.

use std::path::Path;

use base64::Engine;
use glam::{DMat3, DMat4, DQuat, DVec3};
use serde_json::{json, Value};

use crate::export::armature::{ArmatureNode, ArmatureTrack};
use crate::export::error::ExportError;
use crate::export::glb::{glb_chunks, glb_container};
use crate::files::read_bytes;
use crate::limits::CHARACTER_FILE_BYTES;

/// glTF's component type of 32-bit floats.
const FLOAT: u64 = 5126;

/// A bind matrix whose determinant is smaller than this cannot be inverted.
const SINGULAR: f64 = 1e-12;

/// A skinned character read from a glTF file.
#[derive(Clone, PartialEq)]
pub struct Character {
    /// The document: every buffer merged into one (the BIN chunk) and every image moved into it.
    document: Value,
    /// The one buffer.
    bin: Vec<u8>,
    /// Per document node, its parent.
    parents: Vec<Option<usize>>,
    /// Per document node, its local matrix at rest (`matrix`, or translation · rotation · scale).
    locals: Vec<DMat4>,
    /// The document's nodes, parents first.
    order: Vec<usize>,
    /// The document node of each rig node.
    joints: Vec<usize>,
    /// The linear part `A_i` of each rig node's bind matrix.
    linear: Vec<DMat3>,
}

impl std::fmt::Debug for Character {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Character {{ {} nodes, {} joints, {} bytes }}",
            self.parents.len(),
            self.joints.len(),
            self.bin.len()
        )
    }
}

/// The character of a glTF file and its rig's nodes (rest offsets and end sites in file units,
/// the root at its bind position). The error says what is wrong, for the caller to name the file.
pub fn read_character(path: &Path) -> Result<(Character, Vec<ArmatureNode>), String> {
    let (document, bin) = load(path)?;
    let nodes = array(&document, "nodes");
    let mut parents = vec![None; nodes.len()];
    for (i, node) in nodes.iter().enumerate() {
        for child in array(node, "children") {
            let c = child.as_u64().map(|c| c as usize).filter(|c| *c < nodes.len());
            let c = c.ok_or_else(|| format!("node {i} has a child {child} that is not a node"))?;
            if parents[c].replace(i).is_some() {
                return Err(format!("node {c} has two parents"));
            }
        }
    }
    let order = parents_first(&parents).ok_or("the nodes' children form a cycle")?;
    let locals = nodes.iter().enumerate().map(|(i, n)| local_matrix(n).ok_or(i)).collect::<Result<Vec<_>, _>>();
    let locals = locals.map_err(|i| format!("node {i}'s transform is not a finite translation, rotation and scale"))?;
    let mut world = vec![DMat4::IDENTITY; nodes.len()];
    for &n in &order {
        world[n] = parents[n].map_or(DMat4::IDENTITY, |p| world[p]) * locals[n];
    }
    let (skin_joints, bind) = skin(&document, &bin, &world)?;
    let (joints, tree_parents) = joint_tree(&skin_joints, &parents);
    let position = |k: usize| bind[k].w_axis.truncate();
    let rig_nodes: Vec<ArmatureNode> = joints
        .iter()
        .zip(&tree_parents)
        .map(|(&k, parent)| {
            let leaf = !tree_parents.contains(&Some(k));
            let offset = parent.map_or(position(k), |p| position(k) - position(p));
            ArmatureNode {
                name: node_name(&nodes[skin_joints[k]], skin_joints[k]),
                parent: parent.map(|p| joints.iter().position(|j| *j == p).unwrap_or(0)),
                offset_m: offset,
                end_site_m: (leaf && parent.is_some()).then_some(offset * 0.5),
                translated: false,
            }
        })
        .collect();
    let linear = joints.iter().map(|&k| DMat3::from_mat4(bind[k])).collect();
    let joints = joints.iter().map(|&k| skin_joints[k]).collect();
    Ok((Character { document, bin, parents, locals, order, joints, linear }, rig_nodes))
}

impl Character {
    /// The GLB of the character with `track` (the rig's retargeted motion: m, our axes) as its
    /// one animation, named `label`, at `units_per_metre` of the file (see the module doc).
    /// Fails on a track of other nodes than the rig's, or a transform that is not finite.
    pub fn animated_glb(
        &self,
        label: &str,
        track: &ArmatureTrack,
        units_per_metre: f64,
    ) -> Result<Vec<u8>, ExportError> {
        let fail = |what: String| ExportError::Shape(format!("sample `{label}` on the character: {what}"));
        if track.nodes.len() != self.joints.len() {
            return Err(fail(format!("{} nodes for a rig of {}", track.nodes.len(), self.joints.len())));
        }
        let mut rig_node = vec![None; self.parents.len()];
        for (r, &n) in self.joints.iter().enumerate() {
            rig_node[n] = Some(r);
        }
        // Per rig node and frame: the local translation and rotation.
        let mut translations = vec![Vec::with_capacity(track.frames()); self.joints.len()];
        let mut rotations: Vec<Vec<DQuat>> = vec![Vec::with_capacity(track.frames()); self.joints.len()];
        let mut world = vec![DMat4::IDENTITY; self.parents.len()];
        for t in 0..track.frames() {
            let posed = track.world(t);
            for &n in &self.order {
                let above = self.parents[n].map_or(DMat4::IDENTITY, |p| world[p]);
                world[n] = match rig_node[n] {
                    None => above * self.locals[n],
                    Some(r) => {
                        let (at, turn) = posed[r];
                        let w = DMat4::from_rotation_translation(turn, at * units_per_metre)
                            * DMat4::from_mat3(self.linear[r]);
                        let (_, rotation, translation) = (above.inverse() * w).to_scale_rotation_translation();
                        let previous = rotations[r].last().copied().unwrap_or(DQuat::IDENTITY);
                        let rotation = if rotation.dot(previous) < 0.0 { -rotation } else { rotation };
                        if !(rotation.is_finite() && translation.is_finite()) {
                            return Err(fail(format!(
                                "frame {t}: the transform of `{}` is not finite",
                                track.nodes[r].name
                            )));
                        }
                        translations[r].push(translation);
                        rotations[r].push(rotation.normalize());
                        w
                    }
                };
            }
        }
        let mut document = self.document.clone();
        let mut bin = self.bin.clone();
        let mut add =
            |values: Vec<f32>, kind: &str, bounds: bool| accessor(&mut document, &mut bin, &values, kind, bounds);
        let times: Vec<f32> = (0..track.frames()).map(|k| (k as f64 / track.fps) as f32).collect();
        let input = add(times, "SCALAR", true);
        let mut samplers = Vec::new();
        let mut channels = Vec::new();
        for (r, &n) in self.joints.iter().enumerate() {
            let t: Vec<f32> = translations[r].iter().flat_map(|v| v.as_vec3().to_array()).collect();
            let q: Vec<f32> = rotations[r].iter().flat_map(|q| q.as_quat().to_array()).collect();
            for (output, path) in [(add(t, "VEC3", false), "translation"), (add(q, "VEC4", false), "rotation")] {
                channels.push(json!({"sampler": samplers.len(), "target": {"node": n, "path": path}}));
                samplers.push(json!({"input": input, "output": output, "interpolation": "LINEAR"}));
            }
        }
        document["animations"] = json!([{"name": label, "samplers": samplers, "channels": channels}]);
        // Animated nodes take translation, rotation and scale rather than a matrix.
        for &n in &self.joints {
            let node = &mut document["nodes"][n];
            if let Some(object) = node.as_object_mut().filter(|o| o.contains_key("matrix")) {
                object.remove("matrix");
                let (scale, rotation, translation) = self.locals[n].to_scale_rotation_translation();
                object.insert("translation".into(), json!(translation.to_array()));
                object.insert("rotation".into(), json!(rotation.to_array()));
                object.insert("scale".into(), json!(scale.to_array()));
            }
        }
        document["buffers"] = json!([{"byteLength": bin.len()}]);
        document["asset"]["generator"] = json!("mogen (the character's file with its motion)");
        let text = serde_json::to_vec(&document).map_err(|e| fail(format!("its glTF JSON: {e}")))?;
        glb_container(&text, &bin)
    }
}

/// Appends `values` (elements of glTF type `kind`, floats) to `bin` in a buffer view of their
/// own on a 4-byte boundary and adds their accessor to `document`, with per-component bounds
/// when `bounds` (glTF requires them of animation inputs); its index.
fn accessor(document: &mut Value, bin: &mut Vec<u8>, values: &[f32], kind: &str, bounds: bool) -> usize {
    let width = components(kind).unwrap_or(1);
    bin.resize(bin.len().next_multiple_of(4), 0);
    let offset = bin.len();
    bin.extend(values.iter().flat_map(|x| x.to_le_bytes()));
    let views =
        push(document, "bufferViews", json!({"buffer": 0, "byteOffset": offset, "byteLength": 4 * values.len()}));
    let mut accessor =
        json!({"bufferView": views, "componentType": FLOAT, "count": values.len() / width, "type": kind});
    if bounds {
        let (min, max) = crate::export::gltf::bounds(values, width);
        accessor["min"] = min;
        accessor["max"] = max;
    }
    push(document, "accessors", accessor)
}

/// Appends `item` to the document's array `key` (made when absent); its index.
fn push(document: &mut Value, key: &str, item: Value) -> usize {
    let list = document.as_object_mut().map(|o| o.entry(key).or_insert_with(|| json!([])));
    match list.and_then(Value::as_array_mut) {
        Some(list) => {
            list.push(item);
            list.len() - 1
        }
        None => 0,
    }
}

/// Scalars per element of a glTF accessor type.
fn components(kind: &str) -> Option<usize> {
    Some(match kind {
        "SCALAR" => 1,
        "VEC2" => 2,
        "VEC3" => 3,
        "VEC4" | "MAT2" => 4,
        "MAT3" => 9,
        "MAT4" => 16,
        _ => return None,
    })
}

/// The array `key` of `value`, empty when absent.
fn array<'a>(value: &'a Value, key: &str) -> &'a [Value] {
    value.get(key).and_then(Value::as_array).map_or(&[], Vec::as_slice)
}

/// The number `key` of `value` as an index or length.
fn count(value: &Value, key: &str) -> Option<usize> {
    value.get(key).and_then(Value::as_u64).map(|v| v as usize)
}

/// A node's name, or `node<i>` for an unnamed one.
fn node_name(node: &Value, i: usize) -> String {
    node.get("name")
        .and_then(Value::as_str)
        .filter(|n| !n.trim().is_empty())
        .map_or_else(|| format!("node{i}"), str::to_owned)
}

/// A node's local matrix: its `matrix` (column-major), or `T · R · S`; `None` when not finite.
fn local_matrix(node: &Value) -> Option<DMat4> {
    let numbers = |key: &str, n: usize| -> Option<Option<Vec<f64>>> {
        match node.get(key) {
            None => Some(None),
            Some(v) => {
                let values: Vec<f64> = v.as_array()?.iter().map(Value::as_f64).collect::<Option<_>>()?;
                (values.len() == n && values.iter().all(|x| x.is_finite())).then_some(Some(values))
            }
        }
    };
    let matrix = match numbers("matrix", 16)? {
        Some(m) => DMat4::from_cols_slice(&m),
        None => {
            let t = numbers("translation", 3)?.map_or(DVec3::ZERO, |v| DVec3::from_slice(&v));
            let r = numbers("rotation", 4)?.map_or(DQuat::IDENTITY, |v| DQuat::from_slice(&v));
            let s = numbers("scale", 3)?.map_or(DVec3::ONE, |v| DVec3::from_slice(&v));
            let r = (r.length() > 1e-9).then(|| r.normalize())?;
            DMat4::from_scale_rotation_translation(s, r, t)
        }
    };
    Some(matrix)
}

/// The nodes ordered parents first; `None` when the parent links form a cycle.
fn parents_first(parents: &[Option<usize>]) -> Option<Vec<usize>> {
    let mut children = vec![Vec::new(); parents.len()];
    for (n, p) in parents.iter().enumerate() {
        if let Some(p) = p {
            children[*p].push(n);
        }
    }
    let mut order: Vec<usize> = (0..parents.len()).filter(|n| parents[*n].is_none()).collect();
    let mut at = 0;
    while at < order.len() {
        order.extend(children[order[at]].iter().copied());
        at += 1;
    }
    (order.len() == parents.len()).then_some(order)
}

/// The joints of the skin with the most (its nodes) and each one's bind world matrix.
fn skin(document: &Value, bin: &[u8], world: &[DMat4]) -> Result<(Vec<usize>, Vec<DMat4>), String> {
    let skins = array(document, "skins");
    let skin = skins
        .iter()
        .max_by_key(|s| array(s, "joints").len())
        .filter(|s| !array(s, "joints").is_empty())
        .ok_or("it has no skin: export the character with its armature (skinning on)")?;
    let mut joints: Vec<usize> = Vec::new();
    for j in array(skin, "joints") {
        let n = j.as_u64().map(|n| n as usize).filter(|n| *n < world.len());
        let n = n.ok_or_else(|| format!("the skin names joint {j}, which is not a node"))?;
        if joints.contains(&n) {
            return Err(format!("the skin names node {n} twice"));
        }
        joints.push(n);
    }
    let bind = match count(skin, "inverseBindMatrices") {
        None => joints.iter().map(|&n| world[n]).collect(),
        Some(a) => {
            let floats = accessor_floats(document, bin, a, "MAT4")?;
            if floats.len() < 16 * joints.len() {
                return Err(format!("inverse bind matrices: {} for {} joints", floats.len() / 16, joints.len()));
            }
            let mut bind = Vec::with_capacity(joints.len());
            for (k, m) in floats.chunks(16).take(joints.len()).enumerate() {
                let ibm = DMat4::from_cols_slice(&m.iter().map(|&x| f64::from(x)).collect::<Vec<_>>());
                if !(ibm.is_finite() && ibm.determinant().abs() > SINGULAR) {
                    return Err(format!("the inverse bind matrix of joint {k} cannot be inverted"));
                }
                bind.push(ibm.inverse());
            }
            bind
        }
    };
    Ok((joints, bind))
}

/// The rig's tree among the skin's joints (indices into them): the joints under the root whose
/// tree holds the most, depth first in skin order, and each one's parent joint (its nearest
/// ancestor node that is a joint).
fn joint_tree(joints: &[usize], parents: &[Option<usize>]) -> (Vec<usize>, Vec<Option<usize>>) {
    let mut skin_index = vec![None; parents.len()];
    for (k, &n) in joints.iter().enumerate() {
        skin_index[n] = Some(k);
    }
    let above = |k: usize| {
        let mut n = parents[joints[k]];
        while let Some(p) = n {
            if skin_index[p].is_some() {
                return skin_index[p];
            }
            n = parents[p];
        }
        None
    };
    let joint_parent: Vec<Option<usize>> = (0..joints.len()).map(above).collect();
    let mut children = vec![Vec::new(); joints.len()];
    for (k, p) in joint_parent.iter().enumerate() {
        if let Some(p) = p {
            children[*p].push(k);
        }
    }
    // The tree of each root, depth first in skin order; the largest is the rig.
    let tree = |root: usize| {
        let mut order = Vec::new();
        let mut stack = vec![root];
        while let Some(k) = stack.pop() {
            order.push(k);
            stack.extend(children[k].iter().rev());
        }
        order
    };
    let roots = (0..joints.len()).filter(|k| joint_parent[*k].is_none());
    let order = roots.map(tree).max_by_key(|order| order.len()).unwrap_or_default();
    let parents_out = order.iter().map(|&k| joint_parent[k]).collect();
    (order, parents_out)
}

/// The floats of accessor `index`, of glTF type `kind`, element after element.
fn accessor_floats(document: &Value, bin: &[u8], index: usize, kind: &str) -> Result<Vec<f32>, String> {
    let fail = |what: &str| format!("accessor {index}: {what}");
    let accessor = array(document, "accessors").get(index).ok_or_else(|| fail("there is no such accessor"))?;
    if accessor.get("type").and_then(Value::as_str) != Some(kind)
        || accessor.get("componentType").and_then(Value::as_u64) != Some(FLOAT)
    {
        return Err(fail(&format!("expected {kind} of floats")));
    }
    if accessor.get("sparse").is_some() {
        return Err(fail("sparse accessors are not read"));
    }
    let width = components(kind).unwrap_or(1);
    let n = count(accessor, "count").ok_or_else(|| fail("it has no count"))?;
    let view = count(accessor, "bufferView").and_then(|v| array(document, "bufferViews").get(v));
    let view = view.ok_or_else(|| fail("it has no buffer view"))?;
    let stride = count(view, "byteStride").unwrap_or(4 * width);
    let start = count(view, "byteOffset").unwrap_or(0) + count(accessor, "byteOffset").unwrap_or(0);
    let mut out = Vec::with_capacity(n * width);
    for e in 0..n {
        let at = start + e * stride;
        let bytes = bin.get(at..at + 4 * width).ok_or_else(|| fail("it reads past the end of its buffer"))?;
        out.extend(bytes.chunks(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])));
    }
    Ok(out)
}

/// The document of a `.glb` or `.gltf` file with every buffer merged into one (the returned
/// bytes) and every image moved into it, so the whole character can be written as one GLB.
fn load(path: &Path) -> Result<(Value, Vec<u8>), String> {
    let bytes = read_bytes(path, &CHARACTER_FILE_BYTES).map_err(|e| e.to_string())?;
    let (text, glb_bin) = if bytes.starts_with(b"glTF") { glb_chunks(&bytes)? } else { (&bytes[..], None) };
    let mut document: Value = serde_json::from_slice(text).map_err(|e| format!("its glTF JSON cannot be read: {e}"))?;
    let version = document.pointer("/asset/version").and_then(Value::as_str).unwrap_or("");
    if !version.starts_with("2.") {
        return Err(format!("glTF version `{version}`; only glTF 2.0 is read"));
    }
    let folder = path.parent().unwrap_or(Path::new("."));
    let mut bin = Vec::new();
    let mut starts = Vec::new();
    for (i, buffer) in array(&document, "buffers").iter().enumerate() {
        let mut data = match buffer.get("uri").and_then(Value::as_str) {
            Some(uri) => resource(folder, uri).map_err(|e| format!("buffer {i}: {e}"))?.0,
            None if i == 0 => glb_bin.ok_or("buffer 0 has no uri and the file no BIN chunk")?.to_vec(),
            None => return Err(format!("buffer {i} has no uri")),
        };
        let length = count(buffer, "byteLength").ok_or_else(|| format!("buffer {i} has no byteLength"))?;
        if data.len() < length {
            return Err(format!("buffer {i} holds {} bytes of the {length} it declares", data.len()));
        }
        data.truncate(length);
        bin.resize(bin.len().next_multiple_of(8), 0);
        starts.push(bin.len());
        bin.extend(data);
    }
    if let Some(views) = document.get_mut("bufferViews").and_then(Value::as_array_mut) {
        for (v, view) in views.iter_mut().enumerate() {
            let start = count(view, "buffer")
                .and_then(|b| starts.get(b))
                .ok_or_else(|| format!("buffer view {v} names no buffer"))?;
            view["byteOffset"] = json!(start + count(view, "byteOffset").unwrap_or(0));
            view["buffer"] = json!(0);
        }
    }
    let mut embedded = Vec::new();
    if let Some(images) = document.get_mut("images").and_then(Value::as_array_mut) {
        for (i, image) in images.iter_mut().enumerate() {
            let Some(uri) = image.get("uri").and_then(Value::as_str).map(str::to_owned) else { continue };
            let (data, mime) = resource(folder, &uri).map_err(|e| format!("image {i}: {e}"))?;
            let mime = mime.ok_or_else(|| format!("image {i} (`{uri}`) is not a PNG, JPEG, WebP or KTX2 file"))?;
            bin.resize(bin.len().next_multiple_of(8), 0);
            embedded.push((i, bin.len(), data.len(), mime));
            bin.extend(data);
        }
    }
    for (i, offset, length, mime) in embedded {
        let view = push(&mut document, "bufferViews", json!({"buffer": 0, "byteOffset": offset, "byteLength": length}));
        let image = &mut document["images"][i];
        if let Some(object) = image.as_object_mut() {
            object.remove("uri");
        }
        image["bufferView"] = json!(view);
        image["mimeType"] = json!(mime);
    }
    Ok((document, bin))
}

/// The bytes a glTF `uri` names (a `data:` URI in base64, or a file relative to `folder`) and
/// the image type it has, if any.
fn resource(folder: &Path, uri: &str) -> Result<(Vec<u8>, Option<&'static str>), String> {
    const IMAGES: [(&str, &str); 5] = [
        ("png", "image/png"),
        ("jpg", "image/jpeg"),
        ("jpeg", "image/jpeg"),
        ("webp", "image/webp"),
        ("ktx2", "image/ktx2"),
    ];
    if let Some(data) = uri.strip_prefix("data:") {
        let (head, body) = data.split_once(',').ok_or("a data URI without a comma")?;
        let head = head.strip_suffix(";base64").ok_or("a data URI that is not base64")?;
        let bytes = base64::engine::general_purpose::STANDARD.decode(body).map_err(|e| format!("its base64: {e}"))?;
        let mime = IMAGES.iter().find(|(_, m)| *m == head).map(|(_, m)| *m);
        return Ok((bytes, mime));
    }
    let file = folder.join(uri.replace("%20", " "));
    let extension = file.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
    let mime = IMAGES.iter().find(|(e, _)| *e == extension).map(|(_, m)| *m);
    let bytes = read_bytes(&file, &CHARACTER_FILE_BYTES).map_err(|e| e.to_string())?;
    Ok((bytes, mime))
}

#[cfg(test)]
mod tests;
