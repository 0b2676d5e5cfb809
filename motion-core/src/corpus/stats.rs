//! What a corpus holds: minutes per source, per split, per skill family named by the takes'
//! descriptions ([`Skill`]) and per action measured in the windows ([`Action`]), and what the
//! screen dropped. `mogen data stats` prints it.

use std::collections::BTreeMap;
use std::fmt;

use super::caption::Action;
use super::skill::Skill;
use super::split::Split;
use super::{Corpus, Source};
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
        per_action.sort_by(|a, b| b.1.cmp(&a.1));
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
            super::WINDOW_FRAMES as f64 / FPS,
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
        write!(f, "  ({} duplicate takes)", self.duplicates)
    }
}
