//! The prior quality report: unconstrained samples per label against the training data, on
//! the motion metrics, plus a memorisation check (nearest training window); and per skill
//! family against the corpus's held-out capture ([`families`]), with issue 40's ratio bars
//! ([`held_out_ratio`]); and held-out paraphrases through the families' detectors
//! ([`paraphrases`]).

mod distances;
pub mod families;
pub mod held_out_ratio;
pub mod paraphrases;
mod sampling;
pub mod text_motion;

#[cfg(test)]
mod test_fixtures;

pub use sampling::{joints_of, Denoising, ReportSampling};

use candle_core::{Device, Tensor};
use serde::Serialize;

use crate::cleanup::{foot_lock, FootLockConfig};
use crate::database::MotionDatabase;
use crate::diffusion::noise::gaussian;
use crate::diffusion::NoiseSchedule;
use crate::generation::inversion::{invert_motion, mean_joint_distance, InversionConfig};
use crate::metrics::MetricMeans;
use crate::motion::tensor_to_poses;
use crate::prior::{Prior, PriorError};
use crate::skeleton::Pose;
use distances::{descriptors, mean_pairwise, nearest_distances};

/// One label's row of the report.
#[derive(Debug, Clone, Serialize)]
pub struct LabelQuality {
    /// The label (also the prompt).
    pub label: String,
    /// Generated samples, as the network made them.
    pub samples: MetricMeans,
    /// The same samples after the foot clean-up with its defaults ([`fn@foot_lock`]): the motions
    /// `mogen sample` writes.
    pub cleaned: MetricMeans,
    /// Training windows of the label (cropped to the same length).
    pub training: MetricMeans,
    /// Mean over samples of the RMS joint distance (root-relative, heading-free) to the nearest
    /// training crop of any label, m. Near 0 would mean copying.
    pub nearest_training_m: f64,
    /// The same distance from each training crop to the nearest crop of another sequence, m:
    /// the spacing of the data itself, for scale.
    pub training_spacing_m: f64,
    /// RMS joint distance between the label's samples, m: how different seeds are.
    pub sample_diversity_m: f64,
}

/// Settings of the per-label report.
#[derive(Debug, Clone, Default)]
pub struct QualityConfig {
    /// The samples (label i's noise from seed + i).
    pub sampling: ReportSampling,
    /// Only these labels (all of the database's when empty).
    pub labels: Vec<String>,
}

/// Runs the report over every label of the database; `on_label` is called after each.
pub fn quality_report(
    prior: &Prior,
    db: &MotionDatabase,
    config: &QualityConfig,
    device: &Device,
    mut on_label: impl FnMut(&LabelQuality),
) -> Result<Vec<LabelQuality>, PriorError> {
    let fail = |e: candle_core::Error| PriorError::Compute { what: "the quality report", message: e.to_string() };
    let t = config.sampling.frames;
    // Every training window long enough, cropped to its first `t` frames.
    let crops: Vec<(usize, String, Tensor)> = db
        .windows()
        .iter()
        .filter(|w| w.frames >= t)
        .map(|w| Ok((w.sequence, db.label(w).to_owned(), db.window_tensor(w, device)?.narrow(0, 0, t)?)))
        .collect::<candle_core::Result<_>>()
        .map_err(fail)?;
    let train_desc = descriptors(&crops.iter().map(|c| c.2.clone()).collect::<Vec<_>>()).map_err(fail)?;
    if let Some(unknown) = config.labels.iter().find(|l| !db.labels().contains(l)) {
        return Err(PriorError::Compute {
            what: "the quality report",
            message: format!("label `{unknown}` is not in the database (labels: {})", db.labels().join("; ")),
        });
    }
    let mut rows = Vec::new();
    for (i, label) in db.labels().iter().enumerate() {
        if !config.labels.is_empty() && !config.labels.contains(label) {
            continue;
        }
        let request = config.sampling.denoising.request(label, t, config.sampling.samples, i as u64);
        let x = prior.sample(&request, device)?;
        let raw = prior.to_features(&x).map_err(fail)?;
        let samples = tensor_to_poses(&prior.joints_of(&raw).map_err(fail)?).map_err(fail)?;
        let cleaned: Vec<Vec<Pose>> = samples
            .iter()
            .map(|m| foot_lock(m, None, &FootLockConfig::default()).map(|c| c.poses))
            .collect::<Result<_, _>>()
            .map_err(|e| PriorError::Compute { what: "the quality report", message: e.to_string() })?;
        let sample_desc = descriptors(
            &raw.chunk(raw.dim(0).map_err(fail)?, 0)
                .map_err(fail)?
                .iter()
                .map(|s| s.squeeze(0))
                .collect::<candle_core::Result<Vec<_>>>()
                .map_err(fail)?,
        )
        .map_err(fail)?;
        let own: Vec<usize> = crops.iter().enumerate().filter(|(_, c)| &c.1 == label).map(|(k, _)| k).collect();
        let own_crops: Vec<Tensor> =
            own.iter().map(|k| crops[*k].2.unsqueeze(0)).collect::<candle_core::Result<_>>().map_err(fail)?;
        let training = if own_crops.is_empty() {
            MetricMeans::default()
        } else {
            // The data's root goes through the same decode as the samples'.
            let stacked = prior.root_decode.apply(&Tensor::cat(&own_crops, 0).map_err(fail)?).map_err(fail)?;
            MetricMeans::of(&tensor_to_poses(&prior.joints_of(&stacked).map_err(fail)?).map_err(fail)?)
        };
        let nearest = nearest_distances(&sample_desc, &train_desc, |_, _| true).map_err(fail)?;
        let spacing = if own.is_empty() {
            f64::NAN
        } else {
            let own_desc = train_desc
                .index_select(
                    &Tensor::from_vec(own.iter().map(|k| *k as u32).collect::<Vec<_>>(), own.len(), device)
                        .map_err(fail)?,
                    0,
                )
                .map_err(fail)?;
            nearest_distances(&own_desc, &train_desc, |a, b| crops[own[a]].0 != crops[b].0).map_err(fail)?
        };
        let diversity = mean_pairwise(&sample_desc).map_err(fail)?;
        let row = LabelQuality {
            label: label.clone(),
            samples: MetricMeans::of(&samples),
            cleaned: MetricMeans::of(&cleaned),
            training,
            nearest_training_m: nearest,
            training_spacing_m: spacing,
            sample_diversity_m: diversity,
        };
        on_label(&row);
        rows.push(row);
    }
    Ok(rows)
}

