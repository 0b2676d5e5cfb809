//! The motion prior as shipped: the MDM denoiser, its text encoder and the normalisation
//! statistics of its training data, in one safetensors file.
//!
//! File layout: the denoiser's tensors under their official MDM names, `normalization.mean`
//! and `normalization.std` (`[263]`), and header metadata `mdm_config` (JSON of
//! [`MdmConfig`]), the text encoder (either `vocabulary`, JSON of
//! [`VocabularyEncoder`](crate::text::vocabulary::VocabularyEncoder), or
//! `sentence_encoder`, the name of a sentence encoder such as [`MINILM_NAME`], whose weights live
//! in the text models folder, not in the prior) and `rest_skeleton` (JSON of [`RestSkeleton`], the
//! training data's bone lengths; absent in files written before it existed). A prior conditioned
//! on a sentence encoder may carry its [`CaptionBank`]: the distinct training captions' vectors
//! as `conditioning.captions` (`[captions, text_dim]`, f16) and the captions themselves as
//! `caption_bank` (a JSON list); a free prompt far from every training caption is then
//! conditioned on the nearest one ([`Prior::caption_conditions`]), after its verbs that no
//! caption uses are restated through WordNet (read from the text models folder's
//! [`wordnet::FOLDER`]).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use candle_core::{DType, Device, Tensor};
use candle_nn::VarBuilder;
use serde::{Deserialize, Serialize};

use crate::diffusion::noise::gaussian;
use crate::diffusion::{DdimSampler, Guidance, NoiseSchedule};
use crate::files::FileError;
use crate::model::{Mdm, MdmConfig};
use crate::representation::{
    recover_from_ric, rigid_bones, root_velocity_from_planted_feet, MeanStd, NormalizationError, RestSkeleton,
};
use crate::tensor_file::{read_metadata, write_safetensors};
use crate::text::caption_bank::{CaptionBank, NearestCaption};
use crate::text::restatement::Restated;
use crate::text::wordnet::{self, WordNet};
use crate::text::{ConditionEncoder, TextEncoder, MINILM_NAME};

const MEAN_KEY: &str = "normalization.mean";
const STD_KEY: &str = "normalization.std";
const REST_KEY: &str = "rest_skeleton";
const VOCABULARY_KEY: &str = "vocabulary";
const SENTENCE_KEY: &str = "sentence_encoder";
const BANK_KEY: &str = "conditioning.captions";
const BANK_TEXT_KEY: &str = "caption_bank";

/// Errors loading or saving a prior.
#[derive(Debug, thiserror::Error)]
pub enum PriorError {
    /// The prior file could not be read or written, or is malformed or incomplete.
    #[error(transparent)]
    File(#[from] FileError),
    /// A computation with the prior failed (sampling, a report): what was being done, and why.
    #[error("{what}: {message}")]
    Compute {
        /// What was being done (`sampling`, `the family report`, ...).
        what: &'static str,
        /// What went wrong.
        message: String,
    },
    /// Bad normalisation statistics.
    #[error("{path}: {source}")]
    Normalization {
        /// The file.
        path: PathBuf,
        /// What is wrong (boxed: a candle error inside is large).
        source: Box<NormalizationError>,
    },
}

/// What [`Prior::sample`] draws: `batch` motions of `frames` frames for `prompt` from the start
/// noise of `seed`, through DDIM with `steps` steps and classifier-free guidance `guidance`.
#[derive(Debug, Clone, Copy)]
pub struct Sampling<'a> {
    /// The text prompt.
    pub prompt: &'a str,
    /// Frames per motion (20 fps).
    pub frames: usize,
    /// Motions.
    pub batch: usize,
    /// Seed of the start noise.
    pub seed: u64,
    /// DDIM steps.
    pub steps: usize,
    /// Classifier-free guidance.
    pub guidance: Guidance,
}

