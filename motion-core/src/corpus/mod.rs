//! The motion corpus: hours of real capture on the project's one skeleton, screened, cut into
//! captioned windows and split by subject. It is what the prior is trained on, and its train
//! split is what RG-DNO retrieves from ([`crate::generation::rgdno::candidates`]); the validation and test
//! splits are held out of both.
//!
//! Sources: the CMU Graphics Lab Motion Capture Database in its shared 22-joint form
//! ([`cmu`]), HDM05 clips read from ASF/AMC, ACCAD's BVH takes ([`accad`]) and the clips shipped
//! before the corpus (`fixtures/mocap/catalog.json`), each with its provenance. Every take goes through the same
//! steps: [`screen`] (drop what is not motion, by measurement), [`prepare`] (re-target to the
//! rest skeleton, floor under the stance feet, canonical start), then windows of
//! [`WINDOW_FRAMES`] every [`WINDOW_STRIDE_FRAMES`], each with its measured [`tags`] and
//! [`caption`]s. [`mod@file`] stores it compactly; [`stats`] counts hours per source, skill and
//! split.

pub mod accad;
pub mod caption;
mod clips;
pub mod cmu;
pub mod family;
pub mod file;
pub mod hdm05;
pub mod prepare;
pub mod screen;
pub mod skill;
mod source;
pub mod split;
pub mod stats;
pub mod tags;

pub use clips::{window_starts, Corpus, CorpusClip, CorpusWindow, DropReport, WINDOW_FRAMES, WINDOW_STRIDE_FRAMES};
pub use source::{RawTake, Source};
pub use split::Split;
