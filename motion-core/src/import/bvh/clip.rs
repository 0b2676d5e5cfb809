//! [`BvhClip`]: a BVH file posed at any time on the canonical skeleton.

use std::path::Path;

use glam::DVec3;

use super::animation::BvhAnimation;
use super::error::invalid;
use super::file::Bvh;
use super::rig::Rig;
use super::units::{LengthUnit, UpAxis, PLAUSIBLE_STATURE_M};
use crate::import::error::{ImportError, ImportWarning};
use crate::import::retargeted::{RetargetedClip, SourceSkeleton};
use crate::skeleton::{Pose, NUM_JOINTS};

/// How to read a BVH file into a [`BvhClip`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BvhOptions {
    /// The file's length unit; `None` detects it from the rest height ([`LengthUnit::detect`]).
    pub unit: Option<LengthUnit>,
    /// The file's up axis (default Y).
    pub up: UpAxis,
    /// The joint naming; `None` takes the first of [`Rig::ALL`] whose joints are all present.
    pub rig: Option<Rig>,
}

/// A BVH clip posed on the 22 joints: the source is posed by [`BvhAnimation`] (slerped rotations,
/// lerped root), the rig map picks the 22 points, and bone lengths are retargeted to those of
/// [`crate::skeleton::rest_pose`] with [`retarget_bone_lengths`] (bone directions kept, the root
/// trajectory scaled by the leg-length ratio). Not cyclic.
///
/// The project's own exports ([`Rig::Smpl`]) come back as written from
/// [`BvhClip::mapped_pose_at`] (the file's joints and bone lengths); [`MocapClip::pose_at`]
/// retargets them like any other rig's, so that a database built from them stays on one skeleton.
///
/// [`retarget_bone_lengths`]: crate::motion::retarget_bone_lengths
/// [`MocapClip::pose_at`]: crate::import::MocapClip::pose_at
pub type BvhClip = RetargetedClip<MappedBvh>;

/// A BVH animation with its rig and the 22 points the rig map picks from its nodes.
#[derive(Debug, Clone)]
pub struct MappedBvh {
    rig: Rig,
    animation: BvhAnimation,
    /// Per joint: the nodes it lies between and the fraction of the way (0 = at the first).
    map: [(usize, usize, f64); NUM_JOINTS],
}

impl MappedBvh {
    /// The 22 points picked from node positions (source bone lengths).
    fn map_to_joints(&self, positions: &[DVec3]) -> Pose {
        self.map.map(|(a, b, t)| match (positions.get(a), positions.get(b)) {
            (Some(p), Some(q)) => p.lerp(*q, t),
            _ => DVec3::ZERO,
        })
    }
}

impl SourceSkeleton for MappedBvh {
    fn duration_s(&self) -> f64 {
        self.animation.duration_s()
    }

    fn frame_time_s(&self) -> f64 {
        self.animation.frame_time_s()
    }

    fn mapped_pose_at(&self, t_s: f64) -> Pose {
        self.map_to_joints(&self.animation.positions_at(t_s))
    }

    /// The source's rest skeleton (OFFSETs only) mapped to the 22 joints.
    fn mapped_rest_pose(&self) -> Pose {
        self.map_to_joints(&self.animation.rest_positions())
    }
}

impl BvhClip {
    /// Reads and maps a file; the warnings include the BVH reader's.
    pub fn read(path: &Path, options: &BvhOptions) -> Result<(Self, Vec<ImportWarning>), ImportError> {
        let (bvh, mut warnings) = Bvh::read(path)?;
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let (clip, more) = Self::from_bvh(&name, &bvh, options, path)?;
        warnings.extend(more);
        Ok((clip, warnings))
    }