/// How the root's x/z motion is read from generated features, which carry it twice: as the
/// root velocity and through the planted feet (root-relative foot positions plus contacts).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RootDecode {
    /// The root velocity is re-derived from the feet whose contact is on, so they stay where
    /// they were planted ([`root_velocity_from_planted_feet`]); frames without a planted foot
    /// keep the predicted velocity. For priors whose root velocity runs ahead of their legs
    /// (such as the incoherent 3,000-step prior of `fixtures/model/HISTORY.md`).
    PlantedFeet,
    /// The predicted root velocity as it is (HumanML3D's `recover_from_ric`). The default: the
    /// temporally coherent prior's walks travel and step like the data with it.
    #[default]
    Velocity,
}

impl RootDecode {
    /// De-normalised features `[batch, frames, 263]` with the root velocity decoded this way.
    pub fn apply(self, raw: &Tensor) -> candle_core::Result<Tensor> {
        match self {
            Self::PlantedFeet => root_velocity_from_planted_feet(raw),
            Self::Velocity => Ok(raw.clone()),
        }
    }
}

impl std::str::FromStr for RootDecode {
    type Err = String;

    /// `planted-feet` or `velocity`.
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "planted-feet" => Ok(Self::PlantedFeet),
            "velocity" => Ok(Self::Velocity),
            other => Err(format!("unknown root decode {other:?}: expected \"planted-feet\" or \"velocity\"")),
        }
    }
}

impl std::fmt::Display for RootDecode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::PlantedFeet => "planted-feet",
            Self::Velocity => "velocity",
        })
    }
}

/// A trained denoiser with everything needed to use it.
#[derive(Debug, Clone)]
pub struct Prior {
    /// The denoiser (frozen weights).
    pub mdm: Mdm,
    /// The text encoder it was trained with.
    pub encoder: ConditionEncoder,
    /// Normalisation of its features.
    pub mean_std: MeanStd,
    /// How generated features become a root trajectory (not stored in the file; default
    /// [`RootDecode::Velocity`]).
    pub root_decode: RootDecode,
    /// Bone lengths of the training data: generated joints are re-derived on them, so bones are
    /// rigid by construction ([`rigid_bones`]); `None` for files without it (joints as decoded).
    pub rest: Option<RestSkeleton>,
    /// The captions it was trained on, when the file carries them: a free prompt far from all
    /// of them is conditioned on the nearest ([`Self::caption_conditions`]).
    pub captions: Option<CaptionBank>,
    /// The file it was loaded from ([`Prior::load`]); `None` for a prior built in memory.
    pub identity: Option<PriorIdentity>,
}

/// Which file a prior was loaded from: its name and the SHA-256 of its bytes. Every run's report
/// carries it ([`crate::evaluation::TaskReport::prior`]), so that a figure names the model that
/// made it and a stored result is not taken for another model's.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PriorIdentity {
    /// The file's name, without its folder.
    pub file: String,
    /// SHA-256 of the file's bytes, 64 lower-case hex digits.
    pub sha256: String,
}

impl PriorIdentity {
    /// The identity of the file at `path` holding `bytes`.
    pub fn of(path: &Path, bytes: &[u8]) -> Self {
        let file = path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned());
        Self { file, sha256: crate::files::sha256_hex(bytes) }
    }
}

