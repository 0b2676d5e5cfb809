//! `mogen report prior`: the prior quality report, per skill family against the corpus's
//! held-out capture, or per label against a database of labelled clips.

use std::path::{Path, PathBuf};

use anyhow::Context;
use candle_core::Device;
use clap::Args;
use motion_core::cleanup::{foot_lock, FootLockConfig};
use motion_core::corpus::family::Family;
use motion_core::corpus::file as corpus_file;
use motion_core::database::MotionDatabase;
use motion_core::generation::inversion::InversionConfig;
use motion_core::metrics::MetricMeans;
use motion_core::prior::{Prior, RootDecode, Sampling};
use motion_core::quality::families::{family_report, FamilyConfig, FamilyQuality};
use motion_core::quality::held_out_ratio::{ratios, Ratio, RATIO_FIGURES};
use motion_core::quality::paraphrases::{paraphrase_report, read_paraphrases, Paraphrase, ParaphraseOutcome};
use motion_core::quality::text_motion::{
    text_motion_report, TextMotionConfig, TextMotionReport, CLEANED, HELD_OUT, SAMPLES, TRAIN,
};
use motion_core::quality::{
    denoising_fidelity, inversion_round_trip, quality_report, Denoising, LabelQuality, QualityConfig, ReportSampling,
};
use motion_core::render::{motion_strip, StripRow};
use motion_core::skeleton::Pose;
use motion_core::text::caption_bank::KEEP_OWN_SIMILARITY;

use agent::paths;

#[derive(Debug, Args)]
pub struct ReportArgs {
    /// Trained prior file.
    #[arg(long, default_value_os_t = paths::default_prior())]
    prior: PathBuf,
    /// Motion corpus whose held-out (test-split) windows the samples of each skill family are
    /// measured against.
    #[arg(long, default_value_os_t = paths::default_corpus(), conflicts_with = "database")]
    corpus: PathBuf,
    /// Report per label against this database of labelled clips (`mogen data build`) instead,
    /// with inversion round trips and one-step denoising figures.
    #[arg(long)]
    database: Option<PathBuf>,
    /// Only this skill family (repeatable; all when absent): walk, run, "turn left",
    /// "turn right", "sideways walk", "sneak/crouch walk", jump, "hop on one foot",
    /// "one-leg balance", carry, "sit down", crawl.
    #[arg(long = "family", value_parser = Family::from_name)]
    families: Vec<Family>,
    /// Samples per label (per family with the corpus).
    #[arg(long, default_value_t = ReportSampling::default().samples)]
    samples: usize,
    /// Frames per sample.
    #[arg(long, default_value_t = ReportSampling::default().frames)]
    frames: usize,
    /// DDIM steps.
    #[arg(long, default_value_t = Denoising::default().ddim_steps)]
    steps: usize,
    /// Classifier-free guidance scale (1 = conditional model alone).
    #[arg(long, default_value_t = Denoising::default().guidance, value_parser = crate::cli::flags::guidance)]
    guidance: f64,
    /// Only this label (repeatable; all labels when absent), e.g. "a person walks forward".
    #[arg(long = "label")]
    labels: Vec<String>,
    /// Seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// DDIM steps of the inversion round trips (the sampler the noise is for).
    #[arg(long, default_value_t = InversionConfig::default().ddim_steps)]
    invert_steps: usize,
    /// Fixed-point iterations per inversion step (the first round trip uses 0, the classic
    /// DDIM inversion).
    #[arg(long, default_value_t = InversionConfig::default().fixed_point_iterations)]
    invert_iterations: usize,
    /// DNO steps polishing the inverted noise against the feature MSE in the third round trip.
    #[arg(long, default_value_t = InversionConfig::default().feature_polish_steps)]
    feature_polish_steps: usize,
    /// DNO steps polishing the inverted noise against the joint error in the third round trip,
    /// after the feature polish.
    #[arg(long, default_value_t = InversionConfig::default().polish_steps)]
    polish_steps: usize,
    /// How the root trajectory is read from the features, for samples and training data alike:
    /// `planted-feet` (the root velocity follows the feet whose contact is on, so they stay
    /// put) or `velocity` (the root velocity as predicted, HumanML3D's decode).
    #[arg(long, default_value_t = RootDecode::default())]
    root_decode: RootDecode,
    /// The text–motion evaluator (`mogen train --evaluator`) for R-precision and FID of samples
    /// against held-out capture, with the corpus; the report says so and leaves them out when
    /// the file is missing.
    #[arg(long, default_value_os_t = paths::default_evaluator())]
    evaluator: PathBuf,
    /// Held-out windows (with one caption each, and as many samples of those captions and
    /// train-split windows) for R-precision and FID; 0 leaves them out.
    #[arg(long, default_value_t = TextMotionConfig::default().pairs)]
    pairs: usize,
    /// Held-out paraphrases (`family<TAB>prompt` lines, written before they were ever sampled),
    /// each sampled and judged by its family's detector, with the corpus; the report says so
    /// and leaves them out when the file is missing.
    #[arg(long, default_value_os_t = paths::default_paraphrases())]
    paraphrases: PathBuf,
    /// Samples per held-out paraphrase; 0 leaves them out.
    #[arg(long, default_value_t = 16)]
    paraphrase_samples: usize,
    /// Output folder (report.md, report.json, and samples.png per label or families/*.png per
    /// family).
    #[arg(long, short, default_value = "out/report")]
    out: PathBuf,
}

