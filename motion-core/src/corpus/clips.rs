//! The corpus itself: its clips, their captioned windows and what the screen dropped, and how
//! takes become them.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::screen::{self, DropReason, FrameVerdicts, ScreenConfig};
use super::source::{RawTake, Source};
use super::split::{self, Split};
use super::tags::MotionTags;
use super::{caption, prepare, skill};
use crate::skeleton::{Pose, FPS};

/// Frames of a captioned window (6 s): long enough to see a gait, short enough that one
/// caption says what it does.
pub const WINDOW_FRAMES: usize = 120;
/// Frames between the starts of consecutive windows of a clip (2 s).
pub const WINDOW_STRIDE_FRAMES: usize = 40;

/// A kept stretch of one take.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CorpusClip {
    /// Unique name: the take, and `#k` for its k-th kept stretch when a take was cut (`07_01#1`).
    pub name: String,
    /// The source.
    pub source: Source,
    /// The take id within its source (`07_01`, `HDM_bd_hopLLeg_001`, `humanoid3d_walk`).
    pub take: String,
    /// The subject (`07`, `bd`); whole subjects go to one split.
    pub subject: String,
    /// What the source says of the whole take (CMU's description, HDM05's class, the shipped
    /// label), in words ([`caption::readable_description`]: `Reach_Left002` → `reach left`).
    pub description: String,
    /// The split.
    pub split: Split,
    /// First frame of the stretch in the take as imported (20 fps).
    pub take_frame: usize,
    /// First frame in the corpus's joints.
    pub offset: usize,
    /// Frames.
    pub frames: usize,
}

/// A captioned window of a clip: the unit of training and retrieval.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CorpusWindow {
    /// Index of the clip.
    pub clip: usize,
    /// First frame within the clip.
    pub start: usize,
    /// Frames.
    pub frames: usize,
    /// What the window's own motion does.
    pub tags: MotionTags,
    /// Several phrasings of what it does ([`caption::captions`]).
    pub captions: Vec<String>,
}

/// What the screen dropped, per reason.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DropReport {
    /// Frames dropped per reason (20 fps), with the takes affected.
    pub frames: BTreeMap<DropReason, (usize, usize)>,
    /// Frames read before any drop, per source.
    pub frames_read: BTreeMap<Source, usize>,
    /// Duplicate takes: (dropped take, the earlier take it repeats).
    pub duplicates: Vec<(String, String)>,
    /// The takes that lost the most frames (take, frames dropped, main reason), worst first.
    pub worst_takes: Vec<(String, usize, DropReason)>,
}

/// The corpus: clips, their joints and captioned windows, and what was dropped.
#[derive(Debug, Clone)]
pub struct Corpus {
    /// Every kept clip, in source then take order.
    pub clips: Vec<CorpusClip>,
    /// Every clip's joints, concatenated (floor y = 0, each clip starting at x = z = 0 facing +z).
    pub joints: Vec<Pose>,
    /// The captioned windows.
    pub windows: Vec<CorpusWindow>,
    /// What the screen dropped.
    pub drops: DropReport,
}