impl Prior {
    /// Loads a prior file onto `device`; a prior conditioned on a sentence encoder loads it from
    /// `text_models`, the folder holding one folder per encoder (`fixtures/text`).
    pub fn load(path: &Path, text_models: &Path, device: &Device) -> Result<Self, PriorError> {
        let format = |message: String| PriorError::from(FileError::format(path, message));
        let bytes = std::fs::read(path).map_err(|e| FileError::io(path, &e))?;
        let meta = read_metadata(&bytes).map_err(format)?;
        let get = |key: &str| meta.get(key).ok_or_else(|| format(format!("no `{key}` in the header metadata")));
        let cfg: MdmConfig =
            serde_json::from_str(get("mdm_config")?).map_err(|e| format(format!("bad mdm_config: {e}")))?;
        let encoder = match (meta.get(VOCABULARY_KEY), meta.get(SENTENCE_KEY)) {
            (Some(json), None) => ConditionEncoder::Vocabulary(
                serde_json::from_str(json).map_err(|e| format(format!("bad {VOCABULARY_KEY}: {e}")))?,
            ),
            (None, Some(name)) => ConditionEncoder::sentence(name, text_models, device)
                .map_err(|e| format(format!("its text encoder {name:?} (from {}): {e}", text_models.display())))?,
            (Some(_), Some(_)) => return Err(format(format!("both `{VOCABULARY_KEY}` and `{SENTENCE_KEY}` are set"))),
            (None, None) => {
                return Err(format(format!("no text encoder (`{VOCABULARY_KEY}` or `{SENTENCE_KEY}`) in the metadata")))
            }
        };
        if encoder.dim() != cfg.text_dim {
            return Err(format(format!(
                "the text encoder gives {}-d vectors, the model expects {}",
                encoder.dim(),
                cfg.text_dim
            )));
        }
        let mut tensors = candle_core::safetensors::load_buffer(&bytes, device).map_err(|e| format(e.to_string()))?;
        for (name, tensor) in &tensors {
            let values = tensor
                .to_dtype(DType::F32)
                .and_then(|t| t.flatten_all())
                .and_then(|t| t.to_vec1::<f32>())
                .map_err(|e| format(format!("tensor `{name}`: {e}")))?;
            let bad = values.iter().filter(|v| !v.is_finite()).count();
            if bad > 0 {
                return Err(format(format!(
                    "tensor `{name}` has {bad} of {} values NaN or infinite; the file is damaged",
                    values.len()
                )));
            }
        }
        let stat = |key: &str| -> Result<Vec<f32>, PriorError> {
            tensors
                .get(key)
                .ok_or_else(|| format(format!("missing tensor `{key}`")))?
                .to_dtype(DType::F32)
                .and_then(|t| t.to_vec1::<f32>())
                .map_err(|e| format(format!("tensor `{key}`: {e}")))
        };
        let mean_std = MeanStd::from_vecs(stat(MEAN_KEY)?, stat(STD_KEY)?, device)
            .map_err(|source| PriorError::Normalization { path: path.into(), source: Box::new(source) })?;
        let rest = meta
            .get(REST_KEY)
            .map(|json| serde_json::from_str(json).map_err(|e| format(format!("bad {REST_KEY}: {e}"))))
            .transpose()?;
        let captions = match (tensors.remove(BANK_KEY), meta.get(BANK_TEXT_KEY)) {
            (None, None) => None,
            (Some(vectors), Some(json)) if matches!(encoder, ConditionEncoder::MiniLm(_)) => {
                let captions = serde_json::from_str(json).map_err(|e| format(format!("bad {BANK_TEXT_KEY}: {e}")))?;
                if vectors.dims().get(1) != Some(&cfg.text_dim) {
                    return Err(format(format!("`{BANK_KEY}` is {:?}, not [_, {}]", vectors.dims(), cfg.text_dim)));
                }
                let bank = CaptionBank::new(captions, vectors).map_err(|e| format(format!("`{BANK_KEY}`: {e}")))?;
                let wordnet = WordNet::load(&text_models.join(wordnet::FOLDER))
                    .map_err(|e| format(format!("its caption bank's WordNet: {e}")))?;
                Some(bank.with_wordnet(std::sync::Arc::new(wordnet)))
            }
            (Some(_), Some(_)) => return Err(format(format!("`{BANK_KEY}` needs a sentence encoder"))),
            _ => return Err(format(format!("`{BANK_KEY}` and `{BANK_TEXT_KEY}` come together; one is missing"))),
        };
        let mdm =
            Mdm::new(cfg, VarBuilder::from_tensors(tensors, DType::F32, device)).map_err(|e| format(e.to_string()))?;
        let identity = Some(PriorIdentity::of(path, &bytes));
        Ok(Self { mdm, encoder, mean_std, root_decode: RootDecode::default(), rest, captions, identity })
    }