/// The motion-metric columns of every report table, in [`metric_values`]' order.
const METRIC_COLUMNS: [&str; 14] = [
    "steps/s",
    "toe flicker",
    "mean acc (m/frame²)",
    "max acc (m/frame²)",
    "foot skate",
    "bone range (m)",
    "deepest joint under floor (m)",
    "lower toe y (m)",
    "airborne",
    "floating (longest flight, s)",
    "turn ° (left / right)",
    "spikes",
    "head y (m)",
    "travel (m)",
];

impl ReportArgs {
    /// The sampling settings of the flags.
    fn sampling(&self) -> ReportSampling {
        ReportSampling { samples: self.samples, frames: self.frames, denoising: self.denoising() }
    }

    fn denoising(&self) -> Denoising {
        Denoising { ddim_steps: self.steps, guidance: self.guidance, seed: self.seed }
    }
}

pub fn run(args: ReportArgs) -> anyhow::Result<()> {
    let device = crate::cli::load::device()?;
    let mut prior = crate::cli::load::load_prior(&args.prior, &device)?;
    prior.root_decode = args.root_decode;
    let Some(database) = &args.database else {
        return run_families(&args, &prior, &device);
    };
    let db = MotionDatabase::load(database)
        .with_context(|| format!("reading {} (build it with `mogen data build`)", database.display()))?;
    let (mut lines, rows) = label_tables(&args, &prior, &db, &device)?;
    lines.push(String::new());
    let walk = "a person walks forward";
    if db.labels().iter().any(|l| l == walk) {
        inversion_lines(&args, &prior, &db, walk, &device, &mut lines)?;
    }
    std::fs::create_dir_all(&args.out)?;
    std::fs::write(args.out.join("report.md"), lines.join("\n") + "\n")?;
    std::fs::write(args.out.join("report.json"), serde_json::to_string_pretty(&rows)?)?;
    sample_strip(&args, &prior, &device)?;
    println!("wrote {}/{{report.md,report.json,samples.png}}", args.out.display());
    Ok(())
}

