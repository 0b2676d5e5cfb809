//! What a corpus holds: minutes per source, per split, per skill family named by the takes'
//! descriptions ([`Skill`]) and per action measured in the windows ([`Action`]), and what the
//! screen dropped. `mogen data stats` prints it.

use std::collections::BTreeMap;
use std::fmt;

use super::caption::Action;
use super::clips::Corpus;
use super::prepare::STANCE_TOE_HEIGHT_M;
use super::skill::Skill;
use super::source::Source;
use super::split::Split;
use super::tags::TravelDirection;
use crate::metrics::{foot_skate_ratio, stance_toe_height};
use crate::motion::bone_length_spread;
use crate::skeleton::FPS;

/// Minutes and clip counts of a corpus.
#[derive(Debug, Clone, PartialEq)]
pub struct CorpusStats {
    /// (clips, minutes) per source.
    pub per_source: BTreeMap<Source, (usize, f64)>,
    /// (clips, minutes, subjects) per split.
    pub per_split: BTreeMap<Split, (usize, f64, usize)>,
    /// (takes, minutes) per skill named by descriptions.
    pub per_skill: Vec<(Skill, usize, f64)>,
    /// (windows, share of windows) per measured action.
    pub per_action: Vec<(String, usize, f64)>,
    /// Minutes read before the screen and minutes dropped per reason (with takes affected).
    pub read_minutes: f64,
    /// (reason, frames, takes).
    pub dropped: Vec<(String, usize, usize)>,
    /// Duplicate takes dropped.
    pub duplicates: usize,
    /// Windows.
    pub windows: usize,
    /// Whether the kept motion is sound.
    pub soundness: Soundness,
}

/// Checks of the kept motion against itself, each in natural units.
#[derive(Debug, Clone, PartialEq)]
pub struct Soundness {
    /// Largest change of any bone's length within a clip, m (rigid by construction; the file's
    /// millimetre rounding leaves up to about 2 mm).
    pub bone_spread_max_m: f64,
    /// Median over clips of the lower toe's median height above the floor, m.
    pub stance_toe_median_m: f64,
    /// Share of clips whose lower toe stands within 2 cm of [`STANCE_TOE_HEIGHT_M`] in stance.
    pub stance_within_2cm: f64,
    /// Deepest any joint goes under the floor, m (positive: under).
    pub deepest_under_floor_m: f64,
    /// GMD foot-skating ratio of straight forward walking windows, per source: (windows, mean).
    pub walk_skate: BTreeMap<Source, (usize, f64)>,
}

impl Soundness {
    /// Measures a corpus.
    pub fn of(corpus: &Corpus) -> Self {
        let mut stance: Vec<f64> = corpus.clips.iter().map(|c| stance_toe_height(corpus.clip_joints(c))).collect();
        stance.sort_by(f64::total_cmp);
        let within = stance.iter().filter(|h| (**h - STANCE_TOE_HEIGHT_M).abs() <= 0.02).count();
        let mut walk_skate: BTreeMap<Source, (usize, f64)> = BTreeMap::new();
        for w in &corpus.windows {
            let straight = w.tags.direction == Some(TravelDirection::Forwards) && w.tags.turn_left().is_none();
            if Action::of(&w.tags) == Action::Walk && straight {
                let e = walk_skate.entry(corpus.clips[w.clip].source).or_default();
                e.0 += 1;
                e.1 += foot_skate_ratio(corpus.window_joints(w));
            }
        }
        walk_skate.values_mut().for_each(|(n, sum)| *sum /= (*n).max(1) as f64);
        Self {
            bone_spread_max_m: corpus
                .clips
                .iter()
                .map(|c| bone_length_spread(corpus.clip_joints(c)))
                .fold(0.0, f64::max),
            stance_toe_median_m: stance.get(stance.len() / 2).copied().unwrap_or(0.0),
            stance_within_2cm: within as f64 / stance.len().max(1) as f64,
            deepest_under_floor_m: -corpus.joints.iter().flat_map(|p| p.iter().map(|v| v.y)).fold(0.0, f64::min),
            walk_skate,
        }
    }
}

