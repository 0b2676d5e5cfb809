//! What the trainer learns from ([`TrainingSet`]) and the random batches drawn from it.
//!
//! A training set is a list of normalised 263-d feature sequences, the captions of their
//! stretches as rows of one table of condition vectors, and what ships with the prior trained
//! on it (the text encoder, the normalisation, the rest skeleton). Two sources:
//! - a [`MotionDatabase`]: every window a sequence with its one label, a
//!   [`VocabularyEncoder`] over the labels, batches balanced over labels;
//! - the [`Corpus`]: every clip of a split and its left/right mirrored copy a sequence, each of
//!   its 6 s windows a captioned stretch with all its phrasings (mirrored copies with "left" and
//!   "right" swapped) and its skill [`Family`], encoded by a sentence encoder; batches drawn
//!   uniformly over all crops, or by family ([`TrainConfig::family_balance`]).
//!
//! A crop takes the captions of the window centred nearest its middle frame: each window's
//! captioned stretch is the frames nearer its centre than any other window's (windows of 6 s
//! every 2 s: the 2 s around its centre), so the caption describes the crop's central seconds.
//! (A stretch beginning at the window's first frame would caption a crop by a window starting
//! 1–3 s after the crop does, and a turn in a crop's first seconds could sit under "walks
//! forward": 34.5 % of the train split's crops captioned as a straight walk turn by 45° or
//! more that way, 11.5 % this way; `fixtures/model/training/README.md`.)

mod family_balance;
mod sequence;
mod training_set;

pub use sequence::Stretch;
pub use training_set::{Batch, CaptionedSequences, TrainingSet};

#[cfg(test)]
pub(super) use training_set::tests;