/// The per-label tables against the database (printed as they come): the samples as the
/// network made them, then after the foot clean-up, each cell beside the training data's.
fn label_tables(
    args: &ReportArgs,
    prior: &Prior,
    db: &MotionDatabase,
    device: &Device,
) -> anyhow::Result<(Vec<String>, Vec<LabelQuality>)> {
    let config = QualityConfig { sampling: args.sampling(), labels: args.labels.clone() };
    let metric_columns = METRIC_COLUMNS.join(" | ");
    let header = format!("| label | {metric_columns} | nearest train (m) | data spacing (m) | diversity (m) |");
    let decode = format!(
        "Root decode: `{}` (samples and training data alike). Each cell: generated / training data. The samples as the network made them, before the foot clean-up:",
        args.root_decode
    );
    println!("{decode}\n");
    let mut lines =
        vec![decode, String::new(), header.clone(), format!("|{}", "---|".repeat(4 + METRIC_COLUMNS.len()))];
    println!("{header}");
    let rows = quality_report(prior, db, &config, device, |r| {
        let line = format!(
            "| {} | {} | {:.3} | {:.3} | {:.3} |",
            r.label,
            metric_cells(&r.samples, &r.training),
            r.nearest_training_m,
            r.training_spacing_m,
            r.sample_diversity_m
        );
        println!("{line}");
        lines.push(line);
    })?;
    let cleaned = [
        String::new(),
        "The same samples after the foot clean-up (defaults; what `mogen sample` writes), each cell: cleaned / training data:".to_owned(),
        String::new(),
        format!("| label | {metric_columns} |"),
        format!("|{}", "---|".repeat(1 + METRIC_COLUMNS.len())),
    ];
    lines.extend(cleaned);
    for r in &rows {
        lines.push(format!("| {} | {} |", r.label, metric_cells(&r.cleaned, &r.training)));
    }
    println!("{}", lines[lines.len() - rows.len() - 4..].join("\n"));
    Ok((lines, rows))
}

/// The `walk` windows' DDIM inversion round trips (classic, fixed-point, polished) and their
/// one-step denoising fidelity at several noise levels, printed and added to `lines`.
fn inversion_lines(
    args: &ReportArgs,
    prior: &Prior,
    db: &MotionDatabase,
    walk: &str,
    device: &Device,
    lines: &mut Vec<String>,
) -> anyhow::Result<()> {
    let polished = InversionConfig {
        ddim_steps: args.invert_steps,
        fixed_point_iterations: args.invert_iterations,
        feature_polish_steps: args.feature_polish_steps,
        polish_steps: args.polish_steps,
        ..InversionConfig::default()
    };
    let round_trips = [
        InversionConfig::unpolished(args.invert_steps, 0),
        InversionConfig::unpolished(args.invert_steps, args.invert_iterations),
        polished,
    ];
    for config in &round_trips {
        let r = inversion_round_trip(prior, db, walk, (8, 120), config, device)?;
        let line = format!(
            "DDIM-{} inversion ({} fixed-point iterations{}) then sampling of {} `{walk}` windows ({} frames): mean joint error {:.4} m, pelvis-relative {:.4} m",
            r.ddim_steps,
            r.fixed_point_iterations,
            if r.feature_polish_steps + r.polish_steps > 0 {
                format!(
                    "; rescaled to unit RMS, {} feature-polish and {} joint-polish steps",
                    r.feature_polish_steps, r.polish_steps
                )
            } else {
                String::new()
            },
            r.windows,
            r.frames,
            r.mean_joint_error_m,
            r.pelvis_relative_error_m
        );
        println!("{line}");
        lines.push(line + "  ");
    }
    for f in denoising_fidelity(prior, db, walk, (16, 120), &[50, 200, 400, 600, 800, 900, 950], device)? {
        let m = &f.metrics;
        let line = format!(
            "One-step x̂0 of {} `{walk}` windows noised to t = {}: MSE {:.4} (copying x_t/√ᾱ: {:.4}; frames shuffled: {:.4}), skate {:.3}, foot acc {:.4} m/frame², travel {:.2} m, {:.2} steps/s",
            m.count,
            f.timestep, f.mse, f.identity_mse, f.shuffled_mse, m.foot_skate_ratio, m.foot_acceleration, m.travel_m, m.pace_steps_per_s
        );
        println!("{line}");
        lines.push(line + "  ");
    }
    Ok(())
}