    /// Maps a parsed file; `path` is only used in messages. Fails when no rig's joints are all
    /// present (the message lists what each rig lacks); warns when the rest skeleton is
    /// implausibly tall or short in the chosen unit.
    pub fn from_bvh(
        name: &str,
        bvh: &Bvh,
        options: &BvhOptions,
        path: &Path,
    ) -> Result<(Self, Vec<ImportWarning>), ImportError> {
        let root_line = bvh.joints().first().map_or(1, |j| j.line);
        let rest_height = bvh.rest_height(options.up);
        let unit = match options.unit {
            Some(u) => u,
            None => LengthUnit::detect(rest_height).ok_or_else(|| {
                invalid(path, root_line, None, "cannot detect the unit of a skeleton with no height; give one")
            })?,
        };
        let animation = BvhAnimation::new(bvh, unit, options.up, path)?;
        let mut warnings = Vec::new();
        let stature_m = rest_height * unit.metres();
        if !(PLAUSIBLE_STATURE_M.0..=PLAUSIBLE_STATURE_M.1).contains(&stature_m) {
            warnings.push(ImportWarning {
                path: path.into(),
                message: format!("the rest skeleton is {stature_m:.2} m tall in {unit:?}; check the unit"),
            });
        }
        let (rig, map) = match options.rig {
            Some(rig) => rig.resolve(bvh).map(|m| (rig, m)).map_err(|missing| {
                invalid(path, root_line, None, format!("not a {} rig: missing {}", rig.name(), missing.join(", ")))
            })?,
            None => {
                let mut misses = Vec::new();
                let mut found = None;
                for rig in Rig::ALL {
                    match rig.resolve(bvh) {
                        Ok(map) => {
                            found = Some((rig, map));
                            break;
                        }
                        Err(missing) => misses.push(format!("{} lacks {}", rig.name(), missing.join(", "))),
                    }
                }
                found.ok_or_else(|| {
                    invalid(
                        path,
                        root_line,
                        None,
                        format!("no known rig matches the joint names: {}", misses.join("; ")),
                    )
                })?
            }
        };
        let target = crate::skeleton::rest_bone_lengths();
        Ok((Self { name: name.to_owned(), source: MappedBvh { rig, animation, map }, target }, warnings))
    }

    /// The rig whose joint map is used.
    pub fn rig(&self) -> Rig {
        self.source.rig
    }

    /// The source motion (frames, frame time, unit, every node's positions).
    pub fn animation(&self) -> &BvhAnimation {
        &self.source.animation
    }
}

#[cfg(test)]
mod tests {
    use crate::skeleton::bone_lengths;
    use glam::DQuat;

    use super::*;
    use crate::import::bvh::tests::TINY;
    use crate::import::{resample, MocapClip};
    use crate::motion::bone_length_spread;
    use crate::skeleton::Joint;

    const CMU: [&str; 2] = ["cmu/cmu_01_01_20fps.bvh", "cmu/cmu_01_03_20fps.bvh"];
    const MOCAPBANK: &str = "bvhtoolbox/test_mocapbank.bvh";
    const ALL: [&str; 4] =
        ["cmu/cmu_01_01_20fps.bvh", "cmu/cmu_01_03_20fps.bvh", "cmu/boxing_toes_20fps.bvh", MOCAPBANK];

    /// Path under `fixtures/mocap/`.
    fn fixture(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mocap").join(name)
    }

    fn clip(name: &str) -> BvhClip {
        let path = fixture(name);
        let (clip, warnings) = BvhClip::read(&path, &BvhOptions::default()).unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        clip
    }

    fn at(p: &Pose, j: Joint) -> DVec3 {
        p[j.index()]
    }

    /// Height of the lowest ankle or foot joint, m.
    fn lowest_foot(p: &Pose) -> f64 {
        [Joint::LeftAnkle, Joint::RightAnkle, Joint::LeftFoot, Joint::RightFoot]
            .map(|j| at(p, j).y)
            .into_iter()
            .fold(f64::MAX, f64::min)
    }

    #[test]
    fn fixtures_have_the_right_frames_rate_rig_and_unit() {
        for (name, frames, rig, unit) in [
            ("cmu/cmu_01_01_20fps.bvh", 459, Rig::Cmu, LengthUnit::CmuAsf),
            ("cmu/cmu_01_03_20fps.bvh", 752, Rig::Cmu, LengthUnit::CmuAsf),
            ("cmu/boxing_toes_20fps.bvh", 614, Rig::HipsAbChest, LengthUnit::Centimetres),
        ] {
            let c = clip(name);
            assert_eq!((c.animation().frames(), c.rig(), c.animation().unit()), (frames, rig, unit), "{name}");
            assert!((c.fps() - 20.0).abs() < 1e-9);
            assert!((c.duration_s() - (frames - 1) as f64 * 0.05).abs() < 1e-9);
            assert!(!c.is_cyclic());
            assert_eq!(resample(&c, 1.0, None).len(), frames);
        }
    }