impl CorpusStats {
    /// Counts a corpus.
    pub fn of(corpus: &Corpus) -> Self {
        let minutes = |frames: usize| frames as f64 / FPS / 60.0;
        let mut per_source: BTreeMap<Source, (usize, f64)> = BTreeMap::new();
        let mut per_split: BTreeMap<Split, (usize, f64, usize)> = BTreeMap::new();
        let mut subjects: BTreeMap<Split, std::collections::BTreeSet<(Source, &str)>> = BTreeMap::new();
        let mut per_skill: BTreeMap<Skill, (std::collections::BTreeSet<&str>, usize)> = BTreeMap::new();
        for clip in &corpus.clips {
            let s = per_source.entry(clip.source).or_default();
            s.0 += 1;
            s.1 += minutes(clip.frames);
            let p = per_split.entry(clip.split).or_default();
            p.0 += 1;
            p.1 += minutes(clip.frames);
            subjects.entry(clip.split).or_default().insert((clip.source, clip.subject.as_str()));
            for skill in Skill::of(&clip.description) {
                let e = per_skill.entry(skill).or_default();
                e.0.insert(clip.take.as_str());
                e.1 += clip.frames;
            }
        }
        for (split, set) in subjects {
            if let Some(p) = per_split.get_mut(&split) {
                p.2 = set.len();
            }
        }
        let mut actions: BTreeMap<String, usize> = BTreeMap::new();
        for w in &corpus.windows {
            *actions.entry(format!("{:?}", Action::of(&w.tags)).to_lowercase()).or_default() += 1;
        }
        let n = corpus.windows.len().max(1) as f64;
        let mut per_action: Vec<(String, usize, f64)> =
            actions.into_iter().map(|(a, c)| (a, c, c as f64 / n)).collect();
        per_action.sort_by_key(|a| std::cmp::Reverse(a.1));
        Self {
            per_source,
            per_split,
            per_skill: Skill::ALL
                .into_iter()
                .map(|s| per_skill.get(&s).map_or((s, 0, 0.0), |(takes, frames)| (s, takes.len(), minutes(*frames))))
                .collect(),
            per_action,
            read_minutes: minutes(corpus.drops.frames_read.values().sum()),
            dropped: corpus
                .drops
                .frames
                .iter()
                .map(|(reason, (frames, takes))| (reason.describe().to_owned(), *frames, *takes))
                .collect(),
            duplicates: corpus.drops.duplicates.len(),
            windows: corpus.windows.len(),
            soundness: Soundness::of(corpus),
        }
    }

    /// Total minutes kept.
    pub fn kept_minutes(&self) -> f64 {
        self.per_source.values().map(|v| v.1).sum()
    }
}

impl fmt::Display for CorpusStats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let hours = |m: f64| m / 60.0;
        writeln!(
            f,
            "{:.2} h kept of {:.2} h read ({} clips, {} windows of up to {} s)",
            hours(self.kept_minutes()),
            hours(self.read_minutes),
            self.per_source.values().map(|v| v.0).sum::<usize>(),
            self.windows,
            super::clips::WINDOW_FRAMES as f64 / FPS,
        )?;
        writeln!(f, "\nper source:")?;
        for (source, (clips, minutes)) in &self.per_source {
            writeln!(f, "  {:<10} {clips:>6} clips {:>8.1} min {:>6.2} h", source.name(), minutes, hours(*minutes))?;
        }
        writeln!(f, "\nper split (by subject):")?;
        for (split, (clips, minutes, subjects)) in &self.per_split {
            writeln!(
                f,
                "  {:<10} {clips:>6} clips {:>8.1} min {:>6.2} h {subjects:>4} subjects",
                split.name(),
                minutes,
                hours(*minutes)
            )?;
        }
        writeln!(f, "\nper skill (named by the take's description; a take can name several):")?;
        for (skill, takes, minutes) in &self.per_skill {
            writeln!(f, "  {:<16} {takes:>5} takes {minutes:>7.1} min", skill.name())?;
        }
        writeln!(f, "\nper action (measured in each window, caption rules):")?;
        for (action, count, share) in &self.per_action {
            writeln!(f, "  {action:<12} {count:>6} windows {:>5.1} %", 100.0 * share)?;
        }
        writeln!(f, "\ndropped (20 fps frames, takes affected):")?;
        for (reason, frames, takes) in &self.dropped {
            writeln!(f, "  {reason:<58} {:>7.1} min {takes:>5} takes", *frames as f64 / FPS / 60.0)?;
        }
        writeln!(f, "  ({} duplicate takes)", self.duplicates)?;
        let s = &self.soundness;
        writeln!(f, "\nsoundness:")?;
        writeln!(f, "  bones: largest change of a bone's length within a clip {:.4} m", s.bone_spread_max_m)?;
        writeln!(
            f,
            "  stance: lower toe {:.3} m above the floor (median over clips); {:.1} % of clips within 2 cm of {STANCE_TOE_HEIGHT_M} m",
            s.stance_toe_median_m,
            100.0 * s.stance_within_2cm
        )?;
        writeln!(f, "  floor: deepest joint {:.3} m under it", s.deepest_under_floor_m)?;
        for (source, (n, skate)) in &s.walk_skate {
            writeln!(
                f,
                "  foot skate (GMD ratio) of {n} straight forward walking windows of {}: {skate:.3}",
                source.name()
            )?;
        }
        Ok(())
    }
}