/// samples.png: two unconstrained samples of each of a few labels (the i-th label's seeds
/// 1000 + 10·i and 1001 + 10·i), after the foot clean-up.
fn sample_strip(args: &ReportArgs, prior: &Prior, device: &Device) -> anyhow::Result<()> {
    let strip_labels = [
        "a person walks forward",
        "a person walks and turns left",
        "a person walks and turns right",
        "a person runs forward",
        "a person crawls forward on the ground",
        "a person jumps forward",
        "a person does a cartwheel to the left",
    ];
    let mut motions = Vec::new();
    for (i, label) in strip_labels.iter().enumerate() {
        for seed in 0..2u64 {
            let request = Sampling {
                prompt: label,
                frames: args.frames,
                batch: 1,
                seed: 1000 + 10 * i as u64 + seed,
                steps: args.steps,
                guidance: motion_core::diffusion::Guidance { scale: args.guidance },
            };
            let x = prior.sample(&request, device)?;
            let poses = motion_core::quality::joints_of(prior, &x)?.remove(0);
            let cleaned = foot_lock(&poses, None, &FootLockConfig::default())?.poses;
            motions.push((format!("{label} (seed {})", 1000 + 10 * i as u64 + seed), cleaned));
        }
    }
    let strip: Vec<StripRow<'_>> = motions.iter().map(|(l, p)| StripRow { label: l.clone(), poses: p }).collect();
    motion_strip(
        &strip,
        8,
        &[],
        &[],
        "unconstrained samples of the shipped prior, after the foot clean-up",
        &args.out.join("samples.png"),
    )?;
    Ok(())
}

/// Issue 40's ratio bars ([`motion_core::quality::held_out_ratio`]) as a table in `lines`: each family's figures over
/// its held-out capture's, on the network's output and after the clean-up; returned for the
/// JSON.
fn ratio_section(rows: &[FamilyQuality], lines: &mut Vec<String>) -> Vec<serde_json::Value> {
    let names: Vec<&str> = RATIO_FIGURES.iter().map(|f| f.name).collect();
    lines.extend([
        String::new(),
        "Issue 40's bar on the figures: each over the held-out capture's figure, on the network's output / after the clean-up; within 1/1.5 to 1.5 times (leg alternations within ±25 %, foot skate at most 1.5 times), **bold** outside, – where capture's figure is about 0 or there is no held-out capture:".to_owned(),
        String::new(),
        format!("| family | {} | outside (network / cleaned) |", names.join(" | ")),
        format!("|{}", "---|".repeat(2 + names.len())),
    ]);
    let mut json = Vec::new();
    for r in rows {
        let held_out = (r.held_out.count > 0).then_some(&r.held_out);
        let (network, cleaned) = (ratios(&r.samples, held_out), ratios(&r.cleaned, held_out));
        let cell = |x: &Ratio| match (x.ratio, x.within) {
            (Some(v), Some(false)) => format!("**{v:.2}**"),
            (Some(v), _) => format!("{v:.2}"),
            _ => "–".to_owned(),
        };
        let cells: Vec<String> =
            network.iter().zip(&cleaned).map(|(n, c)| format!("{} / {}", cell(n), cell(c))).collect();
        let outside = |all: &[Ratio]| all.iter().filter(|x| x.within == Some(false)).count();
        let judged = network.iter().filter(|x| x.within.is_some()).count();
        lines.push(format!(
            "| {} | {} | {} / {} of {judged} |",
            r.family.name(),
            cells.join(" | "),
            outside(&network),
            outside(&cleaned)
        ));
        json.push(serde_json::json!({ "family": r.family.name(), "network": network, "cleaned": cleaned }));
    }
    json
}