    #[test]
    fn cmu_first_frame_is_a_human_sized_t_pose_on_the_floor() {
        for name in CMU {
            let c = clip(name);
            let (src, out) = (c.mapped_pose_at(0.0), c.pose_at(0.0));
            // Subject 01 is small: the head joint is 1.40 m above the lowest foot joint in the
            // source, 1.54 m on the canonical skeleton.
            let src_head = at(&src, Joint::Head).y - lowest_foot(&src);
            let out_head = at(&out, Joint::Head).y - lowest_foot(&out);
            assert!((1.3..1.9).contains(&src_head), "{name}: source head {src_head}");
            assert!((1.4..1.9).contains(&out_head), "{name}: head {out_head}");
            assert!((0.0..0.08).contains(&lowest_foot(&src)), "{name}: source feet at {}", lowest_foot(&src));
            assert!((0.0..0.12).contains(&lowest_foot(&out)), "{name}: feet at {}", lowest_foot(&out));
            for side in [[Joint::LeftShoulder, Joint::LeftWrist], [Joint::RightShoulder, Joint::RightWrist]] {
                let arm = at(&out, side[1]) - at(&out, side[0]);
                assert!(arm.y.abs() < 0.1 && arm.length() > 0.5, "{name}: not a T-pose: {arm}");
            }
        }
    }

    #[test]
    fn feet_stay_near_the_floor_and_bones_keep_their_canonical_lengths() {
        let target = crate::skeleton::rest_bone_lengths();
        for name in ALL {
            let c = clip(name);
            let poses = resample(&c, 1.0, None);
            assert!(bone_length_spread(&poses) < 1e-3, "{name}");
            for (j, len) in bone_lengths(&poses[0]).iter().enumerate() {
                assert!((len - target[j]).abs() < 1e-9);
            }
            let src_floor =
                (0..poses.len()).map(|k| lowest_foot(&c.mapped_pose_at(k as f64 * 0.05))).fold(f64::MAX, f64::min);
            assert!((-0.02..0.06).contains(&src_floor), "{name}: lowest foot joint {src_floor}");
        }
    }

    /// Horizontal direction the feet point (ankles to balls), independent of left/right labels.
    fn toes_forward(p: &Pose) -> DVec3 {
        let d = at(p, Joint::LeftFoot) - at(p, Joint::LeftAnkle) + at(p, Joint::RightFoot) - at(p, Joint::RightAnkle);
        DVec3::new(d.x, 0.0, d.z)
    }

    #[test]
    fn left_is_plus_x_when_the_toes_face_plus_z() {
        for name in ALL {
            let c = clip(name);
            let poses = resample(&c, 1.0, None);
            let (mut frames, mut left_ok, mut facing_ok) = (0, 0, 0);
            for p in &poses {
                let fwd = toes_forward(p);
                if fwd.length() < 0.05 {
                    continue;
                }
                frames += 1;
                // Turn about y so the toes face +z; then left joints must have larger x.
                let turn = DQuat::from_rotation_y(-fwd.x.atan2(fwd.z));
                let x = |j: Joint| (turn * at(p, j)).x;
                if x(Joint::LeftHip) > x(Joint::RightHip) && x(Joint::LeftShoulder) > x(Joint::RightShoulder) {
                    left_ok += 1;
                }
                // HumanML3D's facing (up × (right − left)) agrees with the toes.
                let across = at(p, Joint::RightHip) - at(p, Joint::LeftHip) + at(p, Joint::RightShoulder)
                    - at(p, Joint::LeftShoulder);
                if DVec3::Y.cross(across).dot(fwd) > 0.0 {
                    facing_ok += 1;
                }
            }
            println!("{name}: {frames} frames, left {left_ok}, facing {facing_ok}");
            assert!(left_ok as f64 >= 0.95 * frames as f64 && facing_ok as f64 >= 0.95 * frames as f64, "{name}");
            let t_pose = c.pose_at(0.0);
            assert!(toes_forward(&t_pose).length() > 0.05);
        }
    }

    #[test]
    fn mapped_rest_skeletons_have_smpl_like_torsos() {
        let canon = crate::skeleton::rest_pose();
        let torso = [
            Joint::Spine1,
            Joint::Spine2,
            Joint::Spine3,
            Joint::Neck,
            Joint::Head,
            Joint::LeftCollar,
            Joint::RightCollar,
        ];
        for name in ALL {
            let rest = clip(name).mapped_rest_pose();
            for j in torso.into_iter().chain([Joint::LeftShoulder, Joint::RightShoulder]) {
                let Some(p) = j.parent() else { continue };
                let dir = |q: &Pose| (at(q, j) - at(q, p)).normalize();
                let angle = dir(&rest).dot(dir(&canon)).clamp(-1.0, 1.0).acos().to_degrees();
                // Clavicles differ most between rigs (Boxing_Toes' start at its neck joint, above
                // the canonical spine3), so collars get a wider tolerance.
                let limit = if matches!(j, Joint::LeftCollar | Joint::RightCollar) { 40.0 } else { 25.0 };
                assert!(angle < limit, "{name}: {p}->{j} is {angle:.0} deg off");
            }
        }
    }

