//! One normalised feature sequence and its captioned stretches.

use candle_core::Tensor;

use crate::corpus::family::Family;

/// The frames of a sequence that one caption describes: from `start` to the next stretch's
/// start (or the sequence's end).
#[derive(Debug, Clone, PartialEq)]
pub struct Stretch {
    /// First frame.
    pub start: usize,
    /// Rows of the condition table: the phrasings of its caption.
    pub rows: Vec<u32>,
    /// The skill family of the corpus window it belongs to ([`Family::holds`], on the mirrored
    /// window for a mirrored copy); `None` for a window of no family and for database windows.
    pub family: Option<Family>,
}

/// One normalised feature sequence and the captions of its stretches.
#[derive(Debug, Clone)]
pub(super) struct Sequence {
    /// `[frames, 263]`, normalised.
    pub(super) features: Tensor,
    /// The captioned stretches, by first frame; the first starts at frame 0.
    pub(super) stretches: Vec<Stretch>,
    /// Balancing group (the label of a database window).
    pub(super) group: usize,
}

impl Sequence {
    pub(super) fn frames(&self) -> usize {
        self.features.dims()[0]
    }

    /// The condition rows of the stretch holding `frame`.
    pub(super) fn captions_at(&self, frame: usize) -> &[u32] {
        let i = self.stretches.partition_point(|s| s.start <= frame).saturating_sub(1);
        &self.stretches[i].rows
    }

    /// Frames of stretch `i`.
    pub(super) fn stretch_frames(&self, i: usize) -> usize {
        self.stretches.get(i + 1).map_or(self.frames(), |next| next.start) - self.stretches[i].start
    }
}
