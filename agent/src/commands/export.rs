//! `mogen export`: motions already made (an output folder, a `joints.npy`) → BVH, GLB and the
//! viewer page; and the same files for every command that generates motions.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use motion_core::export::bvh::BvhUnit;
use motion_core::export::{read_joints_npy, ExportManifest, OutputFolder};
use motion_core::pipeline::{write_exports, ExportOptions, Motions};
use motion_core::skeleton::FPS;

use super::load::load_program;

#[derive(Debug, Args)]
pub struct ExportArgs {
    /// An output folder of `mogen` (its joints.npy, with program.json and report.json when
    /// present) or a joints.npy file: [frames, 22, 3] or [samples, frames, 22, 3], metres, y up,
    /// +z forward, +x the character's left, the 22 SMPL joints in HumanML3D order.
    input: PathBuf,
    /// Output folder (default: the input folder, or the folder of the npy file).
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// A constraint program whose scene (walls, barriers, ...) is drawn (default: program.json
    /// next to the joints, when there is one).
    #[arg(long, value_name = "FILE")]
    program: Option<PathBuf>,
    /// Frames per second of the motion.
    #[arg(long, default_value_t = FPS, value_parser = super::flags::fps)]
    fps: f64,
    #[command(flatten)]
    formats: ExportFormats,
}

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
}

impl ExportFormats {
    /// The library's export choices.
    pub fn options(self) -> ExportOptions {
        let bvh_unit = if self.centimetres { BvhUnit::Centimetres } else { BvhUnit::Metres };
        ExportOptions { gif: self.gif, bvh_unit }
    }
}

pub fn run(args: ExportArgs) -> anyhow::Result<()> {
    let (joints, folder) = if args.input.is_dir() {
        (args.input.join("joints.npy"), args.input.clone())
    } else {
        let folder = args.input.parent().map(Path::to_path_buf).unwrap_or_default();
        (args.input.clone(), folder)
    };
    let motions = read_joints_npy(&joints)?;
    let program_path = args.program.clone().or_else(|| Some(folder.join("program.json")).filter(|p| p.is_file()));
    let program = program_path.as_deref().map(load_program).transpose()?;
    let report_path = folder.join("report.json");
    let report = if report_path.is_file() {
        let text =
            std::fs::read_to_string(&report_path).with_context(|| format!("reading {}", report_path.display()))?;
        Some(serde_json::from_str(&text).with_context(|| format!("{} is not JSON", report_path.display()))?)
    } else {
        None
    };
    let title = program.as_ref().map_or_else(|| joints.display().to_string(), |p| p.text.clone());
    let out = OutputFolder::create(&args.out.unwrap_or(folder))?;
    let labels = (0..motions.len()).map(|i| format!("sample {i}")).collect();
    let motions = Motions { title: &title, fps: args.fps, poses: &motions, labels };
    let manifest = write_exports(&out, motions, program.as_ref(), report, args.formats.options())
        .with_context(|| format!("exporting into {}", out.target().display()))?;
    print_exports(&out, &manifest, args.formats);
    // The folder's other files (the run's npy, report, strip) stay.
    out.keep_existing()?;
    out.commit()?;
    Ok(())
}

/// Prints what [`motion_core::pipeline::write_exports`] wrote into `out`, with the rotation
/// solve's fit.
pub fn print_exports(out: &OutputFolder, manifest: &ExportManifest, formats: ExportFormats) {
    let worst = manifest.samples.iter().map(|s| s.fit_max_m).fold(0.0, f64::max);
    eprintln!(
        "wrote {}/{{sample_*/motion.bvh,sample_*/motion.glb,viewer.html,export.json}} ({} samples; rigid-skeleton \
         fit: joints within {:.1} mm of the motion)",
        out.target().display(),
        manifest.samples.len(),
        worst * 1000.0
    );
    if formats.gif {
        eprintln!("wrote {}", out.target().join("motion.gif").display());
    }
}
