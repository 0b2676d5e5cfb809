//! Choices about the exported files, as flags, and what was written.

use std::path::{Path, PathBuf};

use clap::Args;
use motion_core::export::bvh::BvhUnit;
use motion_core::export::retarget::{RigConstraint, TargetRig};
use motion_core::export::ExportManifest;
use motion_core::pipeline::ExportOptions;

/// Choices about the exported files, shared by every command that writes them.
#[derive(Debug, Clone, Default, Args)]
pub struct ExportFormats {
    /// Also write motion.gif: the side and top views in world coordinates, animated at the
    /// motion's frame rate.
    #[arg(long)]
    pub gif: bool,
    /// Write BVH in centimetres instead of metres.
    #[arg(long)]
    pub centimetres: bool,
    /// Frame rate of the BVH and GLB files (1 to 240 fps, e.g. 30 or 60 for a game engine,
    /// 24 for film; default: the motion's 20). Every joint's rotation is interpolated by slerp
    /// and the root path linearly between the motion's frames; the duration is kept (less than
    /// one frame short when the rate does not divide it). The viewer, the strip and the npy
    /// files keep the motion's frames.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=i64::from(motion_core::export::resample::MAX_FPS)))]
    pub fps: Option<u32>,
    /// Leave the root's horizontal motion out of the BVH and GLB files, for engines that move
    /// the character themselves: the pelvis stays over its first position on the floor, and
    /// keeps its height and every turn. The viewer, the strip and the npy files keep the path.
    #[arg(long)]
    pub in_place: bool,
    /// Also write every motion onto your own rig: a skinned character (.glb or .gltf: its skin's
    /// joints at their bind pose) or a BVH skeleton (hierarchy and rest offsets), whose bones
    /// follow the Mixamo, Unreal mannequin, Unity humanoid, CMU or SMPL names (any case, any
    /// `name:` prefix); any motion in it is ignored. Written as `sample_<i>/<rig>.bvh` in the rig's
    /// unit and up axis and `sample_<i>/<rig>.glb`: a character's own file (meshes, materials)
    /// with the motion as its animation, or for a BVH rig its bones with a skinned capsule body
    /// and the scene. The feet are kept where the motion plants them; export.json reports what
    /// carried over. Rigs to try: fixtures/rigs/.
    #[arg(long, value_name = "FILE")]
    pub rig: Option<PathBuf>,
    /// With --rig: a JSON file naming the rig's node of each of our 22 joints
    /// ({"pelvis": "Hips", "left_hip": "LeftUpLeg", ...}), for a rig whose names follow no
    /// known convention.
    #[arg(long, value_name = "FILE.json", requires = "rig")]
    pub rig_map: Option<PathBuf>,
}

impl ExportFormats {
    /// The library's export choices, the rig read and matched (so a rig that cannot be used
    /// fails before any work).
    pub fn options(&self) -> anyhow::Result<ExportOptions> {
        let bvh_unit = if self.centimetres { BvhUnit::Centimetres } else { BvhUnit::Metres };
        let rig = self.rig.as_deref().map(|path| TargetRig::read(path, self.rig_map.as_deref())).transpose()?;
        Ok(ExportOptions { gif: self.gif, bvh_unit, fps: self.fps, in_place: self.in_place, rig })
    }
}

/// Prints on stderr what [`motion_core::pipeline::write_exports`] wrote into `folder`, with the
/// rotation solve's fit.
pub fn print_exports(folder: &Path, manifest: &ExportManifest, gif: bool) {
    let worst = manifest.samples.iter().map(|s| s.fit_max_m).fold(0.0, f64::max);
    eprintln!(
        "wrote {}/{{sample_*/motion.bvh,sample_*/motion.glb,viewer.html,export.json}} ({} samples; rigid-skeleton \
         fit: joints within {:.1} mm of the motion)",
        folder.display(),
        manifest.samples.len(),
        worst * 1000.0
    );
    if gif {
        eprintln!("wrote {}", folder.join("motion.gif").display());
    }
    for rig in manifest.samples.iter().filter_map(|s| s.rig.as_ref()) {
        let r = &rig.report;
        let unreached = match r.unreached_frames {
            0 => String::new(),
            n => format!("; in {n} frames an ankle target lay beyond the rig's legs"),
        };
        let lowered = match r.pelvis_lowered_max_m {
            0.0 => String::new(),
            m => format!(", the pelvis lowered up to {:.1} cm for the rig's legs to reach", m * 100.0),
        };
        eprintln!(
            "wrote {} and {} on the rig `{}` ({}, {} nodes, legs {:.2}x ours): joints within {:.1} cm of ours scaled \
             ({}), leg IK moved joints up to {:.1} cm, planted feet within {:.1} mm of their marks, foot skate {:.3} \
             (ours {:.3}){lowered}{unreached}",
            folder.join(&rig.bvh).display(),
            folder.join(&rig.glb).display(),
            r.rig,
            r.matched,
            r.nodes,
            r.leg_ratio,
            r.from_ours_max_m * 100.0,
            r.from_ours_joint,
            r.leg_fix_max_m * 100.0,
            r.contact_miss_max_m * 1000.0,
            r.skate_rig,
            r.skate_ours,
        );
        if !rig.constraints.is_empty() {
            let count = |met: fn(&RigConstraint) -> bool| rig.constraints.iter().filter(|c| met(c)).count();
            let lost: Vec<&str> =
                rig.constraints.iter().filter(|c| c.ours && !c.on_rig).map(|c| c.id.as_str()).collect();
            eprintln!(
                "  the task's {} constraints on the rig: {} met where it stands, {} at our scale (ours: {}){}",
                rig.constraints.len(),
                count(|c| c.on_rig),
                count(|c| c.at_our_scale),
                count(|c| c.ours),
                if lost.is_empty() { String::new() } else { format!("; not carried over: {}", lost.join(", ")) }
            );
        }
    }
    if manifest.samples.iter().any(|s| s.rig.is_some()) {
        eprintln!("wrote {} (each sample on our skeleton and on the rig)", folder.join("rig_strip.png").display());
    }
    if manifest.samples.iter().filter_map(|s| s.rig.as_ref()).any(|r| r.report.from_ours_max_m > 0.03) {
        eprintln!(
            "  the rig's proportions differ from ours: a constraint on a joint's world position may not hold on it"
        );
    }
}