/// How well inversion followed by sampling reproduces training windows.
#[derive(Debug, Clone, Serialize)]
pub struct RoundTrip {
    /// Windows inverted.
    pub windows: usize,
    /// Frames per window.
    pub frames: usize,
    /// DDIM steps, fixed-point iterations and polish steps used.
    pub ddim_steps: usize,
    /// Fixed-point iterations per inversion step (0 = classic DDIM inversion).
    pub fixed_point_iterations: usize,
    /// DNO steps of the feature polish (0 = none).
    pub feature_polish_steps: usize,
    /// DNO steps of the joint polish (0 = none).
    pub polish_steps: usize,
    /// Mean over windows, frames and joints of the world-frame joint error, m (the whole
    /// motion, trajectory included).
    pub mean_joint_error_m: f64,
    /// The same with each frame's pelvis subtracted: the poses alone, m.
    pub pelvis_relative_error_m: f64,
}

/// Inverts the first `windows` training windows of `label` (their first `frames` frames,
/// conditioned on the label) with [`invert_motion`] and samples them back.
pub fn inversion_round_trip(
    prior: &Prior,
    db: &MotionDatabase,
    label: &str,
    (windows, frames): (usize, usize),
    config: &InversionConfig,
    device: &Device,
) -> Result<RoundTrip, PriorError> {
    let fail = |e: candle_core::Error| PriorError::Compute { what: "the inversion round trip", message: e.to_string() };
    let x0 = label_crops(prior, db, label, (windows, frames), device)?;
    let count = x0.dim(0).map_err(fail)?;
    let text = prior.encode_text(&vec![label; count], device).map_err(fail)?;
    let back = invert_motion(prior, &x0, &text, config, |_| {}).map_err(fail)?.x;
    let original = prior.to_joints(&x0).map_err(fail)?;
    let rebuilt = prior.to_joints(&back).map_err(fail)?;
    let error = |a: &Tensor, b: &Tensor| -> candle_core::Result<f64> {
        mean_joint_distance(a, b)?.mean_all()?.to_dtype(candle_core::DType::F64)?.to_scalar::<f64>()
    };
    let relative = |j: &Tensor| j.broadcast_sub(&j.narrow(2, 0, 1)?);
    Ok(RoundTrip {
        windows: count,
        frames,
        ddim_steps: config.ddim_steps,
        fixed_point_iterations: config.fixed_point_iterations,
        feature_polish_steps: config.feature_polish_steps,
        polish_steps: config.polish_steps,
        mean_joint_error_m: error(&original, &rebuilt).map_err(fail)?,
        pelvis_relative_error_m: error(&relative(&original).map_err(fail)?, &relative(&rebuilt).map_err(fail)?)
            .map_err(fail)?,
    })
}

