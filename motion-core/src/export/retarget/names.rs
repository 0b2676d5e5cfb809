//! Which node of a user's rig is which of our 22 joints: by the bone names of the common
//! conventions ([`Convention`]), case- and prefix-insensitive, or by an explicit map.

use std::collections::BTreeMap;

use crate::skeleton::{Joint, NUM_JOINTS};

/// A family of humanoid bone names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Convention {
    /// SMPL's joints, as our own files name them (`pelvis`, `left_hip`, …) or as SMPL does
    /// (`Pelvis`, `L_Hip`, …).
    Smpl,
    /// Mixamo (`mixamorig:Hips`, `Spine`, `Spine1`, `Spine2`, `LeftUpLeg`, `LeftToeBase`, …).
    Mixamo,
    /// Unreal's mannequin (`pelvis`, `spine_01`…`spine_03`, `neck_01`, `clavicle_l`,
    /// `upperarm_l`, `thigh_l`, `calf_l`, `foot_l`, `ball_l`, …; a `root` above the pelvis).
    Unreal,
    /// Unity's humanoid avatar bones (`Hips`, `Spine`, `Chest`, `UpperChest`, `LeftUpperLeg`,
    /// `LeftLowerLeg`, `LeftToes`, …).
    Unity,
    /// CMU capture in the cgspeed BVH conversion (`Hips`, `LowerBack`, `Spine`, `Spine1`,
    /// `Neck1`, `LeftUpLeg`, …).
    Cmu,
}

impl Convention {
    /// Every convention, in the order a rig is tried against them.
    pub const ALL: [Convention; 5] =
        [Convention::Smpl, Convention::Mixamo, Convention::Unreal, Convention::Unity, Convention::Cmu];

    /// Display name.
    pub fn name(self) -> &'static str {
        match self {
            Convention::Smpl => "SMPL",
            Convention::Mixamo => "Mixamo",
            Convention::Unreal => "Unreal mannequin",
            Convention::Unity => "Unity humanoid",
            Convention::Cmu => "CMU",
        }
    }

    /// The convention's bone name of each of our joints, in [`Joint`] order (SMPL's has a second
    /// spelling, [`Convention::names`]).
    fn table(self) -> [&'static str; NUM_JOINTS] {
        match self {
            Convention::Smpl => Joint::ALL.map(Joint::name),
            Convention::Mixamo => [
                "Hips",
                "LeftUpLeg",
                "RightUpLeg",
                "Spine",
                "LeftLeg",
                "RightLeg",
                "Spine1",
                "LeftFoot",
                "RightFoot",
                "Spine2",
                "LeftToeBase",
                "RightToeBase",
                "Neck",
                "LeftShoulder",
                "RightShoulder",
                "Head",
                "LeftArm",
                "RightArm",
                "LeftForeArm",
                "RightForeArm",
                "LeftHand",
                "RightHand",
            ],
            Convention::Unreal => [
                "pelvis",
                "thigh_l",
                "thigh_r",
                "spine_01",
                "calf_l",
                "calf_r",
                "spine_02",
                "foot_l",
                "foot_r",
                "spine_03",
                "ball_l",
                "ball_r",
                "neck_01",
                "clavicle_l",
                "clavicle_r",
                "head",
                "upperarm_l",
                "upperarm_r",
                "lowerarm_l",
                "lowerarm_r",
                "hand_l",
                "hand_r",
            ],
            Convention::Unity => [
                "Hips",
                "LeftUpperLeg",
                "RightUpperLeg",
                "Spine",
                "LeftLowerLeg",
                "RightLowerLeg",
                "Chest",
                "LeftFoot",
                "RightFoot",
                "UpperChest",
                "LeftToes",
                "RightToes",
                "Neck",
                "LeftShoulder",
                "RightShoulder",
                "Head",
                "LeftUpperArm",
                "RightUpperArm",
                "LeftLowerArm",
                "RightLowerArm",
                "LeftHand",
                "RightHand",
            ],
            // Mixamo's names on another spine: LowerBack, Spine, Spine1, then Neck1 at the neck.
            Convention::Cmu => {
                let mut names = Convention::Mixamo.table();
                for (joint, name) in [
                    (Joint::Spine1, "LowerBack"),
                    (Joint::Spine2, "Spine"),
                    (Joint::Spine3, "Spine1"),
                    (Joint::Neck, "Neck1"),
                ] {
                    names[joint.index()] = name;
                }
                names
            }
        }
    }

    /// The accepted names of `joint`, [`normalised`].
    pub fn names(self, joint: Joint) -> Vec<String> {
        let name = self.table()[joint.index()];
        let mut names = vec![normalised(name)];
        if self == Convention::Smpl {
            names.push(normalised(&name.replace("left_", "l_").replace("right_", "r_")));
        }
        names
    }
}