/// The per-family report against the corpus's held-out capture: report.md, report.json and one
/// strip per family (2 cleaned samples of each prompt in world coordinates) under `families/`.
fn run_families(args: &ReportArgs, prior: &Prior, device: &Device) -> anyhow::Result<()> {
    let corpus =
        corpus_file::load(&args.corpus).with_context(|| format!("reading the corpus {}", args.corpus.display()))?;
    // Read before the families are sampled, so that a bad file fails at once.
    let paraphrases = held_out_paraphrases(args)?;
    let config = FamilyConfig { sampling: args.sampling(), families: args.families.clone(), ..FamilyConfig::default() };
    let strips = args.out.join("families");
    std::fs::create_dir_all(&strips).with_context(|| format!("creating {}", strips.display()))?;
    let metric_columns = METRIC_COLUMNS.join(" | ");
    let intro = format!(
        "Prior `{}`{} against the held-out (test-split) windows of `{}`, root decode `{}`, {} samples per family ({} frames, {} DDIM steps, guidance {}). Each metric cell: samples / held-out capture; the detector cell: share of samples, cleaned samples and held-out windows passing it.",
        args.prior.display(),
        prior.identity.as_ref().map_or(String::new(), |id| format!(" (SHA-256 {})", id.sha256)),
        args.corpus.display(),
        args.root_decode,
        args.samples,
        args.frames,
        args.steps,
        args.guidance
    );
    let header = format!(
        "| family | held-out windows | detector | passed (samples / cleaned / held-out) | samples passed per prompt (caption-like / paraphrase) | nearest train (m; samples / held-out) | diversity (m) | {metric_columns} |"
    );
    let mut lines =
        vec![intro.clone(), String::new(), header.clone(), format!("|{}", "---|".repeat(7 + METRIC_COLUMNS.len()))];
    println!("{intro}\n\n{header}");
    let rows = family_report(prior, &corpus, &config, device, |r, cleaned| {
        let line = family_row(r);
        println!("{line}");
        lines.push(line);
        family_strip(r, cleaned, &strips);
    })?;
    lines.extend([
        String::new(),
        "After the foot clean-up (what `mogen sample` writes), each cell: cleaned / held-out capture:".to_owned(),
        String::new(),
        format!("| family | {metric_columns} |"),
        format!("|{}", "---|".repeat(1 + METRIC_COLUMNS.len())),
    ]);
    for r in &rows {
        lines.push(format!("| {} | {} |", r.family.name(), metric_cells(&r.cleaned, &r.held_out)));
    }
    let ratios = ratio_section(&rows, &mut lines);
    if prior.captions.is_some() {
        nearest_caption_section(prior, &rows, &mut lines)?;
    }
    let paraphrases = paraphrase_section(args, prior, paraphrases, &mut lines)?;
    let text_motion = text_motion_section(args, prior, &corpus, device, &mut lines)?;
    std::fs::write(args.out.join("report.md"), lines.join("\n") + "\n")?;
    let json = serde_json::json!({
        "prior": prior.identity,
        "families": rows,
        "ratios": ratios,
        "paraphrases": paraphrases,
        "text_motion": text_motion,
    });
    std::fs::write(args.out.join("report.json"), serde_json::to_string_pretty(&json)?)?;
    println!("wrote {}/{{report.md,report.json,families/*.png}}", args.out.display());
    Ok(())
}

/// A family's row of the first table: held-out windows, detector and shares passing it,
/// nearest training distances, diversity and the metric cells.
fn family_row(r: &FamilyQuality) -> String {
    let share = |s: Option<f64>| s.map_or("–".to_owned(), |v| format!("{:.0} %", 100.0 * v));
    let [samples, cleaned_share, held_out] = r.detected;
    format!(
        "| {} | {} | {} | {} / {} / {} | {} | {:.3} / {} | {:.3} | {} |",
        r.family.name(),
        r.held_out.count,
        r.family.detector(),
        share(samples),
        share(cleaned_share),
        share(held_out),
        r.detected_per_prompt.iter().map(|s| share(*s)).collect::<Vec<_>>().join(" / "),
        r.nearest_training_m,
        if r.held_out_nearest_training_m.is_finite() {
            format!("{:.3}", r.held_out_nearest_training_m)
        } else {
            "–".to_owned()
        },
        r.sample_diversity_m,
        metric_cells(&r.samples, &r.held_out)
    )
}

/// `<family>.png` in `strips`: the first two cleaned samples of each prompt, labelled with the
/// prompt they were drawn for; a failure to draw is a warning.
fn family_strip(r: &FamilyQuality, cleaned: &[Vec<Pose>], strips: &Path) {
    let shown: Vec<StripRow<'_>> = (0..r.prompts.len())
        .flat_map(|k| cleaned.iter().zip(&r.sample_prompts).enumerate().filter(move |(_, (_, &p))| p == k).take(2))
        .map(|(i, (poses, &k))| StripRow { label: format!("{} ({i})", r.prompts[k]), poses })
        .collect();
    let file = strips.join(format!("{}.png", r.family.name().replace([' ', '/'], "_")));
    if let Err(e) =
        motion_strip(&shown, 8, &[], &[], &format!("{}: samples after the foot clean-up", r.family.name()), &file)
    {
        eprintln!("warning: {}: {e}", file.display());
    }
}