impl Corpus {
    /// Screens, prepares, splits and windows raw takes. Splits are assigned per source by
    /// subject ([`split::assign_subjects`]); the shipped clips are all training clips.
    pub fn build(takes: Vec<RawTake>, config: &ScreenConfig) -> Self {
        let mut drops = DropReport::default();
        let mut seen: BTreeMap<Vec<u8>, String> = BTreeMap::new();
        let mut kept: Vec<(RawTake, Vec<std::ops::Range<usize>>, Vec<Pose>)> = Vec::new();
        let mut per_take_drops: Vec<(String, usize, DropReason)> = Vec::new();
        for take in takes {
            *drops.frames_read.entry(take.source).or_default() += take.poses.len();
            let key = content_key(&take.poses);
            if let Some(first) = seen.get(&key) {
                drops.duplicates.push((take.take.clone(), first.clone()));
                add_drop(&mut drops, DropReason::Duplicate, take.poses.len());
                continue;
            }
            seen.insert(key, take.take.clone());
            let mut verdicts = if take.screen {
                screen::screen_take(&take.poses, config)
            } else {
                FrameVerdicts::keep_all(take.poses.len())
            };
            // Floor each screened stretch, then drop what still lies under the floor.
            let prepared = prepare_stretches(&take.poses, &mut verdicts, config, take.screen);
            let segments = verdicts.segments(config.min_segment_frames.saturating_sub(2 * take.hold_frames).max(2));
            let mut lost = (0, DropReason::TooShort);
            for (reason, frames) in verdicts.counts() {
                if frames > 0 {
                    add_drop(&mut drops, reason, frames);
                    if frames > lost.0 {
                        lost = (frames, reason);
                    }
                }
            }
            let total_lost: usize = verdicts.0.iter().filter(|v| v.is_some()).count();
            if total_lost > 0 {
                per_take_drops.push((take.take.clone(), total_lost, lost.1));
            }
            if !segments.is_empty() {
                kept.push((take, segments, prepared));
            }
        }
        per_take_drops.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
        per_take_drops.truncate(40);
        drops.worst_takes = per_take_drops;

        let splits = assign_splits(&kept.iter().map(|(t, _, _)| t).collect::<Vec<_>>());
        let mut corpus = Corpus { clips: Vec::new(), joints: Vec::new(), windows: Vec::new(), drops };
        for (take, segments, prepared) in kept {
            let split = splits.get(&(take.source, take.subject.clone())).copied().unwrap_or(Split::Train);
            let cut = segments.len() > 1;
            for (k, range) in segments.into_iter().enumerate() {
                let held = config.min_segment_frames.saturating_sub(range.len()).div_ceil(2).min(take.hold_frames);
                let poses = prepare::canonical_start(&hold_ends(&prepared[range.clone()], held));
                corpus.push_clip(
                    CorpusClip {
                        name: if cut { format!("{}#{k}", take.take) } else { take.take.clone() },
                        source: take.source,
                        take: take.take.clone(),
                        subject: take.subject.clone(),
                        description: caption::readable_description(&take.description),
                        split,
                        take_frame: range.start,
                        offset: 0,
                        frames: 0,
                    },
                    poses,
                );
            }
        }
        corpus
    }

    /// Appends a clip with its joints and windows.
    fn push_clip(&mut self, mut clip: CorpusClip, poses: Vec<Pose>) {
        clip.offset = self.joints.len();
        clip.frames = poses.len();
        let index = self.clips.len();
        for (start, frames) in window_starts(poses.len()) {
            let tags = MotionTags::measure(&poses[start..start + frames]);
            let captions = caption::captions(&tags, &clip.description, self.windows.len());
            self.windows.push(CorpusWindow { clip: index, start, frames, tags, captions });
        }
        self.joints.extend(poses);
        self.clips.push(clip);
    }

    /// The joints of a clip.
    pub fn clip_joints(&self, clip: &CorpusClip) -> &[Pose] {
        &self.joints[clip.offset..clip.offset + clip.frames]
    }

    /// The joints of a window.
    pub fn window_joints(&self, window: &CorpusWindow) -> &[Pose] {
        let clip = &self.clips[window.clip];
        &self.joints[clip.offset + window.start..clip.offset + window.start + window.frames]
    }

    /// Seconds of motion kept.
    pub fn seconds(&self) -> f64 {
        self.joints.len() as f64 / FPS
    }
}

/// Window (start, frames) pairs of a clip of `frames` frames: every [`WINDOW_STRIDE_FRAMES`],
/// [`WINDOW_FRAMES`] long, the last one ending at the clip's end; a clip shorter than a window
/// is one window.
pub fn window_starts(frames: usize) -> Vec<(usize, usize)> {
    let len = frames.min(WINDOW_FRAMES);
    let last = frames - len;
    let mut starts: Vec<usize> = (0..=last).step_by(WINDOW_STRIDE_FRAMES).collect();
    if starts.last() != Some(&last) {
        starts.push(last);
    }
    starts.into_iter().map(|s| (s, len)).collect()
}

/// The poses with the first and last held for `frames` frames each.
fn hold_ends(poses: &[Pose], frames: usize) -> Vec<Pose> {
    let (Some(first), Some(last)) = (poses.first(), poses.last()) else { return Vec::new() };
    let mut out = Vec::with_capacity(poses.len() + 2 * frames);
    out.extend(std::iter::repeat_n(*first, frames));
    out.extend_from_slice(poses);
    out.extend(std::iter::repeat_n(*last, frames));
    out
}

fn add_drop(drops: &mut DropReport, reason: DropReason, frames: usize) {
    let entry = drops.frames.entry(reason).or_default();
    entry.0 += frames;
    entry.1 += 1;
}

