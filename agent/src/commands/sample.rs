//! `mogen sample`: unconstrained motions from the prior for a text prompt.

use std::path::PathBuf;

use clap::Args;
use motion_core::cleanup::FootLockConfig;
use motion_core::diffusion::Guidance;
use motion_core::export::OutputFolder;
use motion_core::generation::method::ensure_finite;
use motion_core::generation::postprocess::clean_up;
use motion_core::motion::tensor_to_poses;
use motion_core::pipeline::{write_exports, Motions};
use motion_core::prior::{RootDecode, Sampling};
use motion_core::render::{motion_strip, StripRow};
use motion_core::skeleton::FPS;

use crate::cli::export_formats::{print_exports, ExportFormats};
use crate::cli::flags;
use crate::cli::load::{device, load_prior};
use agent::paths;

#[derive(Debug, Args)]
pub struct SampleArgs {
    /// Text prompt, e.g. "a person walks forward".
    prompt: String,
    /// Frames per motion at 20 fps (40..=196 is what the prior was trained on).
    #[arg(long, default_value_t = 120, value_parser = flags::frames)]
    frames: usize,
    /// Number of motions.
    #[arg(long, short = 'n', default_value_t = 4, value_parser = flags::samples)]
    samples: usize,
    /// Seed of the start noise (the same seed gives the same motion on the same machine).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// DDIM steps.
    #[arg(long, default_value_t = 50, value_parser = flags::ddim_steps)]
    steps: usize,
    /// Classifier-free guidance scale (1 = conditional only).
    #[arg(long, default_value_t = Guidance::MDM_SCALE, value_parser = flags::guidance)]
    guidance: f64,
    /// Trained prior file.
    #[arg(long, default_value_os_t = paths::default_prior())]
    prior: PathBuf,
    /// How the root trajectory is read from the features: `planted-feet` (the root velocity
    /// follows the feet whose contact is on, so they stay put) or `velocity` (as predicted).
    #[arg(long, default_value_t = RootDecode::default())]
    root_decode: RootDecode,
    /// Switch off the contact-aware clean-up (foot locking with leg IK) of the samples.
    #[arg(long)]
    no_foot_lock: bool,
    #[command(flatten)]
    formats: ExportFormats,
    /// Output folder: joints.npy [n, frames, 22, 3] (m, y up, after the foot clean-up),
    /// features.npy [n, frames, 263] (de-normalised, the root velocity as decoded, before the
    /// clean-up), strip.png, `sample_<i>/motion.{bvh,glb}`, viewer.html, export.json.
    #[arg(long, short, default_value = "out/sample")]
    out: PathBuf,
}

pub fn run(args: SampleArgs) -> anyhow::Result<()> {
    let exports = args.formats.options()?;
    let folder = OutputFolder::create(&args.out)?;
    let device = device()?;
    let mut prior = load_prior(&args.prior, &device)?;
    prior.root_decode = args.root_decode;
    match prior.encoder.heard_words(&args.prompt) {
        Some(heard) if heard.is_empty() => {
            eprintln!("note: the prior knows none of the words of {:?}; sampling unconditionally", args.prompt)
        }
        Some(heard) => eprintln!("the prior hears: {}", heard.join(" ")),
        None => {}
    }
    let restated = prior.restate(&args.prompt);
    if !restated.replaced.is_empty() {
        let words: Vec<String> = restated.replaced.iter().map(|(word, by)| format!("{word} → {by}")).collect();
        eprintln!("restated in the training captions' verbs (WordNet): {:?} ({})", restated.text, words.join(", "));
    }
    match prior.nearest_caption(&args.prompt)? {
        Some(n) if n.replaces_prompt() => eprintln!(
            "no training caption is near the prompt; conditioned on the nearest: {:?} (cosine similarity {:.2})",
            n.caption, n.similarity
        ),
        Some(n) => eprintln!("the nearest training caption: {:?} (cosine similarity {:.2})", n.caption, n.similarity),
        None => {}
    }
    let request = Sampling {
        prompt: &args.prompt,
        frames: args.frames,
        batch: args.samples,
        seed: args.seed,
        steps: args.steps,
        guidance: Guidance { scale: args.guidance },
    };
    let x = prior.sample(&request, &device)?;
    let raw = prior.to_features(&x)?;
    ensure_finite(&raw, "the prior's sampled features")?;
    let lock = FootLockConfig { enabled: !args.no_foot_lock, ..FootLockConfig::default() };
    let (joints, reports) = clean_up(&prior.joints_of(&raw)?, &lock)?;
    if lock.enabled {
        for (i, r) in reports.iter().enumerate() {
            eprintln!(
                "sample {i}: foot clean-up lowered the body {:.3} m, raised sinking frames up to {:.3} m, moved \
                 joints up to {:.3} m ({} sliding contacts cut to their steadiest stretch, {} leg-frames held above \
                 the floor), foot skate {:.3} → {:.3}",
                r.lowered_m,
                r.raised_m,
                r.max_displacement_m,
                r.shortened,
                r.held_above_floor,
                r.skate_before,
                r.skate_after
            );
        }
    }
    ensure_finite(&joints, "the foot clean-up's joint positions")?;
    folder.write_npy("joints.npy", &joints)?;
    folder.write_npy("features.npy", &raw)?;
    let poses = tensor_to_poses(&joints)?;
    let rows: Vec<StripRow<'_>> = poses
        .iter()
        .enumerate()
        .map(|(i, p)| StripRow { label: format!("sample {i} (seed {})", args.seed), poses: p })
        .collect();
    motion_strip(&rows, 8, &[], &[], &args.prompt, &folder.path().join("strip.png"))?;
    let labels = (0..poses.len()).map(|i| format!("sample {i} (seed {})", args.seed)).collect();
    let motions = Motions { title: &args.prompt, fps: FPS, poses: &poses, labels, initial: None };
    let manifest = write_exports(&folder, motions, None, None, &exports)?;
    let out = folder.commit()?;
    print_exports(&out, &manifest, args.formats.gif);
    println!("wrote {}/{{joints.npy,features.npy,strip.png}}", out.display());
    Ok(())
}