/// The training caption nearest each prompt, as restated in the captions' verbs, and whether
/// the prompt is conditioned on it, as a table in `lines`.
fn nearest_caption_section(prior: &Prior, rows: &[FamilyQuality], lines: &mut Vec<String>) -> anyhow::Result<()> {
    lines.extend([
        String::new(),
        format!(
            "The training caption nearest each prompt as restated in the captions' verbs (WordNet; cosine similarity of the sentence vectors); a prompt under {KEEP_OWN_SIMILARITY} is conditioned on the caption's vector, the others on their own:"
        ),
        String::new(),
        "| family | prompt | restated | conditioned on | cosine |".to_owned(),
        "|---|---|---|---|---|".to_owned(),
    ]);
    for r in rows {
        for prompt in &r.prompts {
            if let Some(n) = prior.nearest_caption(prompt)? {
                let caption =
                    if n.replaces_prompt() { n.caption } else { format!("(its own vector; nearest: {})", n.caption) };
                let restated = prior.restate(prompt);
                let restated = if restated.replaced.is_empty() { "–".to_owned() } else { restated.text };
                lines.push(format!(
                    "| {} | {prompt} | {restated} | {caption} | {:.2} |",
                    r.family.name(),
                    n.similarity
                ));
            }
        }
    }
    Ok(())
}

/// The metric cells of a report row, each `generated / reference` (`/ –` without reference
/// motions).
fn metric_cells(g: &MetricMeans, d: &MetricMeans) -> String {
    let (generated, reference) = (metric_values(g, true), metric_values(d, false));
    let has_reference = d.count > 0;
    generated
        .iter()
        .zip(&reference)
        .map(|(g, d)| if has_reference { format!("{g} / {d}") } else { format!("{g} / –") })
        .collect::<Vec<_>>()
        .join(" | ")
}

/// The metric figures as the report prints them ([`METRIC_COLUMNS`]); the turn with its
/// left/right shares when `turn_shares`.
fn metric_values(m: &MetricMeans, turn_shares: bool) -> [String; METRIC_COLUMNS.len()] {
    let turn = if turn_shares {
        format!("{:+.0} ({:.0}% / {:.0}%)", m.turn_deg, 100.0 * m.turn_left_share, 100.0 * m.turn_right_share)
    } else {
        format!("{:+.0}", m.turn_deg)
    };
    [
        format!("{:.2}", m.pace_steps_per_s),
        format!("{:.3}", m.toe_flicker),
        format!("{:.4}", m.mean_acceleration),
        format!("{:.3}", m.max_acceleration),
        format!("{:.3}", m.foot_skate_ratio),
        format!("{:.3}", m.bone_length_range_m),
        format!("{:.3}", m.max_under_floor_m),
        format!("{:.3}", m.stance_toe_height_m),
        format!("{:.0}%", 100.0 * m.airborne_share),
        format!("{:.0}% ({:.2})", 100.0 * m.floating_share, m.longest_flight_s),
        turn,
        format!("{:.2}", m.spikes),
        format!("{:.2}", m.head_height_m),
        format!("{:.2}", m.travel_m),
    ]
}

#[derive(Debug, Args)]
pub struct LossArgs {
    /// Loss CSV written by `mogen train --loss-csv` (step,loss,... ; the first two columns are read).
    #[arg(long, default_value = "out/train/loss.csv")]
    csv: PathBuf,
    /// Output PNG.
    #[arg(long, short, default_value = "out/train/loss.png")]
    out: PathBuf,
}

