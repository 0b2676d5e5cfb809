//! The limits that protect memory and time, in one place.
//!
//! Every input that sizes an allocation or a loop (a program's frames and constraints, an
//! imported clip's frames and joints, a file's or an LLM reply's bytes, a repair prompt, the wait
//! on `Retry-After`) is checked against one of these **before** anything is allocated for it, and
//! a violation is a [`LimitExceeded`] that names the limit, the value and what to do about it.
//! The program schema (`mogen schema`) states the same bounds, so a program that validates is one
//! that `mogen run` can generate.

use std::fmt;

/// One limit: a name users can search for, the largest allowed value, its unit and advice.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limit {
    /// Name of the limit, as printed (e.g. `program frames`).
    pub name: &'static str,
    /// Largest allowed value.
    pub max: u64,
    /// Unit of the value (`frames`, `bytes`, ...).
    pub unit: &'static str,
    /// What a user can do when they meet it.
    pub advice: &'static str,
}

/// A value over a [`Limit`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what} is {}{value} {unit}, over the limit of {max} {unit} ({name}); {advice}", if *at_least { "at least " } else { "" }, unit = limit.unit, max = limit.max, name = limit.name, advice = limit.advice)]
pub struct LimitExceeded {
    /// What was measured (a file, "the clip length", a flag).
    pub what: String,
    /// The value found, or a lower bound of it when `at_least`.
    pub value: u64,
    /// The value is a lower bound: a stream (a file, a reply) was cut off past the limit.
    pub at_least: bool,
    /// The limit.
    pub limit: Limit,
}

impl Limit {
    /// `Ok` when `value ≤ max`; otherwise the error names `what`.
    pub fn check(&self, value: u64, what: impl fmt::Display) -> Result<(), LimitExceeded> {
        if value <= self.max {
            Ok(())
        } else {
            Err(LimitExceeded { what: what.to_string(), value, at_least: false, limit: *self })
        }
    }

    /// Like [`Limit::check`] for a stream read so far: `read` bytes (or items) of `what`, which
    /// may hold more; the error says "at least".
    pub fn check_stream(&self, read: u64, what: impl fmt::Display) -> Result<(), LimitExceeded> {
        self.check(read, what).map_err(|e| LimitExceeded { at_least: true, ..e })
    }

    /// The limit as a `usize` (saturating on 32-bit targets).
    pub fn max_usize(&self) -> usize {
        usize::try_from(self.max).unwrap_or(usize::MAX)
    }
}

/// Frames of a constraint program (20 fps: 50 s). The prior was trained on clips of up to 196
/// frames; DNO's unrolled sampler keeps activations for every frame pair of the attention, so
/// 1,000 frames is about the most a 24 GiB machine generates in one piece.
pub const PROGRAM_FRAMES: Limit = Limit {
    name: "program frames",
    max: 1000,
    unit: "frames",
    advice: "generate a longer motion in parts of at most 1000 frames (50 s at 20 fps)",
};

/// Constraints of one program (the shipped tasks use at most 12).
pub const PROGRAM_CONSTRAINTS: Limit = Limit {
    name: "constraints per program",
    max: 64,
    unit: "constraints",
    advice: "merge constraints with `all_of`/`any_of`, or split the task",
};

/// Characters of a program's `text` and of each constraint's `description`.
pub const PROGRAM_TEXT_CHARS: Limit = Limit {
    name: "text length",
    max: 2000,
    unit: "characters",
    advice: "shorten the text; the prior reads only its first words",
};

/// Motions generated in one batch (`-n`): DNO keeps every sample's unrolled sampler in memory.
pub const BATCH_SAMPLES: Limit = Limit {
    name: "samples per run",
    max: 64,
    unit: "samples",
    advice: "run several batches with different --seed values",
};

/// Samples × frames² of one optimised batch: DNO's unrolled sampler keeps every attention map
/// for the backward pass, so memory grows with the batch and the square of the clip length
/// (1 sample of 1000 frames peaks at 1.9 GB; the limit allows 4 of them, or 64 of 250 frames).
pub const BATCH_ATTENTION: Limit = Limit {
    name: "samples × frames² per optimised batch",
    max: 4_000_000,
    unit: "frame pairs",
    advice: "use fewer samples per run (-n) or a shorter clip",
};

/// Bytes of a program file (the largest shipped program is under 10 KiB).
pub const PROGRAM_FILE_BYTES: Limit = Limit {
    name: "program file size",
    max: 1 << 20,
    unit: "bytes",
    advice: "a program is a small JSON document; is this the right file?",
};

/// Frames of an imported clip after resampling to 20 fps (one hour).
pub const CLIP_FRAMES: Limit = Limit {
    name: "imported clip length",
    max: 72_000,
    unit: "frames at 20 fps",
    advice: "trim the clip, or check its frame count and frame time",
};

/// Joints of an imported rig (BVH, DeepMimic); SMPL has 24, large face rigs a few hundred.
pub const RIG_JOINTS: Limit = Limit {
    name: "joints per rig",
    max: 1024,
    unit: "joints",
    advice: "remove unused joints (fingers, face) before importing",
};

/// Bytes of an imported mocap file (a 30-minute 120 fps BVH is about 150 MB).
pub const MOCAP_FILE_BYTES: Limit =
    Limit { name: "mocap file size", max: 512 << 20, unit: "bytes", advice: "split the capture into shorter files" };

/// Bytes of a character read as a rig, and of each file its glTF names (a textured game character
/// is tens of MB).
pub const CHARACTER_FILE_BYTES: Limit = Limit {
    name: "character file size",
    max: 256 << 20,
    unit: "bytes",
    advice: "a character to retarget onto needs its skin and meshes; shrink its textures",
};

/// Bytes of a list of prompts read for a report (`mogen report prior --paraphrases`).
pub const PROMPT_LIST_FILE_BYTES: Limit = Limit {
    name: "prompt list file size",
    max: 1 << 20,
    unit: "bytes",
    advice: "a prompt list is a short text file of `family<TAB>prompt` lines; is this the right file?",
};

/// Bytes of one WordNet database file once unpacked (WordNet 3.0's largest read, `index.noun`,
/// is 4.8 MB).
pub const WORDNET_FILE_BYTES: Limit = Limit {
    name: "WordNet file size",
    max: 64 << 20,
    unit: "bytes",
    advice: "the text models folder's `wordnet/` should hold WordNet 3.0's files; re-create it with fixtures/text/extract_wordnet.sh",
};

/// Bytes of one LLM reply body (a program with the largest allowed constraints fits in far less).
pub const LLM_REPLY_BYTES: Limit = Limit {
    name: "LLM reply size",
    max: 1 << 20,
    unit: "bytes",
    advice: "the endpoint sent far more than a constraint program; check --base-url and --model",
};

/// Characters of a bad reply quoted back to the LLM in one repair prompt (the rest is cut, with a
/// note saying so).
pub const REPAIR_QUOTE_CHARS: Limit = Limit {
    name: "repair prompt quote",
    max: 16_384,
    unit: "characters",
    advice: "the reply is quoted up to this length",
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_value_over_the_limit_names_the_limit_and_the_advice() {
        assert!(PROGRAM_FRAMES.check(1000, "frames").is_ok());
        let err = PROGRAM_FRAMES.check(4999, "the clip length").unwrap_err().to_string();
        assert!(
            err.contains("the clip length is 4999 frames, over the limit of 1000 frames (program frames)"),
            "{err}"
        );
        assert!(err.contains("in parts"), "{err}");
    }
}