/// A bone name as it is compared: what follows the last `:` or `|` (a namespace such as
/// `mixamorig:` or an armature's `Armature|`), lower case, letters and digits only.
pub fn normalised(name: &str) -> String {
    let bare = name.rsplit([':', '|']).next().unwrap_or(name);
    bare.chars().filter(char::is_ascii_alphanumeric).map(|c| c.to_ascii_lowercase()).collect()
}

/// How a rig's nodes were matched to our joints.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Matched {
    /// By a convention's names.
    Convention(Convention),
    /// By an explicit map (our joint name → the rig's node name).
    Explicit,
}

impl Matched {
    /// Display name.
    pub fn name(&self) -> &'static str {
        match self {
            Matched::Convention(c) => c.name(),
            Matched::Explicit => "explicit map",
        }
    }
}

/// The node of each of our joints among `nodes` (the rig's node names): through `explicit`
/// (our joint name, as [`Joint::name`] writes it, → a node name, matched [`normalised`]) when
/// given, else through the first [`Convention`] that names all 22. The error says what is
/// missing: the explicit map's unknown keys, absent joints or unknown nodes, or the closest
/// convention's joints the rig lacks.
pub fn match_nodes(
    nodes: &[String],
    explicit: Option<&BTreeMap<String, String>>,
) -> Result<(Matched, [usize; NUM_JOINTS]), String> {
    let normal: Vec<String> = nodes.iter().map(|n| normalised(n)).collect();
    let find = |names: &[String]| names.iter().find_map(|name| normal.iter().position(|n| n == name));
    if let Some(map) = explicit {
        let unknown: Vec<&str> =
            map.keys().filter(|k| Joint::ALL.iter().all(|j| j.name() != k.as_str())).map(String::as_str).collect();
        if !unknown.is_empty() {
            return Err(format!(
                "the joint map names {} which {} not among our joints ({})",
                unknown.join(", "),
                if unknown.len() == 1 { "is" } else { "are" },
                Joint::ALL.map(Joint::name).join(", ")
            ));
        }
        let mut missing = Vec::new();
        let mut map_out = [0; NUM_JOINTS];
        for j in Joint::ALL {
            match map.get(j.name()) {
                None => missing.push(format!("{} (not in the map)", j.name())),
                Some(node) => match find(&[normalised(node)]) {
                    Some(i) => map_out[j.index()] = i,
                    None => missing.push(format!("{} (the rig has no node `{node}`)", j.name())),
                },
            }
        }
        if !missing.is_empty() {
            return Err(missing.join(", "));
        }
        for (a, b) in Joint::ALL.iter().flat_map(|a| Joint::ALL.iter().map(move |b| (a, b))) {
            if a.index() < b.index() && map_out[a.index()] == map_out[b.index()] {
                return Err(format!("{} and {} both name node `{}`", a.name(), b.name(), nodes[map_out[a.index()]]));
            }
        }
        return Ok((Matched::Explicit, map_out));
    }
    let mut closest: Option<(Convention, Vec<String>)> = None;
    for convention in Convention::ALL {
        let found = Joint::ALL.map(|j| find(&convention.names(j)));
        let lacking: Vec<String> = Joint::ALL
            .iter()
            .zip(&found)
            .filter(|(_, f)| f.is_none())
            .map(|(j, _)| format!("{} ({})", convention.table()[j.index()], j.name()))
            .collect();
        if lacking.is_empty() {
            return Ok((Matched::Convention(convention), found.map(|f| f.unwrap_or(0))));
        }
        if closest.as_ref().is_none_or(|(_, l)| lacking.len() < l.len()) {
            closest = Some((convention, lacking));
        }
    }
    let (convention, lacking) = closest.unwrap_or((Convention::Smpl, Vec::new()));
    Err(format!(
        "no naming convention ({}) names all 22 joints; the closest, {}, lacks {}; name the nodes with a joint map",
        Convention::ALL.map(Convention::name).join(", "),
        convention.name(),
        lacking.join(", ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rig's node names: `prefix` before each of the convention's names, and extra bones.
    fn rig(convention: Convention, prefix: &str) -> Vec<String> {
        let mut names: Vec<String> = vec![format!("{prefix}Root")];
        names.extend(convention.table().iter().map(|n| format!("{prefix}{n}")));
        names.extend(["LeftHandIndex1", "upperarm_twist_01_l", "prop"].map(String::from));
        names
    }

    #[test]
    fn every_convention_matches_its_own_names_whatever_the_prefix_and_case() {
        for convention in Convention::ALL {
            for prefix in ["", "mixamorig:", "Armature|", "rig1:"] {
                let mut names = rig(convention, prefix);
                if prefix == "rig1:" {
                    names = names.iter().map(|n| n.to_uppercase()).collect();
                }
                let (matched, map) = match_nodes(&names, None).unwrap();
                assert_eq!(matched, Matched::Convention(convention), "{prefix}");
                for j in Joint::ALL {
                    assert_eq!(map[j.index()], j.index() + 1, "{} {prefix} {}", convention.name(), j.name());
                }
            }
        }
        let smpl_own: Vec<String> = [
            "Pelvis",
            "L_Hip",
            "R_Hip",
            "Spine1",
            "L_Knee",
            "R_Knee",
            "Spine2",
            "L_Ankle",
            "R_Ankle",
            "Spine3",
            "L_Foot",
            "R_Foot",
            "Neck",
            "L_Collar",
            "R_Collar",
            "Head",
            "L_Shoulder",
            "R_Shoulder",
            "L_Elbow",
            "R_Elbow",
            "L_Wrist",
            "R_Wrist",
        ]
        .map(String::from)
        .to_vec();
        assert_eq!(match_nodes(&smpl_own, None).unwrap().1, std::array::from_fn(|i| i));
        assert_eq!(normalised("mixamorig1:Left_Up-Leg"), "leftupleg");
    }

    #[test]
    fn a_rig_lacking_joints_is_refused_naming_them() {
        let names: Vec<String> = rig(Convention::Mixamo, "mixamorig:")
            .into_iter()
            .filter(|n| !n.ends_with("ToeBase") && !n.ends_with("Spine2"))
            .collect();
        let err = match_nodes(&names, None).unwrap_err();
        assert!(
            err.contains("the closest, Mixamo, lacks Spine2 (spine3), LeftToeBase (left_foot), RightToeBase"),
            "{err}"
        );
    }

    #[test]
    fn an_explicit_map_names_every_joint_and_its_errors_say_which() {
        let names = rig(Convention::Unity, "");
        let map: BTreeMap<String, String> = Joint::ALL
            .iter()
            .map(|j| (j.name().to_owned(), Convention::Unity.table()[j.index()].to_lowercase()))
            .collect();
        let (matched, found) = match_nodes(&names, Some(&map)).unwrap();
        assert_eq!((matched.name(), found[Joint::Spine3.index()]), ("explicit map", 10));
        let mut bad = map.clone();
        bad.remove("left_wrist");
        bad.insert("neck".into(), "Throat".into());
        let err = match_nodes(&names, Some(&bad)).unwrap_err();
        assert!(
            err.contains("neck (the rig has no node `Throat`)") && err.contains("left_wrist (not in the map)"),
            "{err}"
        );
        bad.insert("tail".into(), "Tail".into());
        let err = match_nodes(&names, Some(&bad)).unwrap_err();
        assert!(err.contains("names tail which is not among our joints"), "{err}");
    }
}
