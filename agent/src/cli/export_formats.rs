//! Choices about the exported files, as flags, and what was written.

use std::path::Path;

use clap::Args;
use motion_core::export::bvh::BvhUnit;
use motion_core::export::ExportManifest;
use motion_core::pipeline::ExportOptions;

/// Choices about the exported files, shared by every command that writes them.
#[derive(Debug, Clone, Copy, Default, Args)]
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
}

impl ExportFormats {
    /// The library's export choices.
    pub fn options(self) -> ExportOptions {
        let bvh_unit = if self.centimetres { BvhUnit::Centimetres } else { BvhUnit::Metres };
        ExportOptions { gif: self.gif, bvh_unit, fps: self.fps, in_place: self.in_place }
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
}