/// How well the denoiser restores noised training windows in one step, at one timestep.
#[derive(Debug, Clone, Serialize)]
pub struct DenoisingFidelity {
    /// Diffusion timestep t (0..999).
    pub timestep: usize,
    /// Mean squared error of x̂0 in normalised feature space.
    pub mse: f64,
    /// The same error of the trivial estimate x_t/√ᾱ_t, (1 − ᾱ_t)/ᾱ_t: a denoiser that does
    /// not beat it has learned to copy its input, not to remove noise.
    pub identity_mse: f64,
    /// The same error when the frames of x_t enter in a seeded random order (x̂0 put back in
    /// order): as large as `mse` for a denoiser that ignores temporal context and denoises each
    /// frame on its own, larger the more it uses its neighbours.
    pub shuffled_mse: f64,
    /// Motion metrics of the x̂0 motions.
    pub metrics: MetricMeans,
}

/// Noises the first `windows` training windows of `label` (their first `frames` frames) to
/// each of `timesteps` with seeded noise, predicts x̂0 in one conditional denoiser call, and
/// measures it. The training windows' own metrics are [`LabelQuality::training`].
pub fn denoising_fidelity(
    prior: &Prior,
    db: &MotionDatabase,
    label: &str,
    (windows, frames): (usize, usize),
    timesteps: &[usize],
    device: &Device,
) -> Result<Vec<DenoisingFidelity>, PriorError> {
    let fail = |e: candle_core::Error| PriorError::Compute { what: "the denoising fidelity", message: e.to_string() };
    let x0 = label_crops(prior, db, label, (windows, frames), device)?;
    let batch = x0.dim(0).map_err(fail)?;
    let text = prior.encode_text(&vec![label; batch], device).map_err(fail)?;
    let noise = gaussian(x0.shape(), 0, device).map_err(fail)?;
    let schedule = NoiseSchedule::mdm();
    let (order, restore) = shuffled_frames(frames, device).map_err(fail)?;
    timesteps
        .iter()
        .map(|&t| {
            let abar = *schedule.alphas_cumprod().get(t).ok_or_else(|| PriorError::Compute {
                what: "the denoising fidelity",
                message: format!("timestep {t} outside 0..{}", schedule.num_timesteps()),
            })?;
            let run = || -> candle_core::Result<DenoisingFidelity> {
                let ts = Tensor::full(t as u32, batch, device)?;
                let x_t = schedule.q_sample(&x0, &ts, &noise)?;
                let denoise = |x: &Tensor| crate::diffusion::Denoiser::predict_x0(&prior.mdm, x, &ts, &text);
                let mse =
                    |x: &Tensor| (x - &x0)?.sqr()?.mean_all()?.to_dtype(candle_core::DType::F64)?.to_scalar::<f64>();
                let x0_hat = denoise(&x_t)?;
                let shuffled = denoise(&x_t.index_select(&order, 1)?)?.index_select(&restore, 1)?;
                Ok(DenoisingFidelity {
                    timestep: t,
                    mse: mse(&x0_hat)?,
                    identity_mse: (1.0 - abar) / abar,
                    shuffled_mse: mse(&shuffled)?,
                    metrics: MetricMeans::of(&joints_of(prior, &x0_hat)?),
                })
            };
            run().map_err(fail)
        })
        .collect()
}

/// A seeded random permutation of `frames` frame indices and its inverse, `[frames]` u32 each.
fn shuffled_frames(frames: usize, device: &Device) -> candle_core::Result<(Tensor, Tensor)> {
    use rand::seq::SliceRandom;
    use rand::SeedableRng;
    let mut order: Vec<u32> = (0..frames as u32).collect();
    order.shuffle(&mut rand::rngs::StdRng::seed_from_u64(0));
    let mut restore = vec![0u32; frames];
    for (position, &frame) in order.iter().enumerate() {
        restore[frame as usize] = position as u32;
    }
    Ok((Tensor::new(order, device)?, Tensor::new(restore, device)?))
}

/// The first `windows` windows of `label` with at least `frames` frames, cropped to their
/// first `frames` frames and normalised: `[windows, frames, 263]`.
fn label_crops(
    prior: &Prior,
    db: &MotionDatabase,
    label: &str,
    (windows, frames): (usize, usize),
    device: &Device,
) -> Result<Tensor, PriorError> {
    let fail = |e: candle_core::Error| PriorError::Compute { what: "the training crops", message: e.to_string() };
    let crops = db
        .windows()
        .iter()
        .filter(|w| db.label(w) == label && w.frames >= frames)
        .take(windows)
        .map(|w| db.window_tensor(w, device)?.narrow(0, 0, frames))
        .collect::<candle_core::Result<Vec<_>>>()
        .map_err(fail)?;
    if crops.is_empty() {
        return Err(PriorError::Compute {
            what: "the training crops",
            message: format!("no window of `{label}` has {frames} frames"),
        });
    }
    prior.mean_std.normalize(&Tensor::stack(&crops, 0).map_err(fail)?).map_err(fail)
}
