//! [`AsfAmcClip`]: an ASF/AMC pair posed at any time on the canonical skeleton.

use std::path::Path;

use glam::DVec3;

use super::amc::AmcMotion;
use super::asf::Asf;
use super::lines::invalid;
use crate::files::read_bytes;
use crate::import::error::{ImportError, ImportWarning};
use crate::import::retargeted::{RetargetedClip, SourceSkeleton};
use crate::import::values::short_number;
use crate::limits::MOCAP_FILE_BYTES;
use crate::skeleton::{Pose, NUM_JOINTS};

/// Rest statures outside this range are reported (m), as for BVH files.
const PLAUSIBLE_STATURE_M: (f64, f64) = (1.0, 2.3);

/// Accepted frame rates, frames per second.
const FPS_RANGE: (f64, f64) = (1.0, 10_000.0);

/// How to read an ASF/AMC pair into an [`AsfAmcClip`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AsfAmcOptions {
    /// Frames per second of the AMC file, which does not record it. Default 120 (CMU and HDM05;
    /// a few CMU subjects are 60).
    pub fps: f64,
    /// Metres per ASF length unit; `None` takes `0.0254 / length` from the ASF's `:units`.
    pub metres_per_unit: Option<f64>,
}

impl Default for AsfAmcOptions {
    fn default() -> Self {
        Self { fps: 120.0, metres_per_unit: None }
    }
}