    /// Writes the prior as one safetensors file.
    pub fn save(&self, path: &Path) -> Result<(), PriorError> {
        Self::write(
            path,
            self.mdm.named_parameters(),
            self.mdm.config(),
            &self.encoder,
            &self.mean_std,
            self.rest.as_ref(),
            self.captions.as_ref(),
        )
    }

    /// Writes a prior from named denoiser tensors (e.g. EMA weights during training).
    pub fn write(
        path: &Path,
        params: &[(String, Tensor)],
        cfg: &MdmConfig,
        encoder: &ConditionEncoder,
        mean_std: &MeanStd,
        rest: Option<&RestSkeleton>,
        captions: Option<&CaptionBank>,
    ) -> Result<(), PriorError> {
        let format = |message: String| PriorError::from(FileError::format(path, message));
        let mut tensors: Vec<(String, Tensor)> = params.iter().map(|(n, t)| (n.clone(), t.detach())).collect();
        tensors.push((MEAN_KEY.into(), mean_std.mean().clone()));
        tensors.push((STD_KEY.into(), mean_std.std().clone()));
        let text = match encoder {
            ConditionEncoder::Vocabulary(v) => {
                (VOCABULARY_KEY.to_owned(), serde_json::to_string(v).map_err(|e| format(e.to_string()))?)
            }
            ConditionEncoder::MiniLm(_) => (SENTENCE_KEY.to_owned(), MINILM_NAME.to_owned()),
        };
        let mut metadata = HashMap::from([
            ("mdm_config".to_owned(), serde_json::to_string(cfg).map_err(|e| format(e.to_string()))?),
            text,
        ]);
        if let Some(rest) = rest {
            metadata.insert(REST_KEY.to_owned(), serde_json::to_string(rest).map_err(|e| format(e.to_string()))?);
        }
        if let Some(bank) = captions {
            let vectors = bank.vectors().to_dtype(DType::F16).map_err(|e| format(e.to_string()))?;
            tensors.push((BANK_KEY.into(), vectors));
            let json = serde_json::to_string(bank.captions()).map_err(|e| format(e.to_string()))?;
            metadata.insert(BANK_TEXT_KEY.to_owned(), json);
        }
        write_safetensors(path, &tensors, metadata).map_err(format)
    }

    /// Condition vectors of prompts, `[prompts.len(), text_dim]`, as the text encoder gives
    /// them. What constrained generation (DNO, RG-DNO) conditions on: the program's constraints
    /// say what the body does, and a program's text heard as its nearest training caption gains
    /// words it did not ask for (Task 3's "a man walks forwards and raises up hands at the same
    /// time" became "... raising both hands, holding the hands together", and three of four
    /// RG-DNO samples started bent double; on its own vector all four met every constraint,
    /// `fixtures/model/training/README.md`).
    pub fn encode_text(&self, prompts: &[&str], device: &Device) -> candle_core::Result<Tensor> {
        self.encoder.encode(prompts, device)
    }

    /// Condition vectors of free prompts (sampling without constraints), `[prompts.len(),
    /// text_dim]`: [`Self::encode_text`]'s, except that for a prior with a [`CaptionBank`] a
    /// prompt far from every training caption takes the nearest one's ([`CaptionBank::snap`]).
    pub fn caption_conditions(&self, prompts: &[&str], device: &Device) -> candle_core::Result<Tensor> {
        match &self.captions {
            Some(bank) => {
                let restated: Vec<String> = prompts.iter().map(|p| bank.restate(p).text).collect();
                let restated: Vec<&str> = restated.iter().map(String::as_str).collect();
                bank.snap(&self.encode_text(&restated, device)?, &restated, device)
            }
            None => self.encode_text(prompts, device),
        }
    }

    /// A free prompt as [`Self::caption_conditions`] encodes it: restated in the training
    /// captions' verbs ([`CaptionBank::restate`]; as it is without a bank).
    pub fn restate(&self, prompt: &str) -> Restated {
        match &self.captions {
            Some(bank) => bank.restate(prompt),
            None => Restated::unchanged(prompt),
        }
    }

