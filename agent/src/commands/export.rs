//! `mogen export`: motions already made (an output folder, a `joints.npy`) → BVH, GLB and the
//! viewer page.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use motion_core::export::{read_joints_npy, OutputFolder};
use motion_core::pipeline::{write_exports, Motions};
use motion_core::skeleton::FPS;

use crate::cli::export_formats::{print_exports, ExportFormats};
use crate::cli::flags;
use crate::cli::load::{device, load_program};

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
    /// Frames per second of the motion in the npy (`--fps` sets the files' rate).
    #[arg(long, default_value_t = FPS, value_parser = flags::fps)]
    input_fps: f64,
    #[command(flatten)]
    formats: ExportFormats,
}

pub fn run(args: ExportArgs) -> anyhow::Result<()> {
    let exports = args.formats.options()?;
    let (joints, folder) = if args.input.is_dir() {
        (args.input.join("joints.npy"), args.input.clone())
    } else {
        let folder = args.input.parent().map(Path::to_path_buf).unwrap_or_default();
        (args.input.clone(), folder)
    };
    let motions = read_joints_npy(&joints)?;
    let program_path = args.program.clone().or_else(|| Some(folder.join("program.json")).filter(|p| p.is_file()));
    let device = device()?;
    let checked = program_path.as_deref().map(|path| load_program(path, &device)).transpose()?;
    let program = checked.as_ref().map(|checked| checked.program());
    let report_path = folder.join("report.json");
    let report = if report_path.is_file() {
        let text =
            std::fs::read_to_string(&report_path).with_context(|| format!("reading {}", report_path.display()))?;
        Some(serde_json::from_str(&text).with_context(|| format!("{} is not JSON", report_path.display()))?)
    } else {
        None
    };
    let title = program.map_or_else(|| joints.display().to_string(), |p| p.text.clone());
    let out = OutputFolder::create(&args.out.unwrap_or(folder))?;
    let labels = (0..motions.len()).map(|i| format!("sample {i}")).collect();
    let motions = Motions { title: &title, fps: args.input_fps, poses: &motions, labels, initial: None };
    let manifest = write_exports(&out, motions, checked.as_ref(), report, &exports)
        .with_context(|| format!("exporting into {}", out.target().display()))?;
    // The folder's other files (the run's npy, report, strip) stay.
    out.keep_existing()?;
    let folder = out.commit()?;
    print_exports(&folder, &manifest, args.formats.gif);
    Ok(())
}
