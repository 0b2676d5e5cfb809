//! Where a clip comes from, and a take as read from its source before the screen.

use serde::{Deserialize, Serialize};

use crate::skeleton::Pose;

/// Most frames of the first and last pose held around a short one-shot take (1 s each), so that
/// a take cut to one repetition (a hop of 0.8 s) reaches a window's length.
pub const HOLD_FRAMES: usize = 20;

/// A take as read from a source, before the screen.
#[derive(Debug, Clone)]
pub struct RawTake {
    /// The source.
    pub source: Source,
    /// Take id.
    pub take: String,
    /// Subject id.
    pub subject: String,
    /// What the source says of the take.
    pub description: String,
    /// 20 fps positions as imported (any skeleton proportions, any floor, any start).
    pub poses: Vec<Pose>,
    /// Whether the take must be screened (`false` for clips already curated on our skeleton,
    /// such as the looped shipped clips, whose seams the screen would cut).
    pub screen: bool,
    /// Frames of the first and last pose held around each kept stretch, at most, to bring a
    /// short one-shot clip to the shortest segment (0: none).
    pub hold_frames: usize,
}

/// Where a clip comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Source {
    /// CMU Graphics Lab Motion Capture Database (mocap.cs.cmu.edu).
    Cmu,
    /// HDM05 (MPI Informatik / Universität Bonn), CC BY-SA 3.0.
    Hdm05,
    /// The clips shipped before the corpus (`fixtures/mocap/`: DeepMimic, CMU via assimp).
    Shipped,
    /// ACCAD's Open Motion Project (The Ohio State University), CC BY 3.0.
    Accad,
}

impl Source {
    /// Every source, in report order.
    pub const ALL: [Source; 4] = [Source::Cmu, Source::Hdm05, Source::Accad, Source::Shipped];

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Source::Cmu => "cmu",
            Source::Hdm05 => "hdm05",
            Source::Shipped => "shipped",
            Source::Accad => "accad",
        }
    }
}