/// Where one of our joints sits on the Acclaim skeleton: a fraction of the way along a bone
/// (0 = its start, which is its parent's end).
type Along = (&'static str, f64);

/// Our joints in [`Joint`](crate::skeleton::Joint) order on the CMU/HDM05 bones. Each joint of
/// the 22 sits at the start of the bone it moves (the hip at the start of the femur, the knee
/// at the start of the tibia, …). The spine is spread like SMPL's over the root → upperneck
/// column (spine1 ≈ 21 %, spine2 ≈ 48 % of the way to the neck, which is the start of
/// `upperneck`; HDM05's shoulders then sit at 92 % and the head at 116 %, SMPL's at 88 % and
/// 113 %); spine3 a third of the way up the thorax, where the CMU database's
/// `batch_cmu.py` puts it (35 % of the way from spine2 to the neck); collars 40 % of the way out
/// along the clavicles, which start on the mid-line (as the BVH importer's CMU rig does). The
/// wrist is the start of `lhand`: `lwrist` only twists (`dof ry`, the forearm's pronation) and
/// `lradius` + `lwrist` make the forearm's length, while `lhand` flexes (`rx rz`) like SMPL's
/// wrist.
const SOURCES: [Along; NUM_JOINTS] = [
    ("root", 0.0),
    ("lfemur", 0.0),
    ("rfemur", 0.0),
    ("lowerback", 0.77),
    ("ltibia", 0.0),
    ("rtibia", 0.0),
    ("upperback", 0.73),
    ("lfoot", 0.0),
    ("rfoot", 0.0),
    ("thorax", 0.35),
    ("ltoes", 0.0),
    ("rtoes", 0.0),
    ("upperneck", 0.0),
    ("lclavicle", 0.4),
    ("rclavicle", 0.4),
    ("head", 0.0),
    ("lhumerus", 0.0),
    ("rhumerus", 0.0),
    ("lradius", 0.0),
    ("rradius", 0.0),
    ("lhand", 0.0),
    ("rhand", 0.0),
];

/// An ASF/AMC clip posed on the 22 joints: the source is posed by [`AmcMotion`] (slerped bone
/// rotations, lerped root translation), `SOURCES` picks the 22 points, and bone lengths are
/// retargeted to those of [`crate::skeleton::rest_pose`] with [`retarget_bone_lengths`] (bone
/// directions kept, the root trajectory scaled by the leg-length ratio). Not cyclic.
///
/// [`retarget_bone_lengths`]: crate::motion::retarget_bone_lengths
pub type AsfAmcClip = RetargetedClip<MappedAmc>;

/// An AMC motion with the 22 points [`SOURCES`] picks from its bones.
#[derive(Debug, Clone)]
pub struct MappedAmc {
    motion: AmcMotion,
    /// Per joint: the bone and the fraction of the way along it.
    map: [(usize, f64); NUM_JOINTS],
}

impl MappedAmc {
    /// The 22 points picked from bone starts and ends (source bone lengths).
    fn map_to_joints(&self, bones: &[(DVec3, DVec3)]) -> Pose {
        self.map.map(|(b, t)| bones.get(b).map_or(DVec3::ZERO, |(start, end)| start.lerp(*end, t)))
    }
}

impl SourceSkeleton for MappedAmc {
    fn duration_s(&self) -> f64 {
        self.motion.duration_s()
    }

    fn frame_time_s(&self) -> f64 {
        self.motion.frame_time_s()
    }

    fn mapped_pose_at(&self, t_s: f64) -> Pose {
        self.map_to_joints(&self.motion.positions_at(t_s))
    }

    fn mapped_rest_pose(&self) -> Pose {
        self.map_to_joints(&self.motion.rest_positions())
    }
}

impl AsfAmcClip {
    /// Reads an ASF skeleton and an AMC motion (each within [`MOCAP_FILE_BYTES`]) and maps them;
    /// the clip is named after the AMC file's stem. Bytes that are not UTF-8 are replaced (HDM05
    /// writes Latin-1 paths in its comments).
    pub fn read(asf: &Path, amc: &Path, options: &AsfAmcOptions) -> Result<(Self, Vec<ImportWarning>), ImportError> {
        let asf_text = String::from_utf8_lossy(&read_bytes(asf, &MOCAP_FILE_BYTES)?).into_owned();
        let amc_text = String::from_utf8_lossy(&read_bytes(amc, &MOCAP_FILE_BYTES)?).into_owned();
        let name = amc.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        Self::parse(&name, (&asf_text, asf), (&amc_text, amc), options)
    }

    /// Parses and maps ASF and AMC text, each given with the path used in its messages. Fails
    /// when a bone of the mapping is missing (naming them all) or an option is out of range;
    /// warns when the rest skeleton is implausibly tall or short.
    pub fn parse(
        name: &str,
        (asf_text, asf_path): (&str, &Path),
        (amc_text, amc_path): (&str, &Path),
        options: &AsfAmcOptions,
    ) -> Result<(Self, Vec<ImportWarning>), ImportError> {
        let option_error =
            |message: String| ImportError::Invalid { path: amc_path.into(), location: "options".into(), message };
        if !(FPS_RANGE.0..=FPS_RANGE.1).contains(&options.fps) {
            return Err(option_error(format!(
                "{} frames per second is outside {} to {}",
                short_number(options.fps),
                short_number(FPS_RANGE.0),
                short_number(FPS_RANGE.1)
            )));
        }
        if let Some(m) = options.metres_per_unit.filter(|m| !(m.is_finite() && *m > 0.0)) {
            return Err(option_error(format!(
                "metres per unit must be positive and finite, found {}",
                short_number(m)
            )));
        }
        let (asf, mut warnings) = Asf::parse(asf_text, asf_path)?;
        let mut missing = Vec::new();
        let map = SOURCES.map(|(bone, t)| match asf.bone_index(bone) {
            Some(b) => (b, t),
            None => {
                missing.push(bone);
                (0, 0.0)
            }
        });
        if !missing.is_empty() {
            let root_line = asf.bones().first().map_or(1, |b| b.line);
            return Err(invalid(
                asf_path,
                root_line,
                None,
                format!("the 22-joint mapping needs bones the skeleton lacks: {}", missing.join(", ")),
            ));
        }
        let metres_per_unit = options.metres_per_unit.unwrap_or(asf.metres_per_unit());
        let motion = AmcMotion::parse(amc_text, amc_path, &asf, metres_per_unit, 1.0 / options.fps)?;
        let source = MappedAmc { motion, map };
        let clip = Self { name: name.to_owned(), source, target: crate::skeleton::rest_bone_lengths() };
        let stature_m = clip.stature_m();
        if !(PLAUSIBLE_STATURE_M.0..=PLAUSIBLE_STATURE_M.1).contains(&stature_m) {
            warnings.push(ImportWarning {
                path: asf_path.into(),
                message: format!(
                    "the rest skeleton is {stature_m:.2} m tall at {} m per unit; check the units",
                    short_number(metres_per_unit)
                ),
            });
        }
        Ok((clip, warnings))
    }

    /// The source motion (frames, frame time, skeleton, every bone's positions).
    pub fn motion(&self) -> &AmcMotion {
        &self.source.motion
    }

    /// Height of the rest skeleton (all dofs zero), m: from the lowest bone end (the toe tips)
    /// to the highest (the top of the head bone).
    pub fn stature_m(&self) -> f64 {
        let ys = self.source.motion.rest_positions().into_iter().flat_map(|(a, b)| [a.y, b.y]);
        let (low, high) = ys.fold((f64::MAX, f64::MIN), |(lo, hi), y| (lo.min(y), hi.max(y)));
        (high - low).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use crate::skeleton::bone_lengths;
    use glam::DQuat;

    use super::*;
    use crate::import::asf_amc::tests::{TINY_AMC, TINY_ASF};
    use crate::import::{resample, MocapClip};
    use crate::motion::bone_length_spread;
    use crate::skeleton::Joint;

    /// The HDM05 fixture (actor bk, one two-legged hop, 56 frames at 120 fps).
    fn hdm05() -> AsfAmcClip {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mocap/hdm05");
        let (clip, warnings) = AsfAmcClip::read(
            &dir.join("HDM_bk.asf"),
            &dir.join("HDM_bk_hopBothLegs1hops_020_120.amc"),
            &AsfAmcOptions::default(),
        )
        .unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        clip
    }

    fn at(p: &Pose, j: Joint) -> DVec3 {
        p[j.index()]
    }

    fn lowest_foot(p: &Pose) -> f64 {
        [Joint::LeftAnkle, Joint::RightAnkle, Joint::LeftFoot, Joint::RightFoot]
            .map(|j| at(p, j).y)
            .into_iter()
            .fold(f64::MAX, f64::min)
    }

    #[test]
    fn hdm05_clip_has_its_frames_stature_and_canonical_bones() {
        let c = hdm05();
        assert_eq!((c.name(), c.motion().frames()), ("HDM_bk_hopBothLegs1hops_020_120", 56));
        assert!((c.fps() - 120.0).abs() < 1e-9 && !c.is_cyclic());
        assert!((c.duration_s() - 55.0 / 120.0).abs() < 1e-12);
        assert!((c.motion().metres_per_unit() - 0.0254 / 0.45).abs() < 1e-12);
        let stature = c.stature_m();
        assert!((1.5..2.0).contains(&stature), "stature {stature}");
        let poses = resample(&c, 1.0, None);
        assert_eq!(poses.len(), 10);
        let target = crate::skeleton::rest_bone_lengths();
        for p in &poses {
            assert!(bone_lengths(p).iter().zip(target).all(|(a, b)| (a - b).abs() < 1e-9));
        }
        // Joints on one Acclaim bone keep their distance; spine2, spine3, the neck, the collars
        // and the wrists (after `lwrist`, whose twist axis is not quite along it) lie a bone
        // further, so theirs changes a little.
        let source: Vec<Pose> = (0..56).map(|k| c.mapped_pose_at(k as f64 / 120.0)).collect();
        assert!(bone_length_spread(&source) < 2e-3);
        for j in Joint::ALL.into_iter().filter(|j| {
            !matches!(
                j,
                Joint::Spine2
                    | Joint::Spine3
                    | Joint::Neck
                    | Joint::LeftCollar
                    | Joint::RightCollar
                    | Joint::LeftWrist
                    | Joint::RightWrist
            )
        }) {
            let lengths: Vec<f64> = source.iter().map(|p| bone_lengths(p)[j.index()]).collect();
            assert!(lengths.iter().all(|l| (l - lengths[0]).abs() < 1e-9), "{j}");
        }
    }

    #[test]
    fn hdm05_standing_frame_has_the_feet_on_the_floor_and_the_head_up() {
        let c = hdm05();
        let (src, out) = (c.mapped_pose_at(0.0), c.pose_at(0.0));
        let floor = lowest_foot(&src);
        assert!((-0.02..0.08).contains(&floor), "lowest source foot joint at {floor} m");
        assert!((-0.02..0.12).contains(&lowest_foot(&out)), "lowest foot joint at {} m", lowest_foot(&out));
        let head = at(&out, Joint::Head).y - lowest_foot(&out);
        assert!((1.4..1.9).contains(&head), "head {head} m above the feet");
    }

    #[test]
    fn left_is_plus_x_when_the_toes_face_plus_z() {
        let c = hdm05();
        for k in 0..56 {
            let p = c.pose_at(k as f64 / 120.0);
            let toes = at(&p, Joint::LeftFoot) - at(&p, Joint::LeftAnkle) + at(&p, Joint::RightFoot)
                - at(&p, Joint::RightAnkle);
            // Turn about y so that the toes face +z; the left joints then have the larger x.
            let turn = DQuat::from_rotation_y(-toes.x.atan2(toes.z));
            let x = |j: Joint| (turn * at(&p, j)).x;
            assert!(x(Joint::LeftHip) > x(Joint::RightHip), "frame {k}");
            assert!(x(Joint::LeftShoulder) > x(Joint::RightShoulder), "frame {k}");
        }
        // In the rest skeleton, which faces +z, the left hip is at +x.
        let rest = c.mapped_rest_pose();
        assert!(at(&rest, Joint::LeftHip).x > 0.05 && at(&rest, Joint::RightHip).x < -0.05);
        assert!(at(&rest, Joint::LeftFoot).z > at(&rest, Joint::LeftAnkle).z + 0.05);
    }

    #[test]
    fn mapped_rest_skeleton_has_a_canonical_spine_and_cmu_database_collars() {
        let canon = crate::skeleton::rest_pose();
        let rest = hdm05().mapped_rest_pose();
        for j in [
            Joint::Spine1,
            Joint::Spine2,
            Joint::Spine3,
            Joint::Neck,
            Joint::Head,
            Joint::LeftShoulder,
            Joint::RightShoulder,
        ] {
            let Some(p) = j.parent() else { continue };
            let dir = |q: &Pose| (at(q, j) - at(q, p)).normalize();
            let angle = dir(&rest).dot(dir(&canon)).clamp(-1.0, 1.0).acos().to_degrees();
            assert!(angle < 25.0, "{p}->{j} is {angle:.0} deg off");
        }
        // spine3 sits a third of the way up the thorax, below the clavicles, as in the CMU
        // database (`batch_cmu.py`), not at shoulder height as in the canonical skeleton: the
        // collars are up and out from it.
        for (collar, side) in [(Joint::LeftCollar, 1.0), (Joint::RightCollar, -1.0)] {
            let d = at(&rest, collar) - at(&rest, Joint::Spine3);
            assert!(d.y > 0.05 && d.x * side > 0.05, "{collar}: {d}");
        }
    }

    #[test]
    fn missing_bones_and_bad_options_are_named() {
        let parse = |options: &AsfAmcOptions| {
            AsfAmcClip::parse("tiny", (TINY_ASF, Path::new("tiny.asf")), (TINY_AMC, Path::new("tiny.amc")), options)
                .map(|_| ())
                .unwrap_err()
                .to_string()
        };
        let e = parse(&AsfAmcOptions::default());
        assert!(e.starts_with("tiny.asf: line 10: the 22-joint mapping needs bones"), "{e}");
        assert!(e.contains("lfemur, rfemur, lowerback, ltibia") && e.contains("rhand") && !e.contains("root"), "{e}");
        for options in [
            AsfAmcOptions { fps: 0.0, ..AsfAmcOptions::default() },
            AsfAmcOptions { fps: f64::NAN, ..AsfAmcOptions::default() },
            AsfAmcOptions { metres_per_unit: Some(-1.0), ..AsfAmcOptions::default() },
        ] {
            let e = parse(&options);
            assert!(e.starts_with("tiny.amc: options: "), "{e}");
        }
    }

    #[test]
    fn settable_frame_rate_and_unit() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mocap/hdm05");
        let options = AsfAmcOptions { fps: 60.0, metres_per_unit: Some(0.0254) };
        let (c, warnings) =
            AsfAmcClip::read(&dir.join("HDM_bk.asf"), &dir.join("HDM_bk_hopBothLegs1hops_020_120.amc"), &options)
                .unwrap();
        assert!((c.duration_s() - 55.0 / 60.0).abs() < 1e-12);
        // In inches the same skeleton is 0.45 times as tall, which is reported.
        assert!((c.stature_m() - 0.45 * hdm05().stature_m()).abs() < 1e-9);
        assert!(warnings.len() == 1 && warnings[0].message.contains("check the units"), "{warnings:?}");
    }

    /// Imports every HDM05 clip under `../shared/data/hdm05` (not part of the repository) and
    /// prints counts, warnings, minutes and statures: `cargo test -p motion-core --lib
    /// import::asf_amc -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn measure_hdm05() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/hdm05");
        let mut amcs: Vec<std::path::PathBuf> = Vec::new();
        for split in ["train", "test"] {
            let Ok(classes) = std::fs::read_dir(root.join(split)) else { continue };
            for class in classes.flatten() {
                for file in std::fs::read_dir(class.path()).into_iter().flatten().flatten() {
                    if file.path().extension().is_some_and(|e| e == "amc") {
                        amcs.push(file.path());
                    }
                }
            }
        }
        amcs.sort();
        let (mut ok, mut failed, mut warned, mut seconds) = (0, 0, 0, 0.0);
        let (mut low, mut high) = (f64::MAX, f64::MIN);
        let mut floors = Vec::new();
        for amc in &amcs {
            let stem = amc.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            let actor = stem.split('_').take(2).collect::<Vec<_>>().join("_");
            let asf = amc.with_file_name(format!("{actor}.asf"));
            match AsfAmcClip::read(&asf, amc, &AsfAmcOptions::default()) {
                Ok((clip, warnings)) => {
                    ok += 1;
                    if !warnings.is_empty() {
                        warned += 1;
                        println!("{}: {warnings:?}", amc.display());
                    }
                    seconds += clip.duration_s();
                    low = low.min(clip.stature_m());
                    high = high.max(clip.stature_m());
                    let poses = resample(&clip, 1.0, None);
                    floors.push(poses.iter().map(lowest_foot).fold(f64::MAX, f64::min));
                }
                Err(e) => {
                    failed += 1;
                    println!("{e}");
                }
            }
        }
        floors.sort_by(f64::total_cmp);
        println!(
            "{} AMC files: {ok} imported, {failed} failed, {warned} with warnings; {:.1} minutes; stature {low:.3}-{high:.3} m",
            amcs.len(),
            seconds / 60.0
        );
        if let (Some(a), Some(b)) = (floors.first(), floors.last()) {
            println!("lowest foot joint per clip: {a:.3} to {b:.3} m, median {:.3}", floors[floors.len() / 2]);
        }
    }
}