/// Plots a training loss curve (raw and a 100-step moving average, log scale).
pub fn run_loss(args: LossArgs) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&args.csv).with_context(|| format!("reading {}", args.csv.display()))?;
    // A resumed run appends: the last row of a step wins.
    let mut by_step = std::collections::BTreeMap::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        let mut f = line.split(',');
        let (Some(step), Some(loss)) = (f.next(), f.next()) else {
            anyhow::bail!("{}: line {}: expected step,loss,...", args.csv.display(), i + 1);
        };
        let step: f64 = step.parse().with_context(|| format!("{}: line {}: step", args.csv.display(), i + 1))?;
        let loss: f64 = loss.parse().with_context(|| format!("{}: line {}: loss", args.csv.display(), i + 1))?;
        by_step.insert(step as u64, loss);
    }
    let raw: Vec<(f64, f64)> = by_step.into_iter().map(|(s, l)| (s as f64, l)).collect();
    anyhow::ensure!(!raw.is_empty(), "{}: no loss rows", args.csv.display());
    let window = 100usize;
    let smooth: Vec<(f64, f64)> = (0..raw.len())
        .map(|i| {
            let lo = i.saturating_sub(window - 1);
            let s = &raw[lo..=i];
            (raw[i].0, motion_core::numeric::mean(s.iter().map(|p| p.1)))
        })
        .collect();
    motion_core::render::line_plot(
        "TRAINING LOSS (X0 MSE, NORMALISED FEATURES)",
        "STEP",
        "LOSS (LOG SCALE)",
        &[
            motion_core::render::Series { name: "per step", points: &raw, rgb: (180, 180, 220) },
            motion_core::render::Series { name: "100-step mean", points: &smooth, rgb: (200, 40, 40) },
        ],
        true,
        &args.out,
    )?;
    let last = smooth.last().map_or(f64::NAN, |p| p.1);
    println!("wrote {} ({} steps, final 100-step mean loss {last:.4})", args.out.display(), raw.len());
    Ok(())
}

/// R-precision and FID of samples against held-out capture (and of the train split, for scale),
/// appended to the report's lines; `None` when `--pairs 0` or without an evaluator file (the
/// lines say which).
/// The held-out paraphrases a report judges, or why it leaves them out.
enum HeldOut {
    Judged(Vec<Paraphrase>),
    LeftOut(String),
}

/// The held-out paraphrases of `--paraphrases`; a bad file is an error.
fn held_out_paraphrases(args: &ReportArgs) -> anyhow::Result<HeldOut> {
    if args.paraphrase_samples == 0 {
        return Ok(HeldOut::LeftOut("Held-out paraphrases: left out (`--paraphrase-samples 0`).".to_owned()));
    }
    if !args.paraphrases.is_file() {
        let note = format!("Held-out paraphrases: left out, no file at `{}`.", args.paraphrases.display());
        eprintln!("{note}");
        return Ok(HeldOut::LeftOut(note));
    }
    Ok(HeldOut::Judged(read_paraphrases(&args.paraphrases)?))
}

/// The held-out paraphrases' table ([`paraphrase_report`]); `None` when left out.
fn paraphrase_section(
    args: &ReportArgs,
    prior: &Prior,
    paraphrases: HeldOut,
    lines: &mut Vec<String>,
) -> anyhow::Result<Option<Vec<ParaphraseOutcome>>> {
    lines.push(String::new());
    let paraphrases = match paraphrases {
        HeldOut::Judged(paraphrases) => paraphrases,
        HeldOut::LeftOut(note) => {
            lines.push(note);
            return Ok(None);
        }
    };
    let outcomes = paraphrase_report(prior, &paraphrases, args.paraphrase_samples, args.frames, args.denoising())?;
    lines.extend([
        format!(
            "Held-out paraphrases (`{}`, written before any was sampled): {} samples of each (paraphrase i's noise from seed {} + 100·i), the share passing its family's detector on the network's output. Each is restated in the training captions' verbs (WordNet; – when unchanged) and heard as its nearest training caption:",
            args.paraphrases.display(),
            args.paraphrase_samples,
            args.seed
        ),
        String::new(),
        "| family | prompt | restated | heard as (cosine) | passed |".to_owned(),
        "|---|---|---|---|---|".to_owned(),
    ]);
    for o in &outcomes {
        let p = &o.paraphrase;
        let restated = if o.restated == p.prompt { "–" } else { o.restated.as_str() };
        let heard = o.heard_as.as_ref().map_or("–".to_owned(), |(caption, cos)| format!("{caption} ({cos:.2})"));
        let passed = o.detected.map_or("–".to_owned(), |v| format!("{:.0} %", 100.0 * v));
        lines.push(format!("| {} | {} | {restated} | {heard} | {passed} |", p.family.name(), p.prompt));
    }
    let shares: Vec<f64> = outcomes.iter().filter_map(|o| o.detected).collect();
    if !shares.is_empty() {
        let mean = motion_core::numeric::mean(shares.iter().copied());
        lines.push(String::new());
        lines.push(format!(
            "Mean share passing over the {} paraphrases with a detector: {:.0} %.",
            shares.len(),
            100.0 * mean
        ));
    }
    Ok(Some(outcomes))
}