    /// A T-posed Mixamo-named skeleton in centimetres, with one frame.
    fn mixamo_bvh() -> String {
        let nodes: [(&str, usize, [f64; 3]); 22] = [
            ("Hips", usize::MAX, [0.0, 100.0, 0.0]),
            ("Spine", 0, [0.0, 10.0, 0.0]),
            ("Spine1", 1, [0.0, 12.0, 0.0]),
            ("Spine2", 2, [0.0, 13.0, 0.0]),
            ("Neck", 3, [0.0, 15.0, 0.0]),
            ("Head", 4, [0.0, 10.0, 2.0]),
            ("LeftShoulder", 3, [6.0, 11.0, 0.0]),
            ("LeftArm", 6, [12.0, 0.0, 0.0]),
            ("LeftForeArm", 7, [27.0, 0.0, 0.0]),
            ("LeftHand", 8, [26.0, 0.0, 0.0]),
            ("RightShoulder", 3, [-6.0, 11.0, 0.0]),
            ("RightArm", 10, [-12.0, 0.0, 0.0]),
            ("RightForeArm", 11, [-27.0, 0.0, 0.0]),
            ("RightHand", 12, [-26.0, 0.0, 0.0]),
            ("LeftUpLeg", 0, [9.0, -6.0, 0.0]),
            ("LeftLeg", 14, [0.0, -42.0, 0.0]),
            ("LeftFoot", 15, [0.0, -42.0, 0.0]),
            ("LeftToeBase", 16, [0.0, -8.0, 12.0]),
            ("RightUpLeg", 0, [-9.0, -6.0, 0.0]),
            ("RightLeg", 18, [0.0, -42.0, 0.0]),
            ("RightFoot", 19, [0.0, -42.0, 0.0]),
            ("RightToeBase", 20, [0.0, -8.0, 12.0]),
        ];
        fn write(nodes: &[(&str, usize, [f64; 3])], i: usize, out: &mut String) {
            let (name, parent, [x, y, z]) = nodes[i];
            let (kind, channels) = if parent == usize::MAX {
                ("ROOT", "6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
            } else {
                ("JOINT", "3 Zrotation Xrotation Yrotation")
            };
            out.push_str(&format!("{kind} mixamorig:{name}\n{{\nOFFSET {x} {y} {z}\nCHANNELS {channels}\n"));
            let children: Vec<usize> = (0..nodes.len()).filter(|c| nodes[*c].1 == i).collect();
            if children.is_empty() {
                out.push_str("End Site\n{\nOFFSET 0 5 0\n}\n");
            }
            for c in children {
                write(nodes, c, out);
            }
            out.push_str("}\n");
        }
        let mut text = String::from("HIERARCHY\n");
        write(&nodes, 0, &mut text);
        text + &format!("MOTION\nFrames: 1\nFrame Time: 0.0333333\n0 100 0 {}\n", vec!["0"; 3 + 21 * 3].join(" "))
    }

    #[test]
    fn mixamo_names_are_detected_and_mapped() {
        let (bvh, _) = Bvh::parse(&mixamo_bvh(), Path::new("mixamo.bvh")).unwrap();
        let (c, warnings) = BvhClip::from_bvh("mixamo", &bvh, &BvhOptions::default(), Path::new("mixamo.bvh")).unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_eq!((c.rig(), c.animation().unit()), (Rig::Mixamo, LengthUnit::Centimetres));
        let p = c.mapped_pose_at(0.0);
        assert!((at(&p, Joint::Pelvis) - DVec3::new(0.0, 1.0, 0.0)).length() < 1e-9);
        assert!((at(&p, Joint::LeftCollar) - DVec3::new(0.06, 1.46, 0.0)).length() < 1e-9);
        assert!((at(&p, Joint::RightWrist) - DVec3::new(-0.71, 1.46, 0.0)).length() < 1e-9);
        assert!((at(&p, Joint::LeftFoot) - DVec3::new(0.09, 0.02, 0.12)).length() < 1e-9);
        let out = c.pose_at(0.0);
        assert!(bone_lengths(&out).iter().zip(crate::skeleton::rest_bone_lengths()).all(|(a, b)| (a - b).abs() < 1e-9));
    }

    #[test]
    fn unmappable_rigs_list_what_is_missing() {
        let (bvh, _) = Bvh::parse(TINY, Path::new("tiny.bvh")).unwrap();
        let options = BvhOptions { unit: Some(LengthUnit::Metres), ..BvhOptions::default() };
        let e = BvhClip::from_bvh("tiny", &bvh, &options, Path::new("tiny.bvh")).unwrap_err().to_string();
        assert!(e.contains("tiny.bvh: line 2: no known rig"), "{e}");
        assert!(
            e.contains("CMU (cgspeed) lacks LeftUpLeg") && e.contains("Mixamo lacks") && e.contains("LeftToes"),
            "{e}"
        );
        assert!(!e.contains("lacks Hips"), "{e}");
        let (mixamo, _) = Bvh::parse(&mixamo_bvh(), Path::new("m.bvh")).unwrap();
        let forced = BvhOptions { rig: Some(Rig::Cmu), ..BvhOptions::default() };
        let e = BvhClip::from_bvh("m", &mixamo, &forced, Path::new("m.bvh")).unwrap_err().to_string();
        assert!(e.contains("not a CMU (cgspeed) rig: missing LowerBack, Neck1"), "{e}");
        // The TINY skeleton is flat: its unit cannot be detected.
        let e = BvhClip::from_bvh("tiny", &bvh, &BvhOptions::default(), Path::new("tiny.bvh")).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("cannot detect the unit"), "{e}");
    }

