//! What the report tests share: bodies that glide at a set velocity and a corpus of such
//! windows (the tiny untrained prior is `Prior::tiny`).

use glam::DVec3;

use crate::corpus::tags::MotionTags;
use crate::corpus::{Corpus, CorpusClip, CorpusWindow, Source, Split};
use crate::skeleton::{rest_pose, Pose, FPS};

/// The rest pose lowered by `drop` m (knees not bent: enough for the pelvis measures) and
/// moved by `velocity` m/s, for `frames` frames.
pub(super) fn moving(frames: usize, velocity: DVec3, drop: f64) -> Vec<Pose> {
    let floor = rest_pose().iter().map(|v| v.y).fold(f64::INFINITY, f64::min);
    (0..frames)
        .map(|t| {
            let shift = velocity * (t as f64 / FPS);
            rest_pose().map(|v| {
                let y = v.y - floor + crate::corpus::prepare::STANCE_TOE_HEIGHT_M;
                let y = if y > 0.5 { y - drop } else { y };
                DVec3::new(v.x + shift.x, y, v.z + shift.z)
            })
        })
        .collect()
}

/// A corpus of one 120-frame clip (one window) per entry of `clips`: its split, its poses and
/// its window's caption.
pub(super) fn corpus_of(clips: Vec<(Split, Vec<Pose>, &str)>) -> Corpus {
    let mut corpus = Corpus { clips: Vec::new(), joints: Vec::new(), windows: Vec::new(), drops: Default::default() };
    for (c, (split, poses, caption)) in clips.into_iter().enumerate() {
        let tags = MotionTags::measure(&poses);
        let frames = poses.len();
        corpus.windows.push(CorpusWindow { clip: c, start: 0, frames, tags, captions: vec![caption.into()] });
        corpus.clips.push(CorpusClip {
            name: format!("{c:02}_01"),
            source: Source::Cmu,
            take: format!("{c:02}_01"),
            subject: format!("{c:02}"),
            description: caption.into(),
            split,
            take_frame: 0,
            offset: corpus.joints.len(),
            frames,
        });
        corpus.joints.extend(poses);
    }
    corpus
}