fn text_motion_section(
    args: &ReportArgs,
    prior: &Prior,
    corpus: &motion_core::corpus::Corpus,
    device: &Device,
    lines: &mut Vec<String>,
) -> anyhow::Result<Option<TextMotionReport>> {
    use motion_core::evaluator::Evaluator;
    use motion_core::text::{ConditionEncoder, MINILM_NAME};
    lines.push(String::new());
    if args.pairs == 0 {
        lines.push("Text–motion metrics: left out (`--pairs 0`).".to_owned());
        return Ok(None);
    }
    if !args.evaluator.is_file() {
        let note = format!(
            "Text–motion metrics: left out, no evaluator at `{}` (train one with `mogen train --evaluator FILE`).",
            args.evaluator.display()
        );
        eprintln!("{note}");
        lines.push(note);
        return Ok(None);
    }
    let evaluator = Evaluator::load(&args.evaluator, device)
        .with_context(|| format!("loading the evaluator {}", args.evaluator.display()))?;
    let sentences = ConditionEncoder::sentence(MINILM_NAME, &paths::text_models(), device)
        .with_context(|| format!("loading {MINILM_NAME} from {}", paths::text_models().display()))?;
    let config = TextMotionConfig { pairs: args.pairs, denoising: args.denoising(), ..TextMotionConfig::default() };
    let started = std::time::Instant::now();
    let report = text_motion_report(prior, &evaluator, &sentences, corpus, &config, device, |done, total| {
        eprintln!("text–motion metrics: {done}/{total} samples ({:.0} s)", started.elapsed().as_secs_f64());
    })?;
    let r3 = |name: &str| report.row(name).map_or(f64::NAN, |r| r.r_precision[2]);
    let fid = |name: &str| report.row(name).and_then(|r| r.fid).unwrap_or(f64::NAN);
    lines.extend([
        format!(
            "Text–motion metrics on our evaluator (`{}`): {} held-out windows with one caption each, the prior's sample of each caption, and {} train-split windows; R-precision over pools of {} captions, FID against the held-out capture's embeddings.",
            args.evaluator.display(),
            report.pairs,
            report.pairs,
            report.pool
        ),
        String::new(),
        "| motions | R-precision top 1 | top 2 | top 3 | FID to held-out |".to_owned(),
        "|---|---|---|---|---|".to_owned(),
    ]);
    for row in &report.rows {
        let [r1, r2, r3] = row.r_precision;
        let fid = row.fid.map_or("–".to_owned(), |f| format!("{f:.3}"));
        lines.push(format!("| {} | {r1:.3} | {r2:.3} | {r3:.3} | {fid} |", row.motions));
    }
    lines.extend([
        String::new(),
        format!(
            "Bars (issue 40): samples' top-3 / held-out's = **{:.2}** (at least 0.8; after the clean-up {:.2}); FID(samples) / FID(train split) = **{:.2}** (at most 2; after the clean-up {:.2}).",
            r3(SAMPLES) / r3(HELD_OUT),
            r3(CLEANED) / r3(HELD_OUT),
            fid(SAMPLES) / fid(TRAIN),
            fid(CLEANED) / fid(TRAIN)
        ),
    ]);
    for line in &lines[lines.len() - report.rows.len() - 5..] {
        println!("{line}");
    }
    Ok(Some(report))
}