    #[test]
    fn mocapbank_clip_kneels_on_the_right_knee_with_the_hands_low_and_stands_up() {
        let c = clip(MOCAPBANK);
        assert_eq!(
            (c.animation().frames(), c.rig(), c.animation().unit()),
            (455, Rig::HipsChestChest2, LengthUnit::Centimetres)
        );
        assert!((c.fps() - 30.0).abs() < 0.01 && (c.duration_s() - 15.13).abs() < 0.01);
        let poses = resample(&c, 1.0, None);
        let floor = poses.iter().map(lowest_foot).fold(f64::MAX, f64::min);
        let height = |t: f64, j: Joint| at(&poses[(t * 20.0) as usize], j).y - floor;
        for t in [1.0, 14.0] {
            assert!(height(t, Joint::Pelvis) > 0.85 && height(t, Joint::Head) > 1.4, "standing at {t} s");
        }
        // From 5 s to 10 s: the right knee on the floor, the left foot flat, the left knee up,
        // the pelvis half-way down and both hands near the ground in front.
        for t in [5.0, 6.0, 8.0, 10.0] {
            let h = |j: Joint| height(t, j);
            assert!(h(Joint::RightKnee) < 0.1 && h(Joint::LeftKnee) > 0.4, "kneeling at {t} s");
            assert!(h(Joint::LeftAnkle) < 0.1 && h(Joint::Pelvis) < 0.6, "kneeling at {t} s");
            assert!(h(Joint::LeftWrist) < 0.3 && h(Joint::RightWrist) < 0.3, "hands low at {t} s");
        }
        // Standing, the balls of the feet are below the ankles and near the floor.
        let p = &poses[20];
        for (ankle, ball) in [(Joint::LeftAnkle, Joint::LeftFoot), (Joint::RightAnkle, Joint::RightFoot)] {
            assert!(at(p, ball).y - floor < 0.06 && (at(p, ball) - at(p, ankle)).y < 0.0, "{ball}");
        }
    }

    #[test]
    fn a_rig_without_the_toe_end_site_is_named() {
        let text = std::fs::read_to_string(fixture(MOCAPBANK)).unwrap();
        // Drop the End Site block of the left ankle (the first End Site after "JOINT LeftAnkle").
        let ankle = text.find("JOINT LeftAnkle").unwrap();
        let start = ankle + text[ankle..].find("End Site").unwrap();
        let end = start + text[start..].find('}').unwrap() + 1;
        let cut = format!("{}{}", &text[..start], &text[end..]);
        let (bvh, _) = Bvh::parse(&cut, Path::new("cut.bvh")).unwrap();
        let forced = BvhOptions { rig: Some(Rig::HipsChestChest2), ..BvhOptions::default() };
        let e = BvhClip::from_bvh("cut", &bvh, &forced, Path::new("cut.bvh")).unwrap_err().to_string();
        assert!(e.contains("cut.bvh") && e.contains("missing LeftAnkle End Site"), "{e}");
    }

    #[test]
    fn implausible_statures_are_reported() {
        let (bvh, _) = Bvh::parse(&mixamo_bvh(), Path::new("m.bvh")).unwrap();
        let options = BvhOptions { unit: Some(LengthUnit::Metres), ..BvhOptions::default() };
        let (_, warnings) = BvhClip::from_bvh("m", &bvh, &options, Path::new("m.bvh")).unwrap();
        assert_eq!(warnings.len(), 1);
        assert!(warnings[0].message.contains("check the unit"));
    }
}