    /// The training caption a non-blank prompt, restated ([`Self::restate`]), is conditioned on
    /// (`None` without a [`CaptionBank`] or for a blank prompt).
    pub fn nearest_caption(&self, prompt: &str) -> candle_core::Result<Option<NearestCaption>> {
        match &self.captions {
            Some(bank) if !prompt.trim().is_empty() => {
                let restated = bank.restate(prompt).text;
                let own = self.encoder.encode(&[&restated], bank.vectors().device())?;
                Ok(bank.nearest(&own, &[&restated])?.pop())
            }
            _ => Ok(None),
        }
    }

    /// Unconstrained samples: `batch` motions of `frames` frames for `prompt`, from seeded start
    /// noise through DDIM with `steps` steps and classifier-free guidance `guidance`. Returns
    /// normalised features `[batch, frames, 263]`.
    pub fn sample(&self, request: &Sampling<'_>, device: &Device) -> Result<Tensor, PriorError> {
        let Sampling { prompt, frames, batch, seed, steps, guidance } = *request;
        let text = self
            .caption_conditions(&vec![prompt; batch], device)
            .map_err(|e| PriorError::Compute { what: "sampling", message: e.to_string() })?;
        self.sample_conditioned(&text, frames, seed, steps, guidance)
    }

    /// One motion per row of condition vectors `text` `[batch, text_dim]` (prompts through
    /// [`Self::caption_conditions`]), as [`Self::sample`] draws them: `[batch, frames, 263]`, normalised.
    pub fn sample_conditioned(
        &self,
        text: &Tensor,
        frames: usize,
        seed: u64,
        steps: usize,
        guidance: Guidance,
    ) -> Result<Tensor, PriorError> {
        let fail = |message: String| PriorError::Compute { what: "sampling", message };
        let sampler = DdimSampler::new(&NoiseSchedule::mdm(), steps).map_err(|e| fail(e.to_string()))?;
        let guidance = guidance.for_text(text).map_err(|e| fail(e.to_string()))?;
        let batch = text.dim(0).map_err(|e| fail(e.to_string()))?;
        let x_t = gaussian((batch, frames, crate::representation::FEATURE_DIM), seed, text.device())
            .map_err(|e| fail(e.to_string()))?;
        sampler.sample(&self.mdm, &x_t, text, guidance).map_err(|e| fail(e.to_string()))
    }

    /// De-normalised features `[batch, frames, 263]` of normalised ones, the root velocity
    /// decoded by [`Self::root_decode`]: what is exported and what the joints come from.
    pub fn to_features(&self, normalized: &Tensor) -> candle_core::Result<Tensor> {
        self.root_decode.apply(&self.mean_std.denormalize(normalized)?)
    }

    /// Joint positions `[batch, frames, 22, 3]` (m, y up) of normalised features
    /// `[batch, frames, 263]`, on the rest skeleton's bone lengths when the file has one;
    /// differentiable.
    pub fn to_joints(&self, normalized: &Tensor) -> candle_core::Result<Tensor> {
        self.joints_of(&self.to_features(normalized)?)
    }

    /// Joint positions `[batch, frames, 22, 3]` of de-normalised, decoded features
    /// `[batch, frames, 263]` (what [`Self::to_features`] returns), on the rest skeleton's bone
    /// lengths when the file has one; differentiable.
    pub fn joints_of(&self, features: &Tensor) -> candle_core::Result<Tensor> {
        let joints = recover_from_ric(features)?;
        match &self.rest {
            Some(rest) => rigid_bones(&joints, rest),
            None => Ok(joints),
        }
    }
}