/// Bytes of a take's positions, for finding exact duplicates.
fn content_key(poses: &[Pose]) -> Vec<u8> {
    poses.iter().flat_map(|p| p.iter().flat_map(|v| v.to_array())).flat_map(|x| (x as f32).to_le_bytes()).collect()
}

/// The whole take prepared stretch by stretch (each kept stretch re-targeted and floored on its
/// own, since a take can move between floors), with frames under the floor then dropped.
/// Dropped frames keep their raw positions.
fn prepare_stretches(poses: &[Pose], verdicts: &mut FrameVerdicts, config: &ScreenConfig, screen: bool) -> Vec<Pose> {
    let mut out = poses.to_vec();
    let mut probe = verdicts.clone();
    for range in probe.segments(2) {
        let floored = prepare::put_on_floor(&crate::motion::retarget_bone_lengths(
            &poses[range.clone()],
            &crate::skeleton::rest_bone_lengths(),
        ));
        out[range].copy_from_slice(&floored);
    }
    if screen {
        let mut found = FrameVerdicts::keep_all(poses.len());
        screen::screen_floor(&out, &mut found, config);
        screen::screen_raised_stance(&out, &mut found, config);
        for (v, u) in verdicts.0.iter_mut().zip(found.0) {
            if v.is_none() {
                *v = u;
            }
        }
    } else {
        // A curated clip is kept whole: lifted so no joint goes deeper than the screen allows
        // (the shipped crawl's knees and hands reach below its stance toes).
        let lowest = out.iter().flat_map(|p| p.iter().map(|v| v.y)).fold(f64::INFINITY, f64::min);
        let lift = (-config.under_floor_m - lowest).max(0.0);
        out.iter_mut().for_each(|p| p.iter_mut().for_each(|v| v.y += lift));
    }
    out
}

/// Splits per (source, subject): the shipped clips and ACCAD's two performers train (they are
/// there for the rare skills retrieval lacks, and CMU's and HDM05's held-out people judge);
/// CMU and HDM05 subjects are assigned
/// by [`split::assign_subjects`] within their source, with the skill families their takes'
/// descriptions name as published (not [`caption::readable_description`]'s words, so that
/// tidying a description never moves a subject to another split).
fn assign_splits(takes: &[&RawTake]) -> BTreeMap<(Source, String), Split> {
    let mut out = BTreeMap::new();
    for source in [Source::Cmu, Source::Hdm05] {
        let mut counts: BTreeMap<String, usize> = BTreeMap::new();
        let mut skills: Vec<BTreeMap<String, usize>> = vec![BTreeMap::new(); skill::Skill::ALL.len()];
        for t in takes.iter().filter(|t| t.source == source) {
            *counts.entry(t.subject.clone()).or_default() += 1;
            for (k, s) in skill::Skill::ALL.iter().enumerate() {
                if s.named_by(&t.description) {
                    *skills[k].entry(t.subject.clone()).or_default() += 1;
                }
            }
        }
        for (subject, split) in split::assign_subjects(&counts, &skills) {
            out.insert((source, subject), split);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::test_support::walking_poses;

    fn raw(take: &str, subject: &str, poses: Vec<Pose>) -> RawTake {
        RawTake {
            source: Source::Cmu,
            take: take.into(),
            subject: subject.into(),
            description: "walk".into(),
            poses,
            screen: true,
            hold_frames: 0,
        }
    }

    #[test]
    fn takes_are_cut_around_glitches_and_duplicates_dropped() {
        let walk = walking_poses(300, 0.0);
        let mut glitchy = walk.clone();
        glitchy[150][crate::skeleton::Joint::Head.index()].y += 0.5;
        let corpus = Corpus::build(
            vec![raw("01_01", "01", walk.clone()), raw("01_02", "01", walk), raw("02_01", "02", glitchy)],
            &ScreenConfig::default(),
        );
        assert_eq!(corpus.drops.duplicates, vec![("01_02".to_owned(), "01_01".to_owned())]);
        let names: Vec<&str> = corpus.clips.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, vec!["01_01", "02_01#0", "02_01#1"]);
        assert_eq!(corpus.clips[2].take_frame, 153);
        assert_eq!(corpus.joints.len(), 300 + 148 + 147);
        // Every window of a walk is captioned as one.
        assert!(corpus.windows.iter().all(|w| w.captions[0].starts_with("a person walks")), "{:?}", corpus.windows[0]);
        assert_eq!(window_starts(300), vec![(0, 120), (40, 120), (80, 120), (120, 120), (160, 120), (180, 120)]);
    }
}