#[cfg(test)]
impl Prior {
    /// An untrained one-layer prior (width 16) that hears the words of `labels`: normalisation
    /// mean 0 and std 0.1, the velocity decode, no rest skeleton. For tests.
    pub(crate) fn tiny(labels: &[&str]) -> Self {
        let encoder = crate::text::vocabulary::VocabularyEncoder::from_labels(labels.iter().copied());
        let cfg = MdmConfig {
            latent_dim: 16,
            ff_size: 32,
            num_layers: 1,
            num_heads: 2,
            text_dim: encoder.words().len(),
            ..MdmConfig::small()
        };
        Self {
            mdm: Mdm::random(cfg, DType::F32, &Device::Cpu, 1).unwrap(),
            encoder: ConditionEncoder::Vocabulary(encoder),
            mean_std: MeanStd::from_vecs(vec![0.0; 263], vec![0.1; 263], &Device::Cpu).unwrap(),
            root_decode: RootDecode::Velocity,
            rest: None,
            captions: None,
            identity: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn root_decode_names_round_trip() {
        for d in [RootDecode::PlantedFeet, RootDecode::Velocity] {
            assert_eq!(d.to_string().parse::<RootDecode>(), Ok(d));
        }
        assert!("feet".parse::<RootDecode>().unwrap_err().contains("\"feet\""));
    }

    /// A loaded prior names its file and the SHA-256 of its bytes; one built in memory names
    /// none.
    #[test]
    fn a_loaded_prior_names_its_file_and_its_sha256() {
        let prior = Prior::tiny(&["a person walks"]);
        assert!(prior.identity.is_none());
        let dir = tempfile::tempdir().unwrap();
        let (path, no_text) = (dir.path().join("tiny.safetensors"), dir.path().join("no_text_models"));
        prior.save(&path).unwrap();
        let identity = Prior::load(&path, &no_text, &Device::Cpu).unwrap().identity.unwrap();
        assert_eq!(
            identity,
            PriorIdentity::of(Path::new("elsewhere/tiny.safetensors"), &std::fs::read(&path).unwrap())
        );
        assert_eq!(identity.file, "tiny.safetensors");
        // The digest of FIPS 180-2's example "abc".
        let abc = PriorIdentity::of(Path::new("abc"), b"abc").sha256;
        assert_eq!(abc, "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
        // Another prior in the same file: another digest.
        Prior::tiny(&["a person runs"]).save(&path).unwrap();
        let other = Prior::load(&path, &no_text, &Device::Cpu).unwrap().identity.unwrap();
        assert_eq!(other.file, identity.file);
        assert_ne!(other.sha256, identity.sha256);
    }

    #[test]
    fn saves_and_loads_with_metadata_and_names_missing_parts() {
        let mut prior = Prior::tiny(&["a person walks", "a person runs"]);
        prior.mean_std = MeanStd::from_vecs(vec![0.1; 263], vec![2.0; 263], &Device::Cpu).unwrap();
        prior.root_decode = RootDecode::PlantedFeet;
        prior.rest = Some(RestSkeleton::of_pose(&crate::skeleton::rest_pose()));
        let ConditionEncoder::Vocabulary(encoder) = prior.encoder.clone() else { unreachable!() };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("prior.safetensors");
        prior.save(&path).unwrap();
        let no_text = dir.path().join("no_text_models");
        let back = Prior::load(&path, &no_text, &Device::Cpu).unwrap();
        assert!(matches!(&back.encoder, ConditionEncoder::Vocabulary(v) if *v == encoder));
        assert_eq!(back.mdm.config(), prior.mdm.config());
        assert_eq!(back.mean_std.std().to_vec1::<f32>().unwrap()[5], 2.0);
        assert_eq!(back.root_decode, RootDecode::Velocity, "the default decode");
        assert_eq!(back.rest, prior.rest);

        // A weight made NaN (a damaged file): refused at load, naming the tensor.
        let mut named = prior.mdm.named_parameters().to_vec();
        let (name, weight) = named.swap_remove(0);
        let mut values = weight.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let middle = values.len() / 2;
        values[middle] = f32::NAN;
        let broken = Tensor::from_vec(values, weight.shape(), &Device::Cpu).unwrap();
        named.push((name.clone(), broken));
        let damaged = dir.path().join("damaged.safetensors");
        Prior::write(&damaged, &named, prior.mdm.config(), &prior.encoder, &prior.mean_std, prior.rest.as_ref(), None)
            .unwrap();
        let err = Prior::load(&damaged, &no_text, &Device::Cpu).unwrap_err().to_string();
        assert!(err.contains(&format!("tensor `{name}` has 1 of")) && err.contains("damaged"), "{err}");

        std::fs::write(&path, b"not a prior").unwrap();
        assert!(Prior::load(&path, &no_text, &Device::Cpu).unwrap_err().to_string().contains("prior.safetensors"));
        assert!(Prior::load(&dir.path().join("missing.safetensors"), &no_text, &Device::Cpu).is_err());
    }

    /// A sentence-conditioned prior names its encoder, loads it from the text models folder,
    /// and says which encoder and folder are missing when they are.
    #[test]
    fn a_sentence_encoder_prior_names_its_encoder_and_finds_it_in_the_text_models() {
        let text_models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/text");
        let encoder = ConditionEncoder::sentence(MINILM_NAME, &text_models, &Device::Cpu).unwrap();
        let cfg =
            MdmConfig { latent_dim: 16, ff_size: 32, num_layers: 1, num_heads: 2, text_dim: 384, ..MdmConfig::small() };
        let mdm = Mdm::random(cfg, DType::F32, &Device::Cpu, 3).unwrap();
        let mean_std = MeanStd::from_vecs(vec![0.0; 263], vec![1.0; 263], &Device::Cpu).unwrap();
        let mut prior = Prior {
            mdm,
            encoder,
            mean_std,
            root_decode: RootDecode::Velocity,
            rest: None,
            captions: None,
            identity: None,
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("prior.safetensors");
        prior.save(&path).unwrap();
        let meta = read_metadata(&std::fs::read(&path).unwrap()).unwrap();
        assert_eq!(meta.get(SENTENCE_KEY).map(String::as_str), Some(MINILM_NAME));
        assert!(!meta.contains_key(VOCABULARY_KEY));
        let back = Prior::load(&path, &text_models, &Device::Cpu).unwrap();
        let a = back.encode_text(&["a person walks sideways to the left"], &Device::Cpu).unwrap();
        let b = prior.encode_text(&["a person walks sideways to the left"], &Device::Cpu).unwrap();
        assert_eq!(a.dims(), &[1, 384]);
        assert_eq!(crate::testing::max_abs_diff(&a, &b).unwrap(), 0.0);
        let err = Prior::load(&path, dir.path(), &Device::Cpu).unwrap_err().to_string();
        assert!(err.contains(MINILM_NAME) && err.contains(&dir.path().display().to_string()), "{err}");

        // With its training captions, a prompt is conditioned on the nearest one, written as
        // f16 and read back.
        let captions = ["a person walks forward", "a person sits down"].map(String::from).to_vec();
        let vectors = prior.encoder.encode(&["a person walks forward", "a person sits down"], &Device::Cpu).unwrap();
        prior.captions = Some(CaptionBank::new(captions, vectors.clone()).unwrap());
        prior.save(&path).unwrap();
        let back = Prior::load(&path, &text_models, &Device::Cpu).unwrap();
        let nearest = back.nearest_caption("someone takes a seat").unwrap().unwrap();
        assert_eq!(nearest.caption, "a person sits down");
        let snapped = back.caption_conditions(&["someone takes a seat", ""], &Device::Cpu).unwrap();
        let own = back.encode_text(&["someone takes a seat"], &Device::Cpu).unwrap();
        assert_eq!(
            crate::testing::max_abs_diff(&own, &prior.encoder.encode(&["someone takes a seat"], &Device::Cpu).unwrap())
                .unwrap(),
            0.0
        );
        assert!(crate::testing::max_abs_diff(&snapped.get(0).unwrap(), &vectors.get(1).unwrap()).unwrap() < 1e-3);
        let blank = prior.encoder.encode(&[""], &Device::Cpu).unwrap();
        // The blank prompt keeps its own vector (batched with another prompt: 2e-7 off).
        assert!(crate::testing::max_abs_diff(&snapped.get(1).unwrap(), &blank.get(0).unwrap()).unwrap() < 1e-5);
        assert_eq!(back.nearest_caption(" ").unwrap(), None);
    }
}
