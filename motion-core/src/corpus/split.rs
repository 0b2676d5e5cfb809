//! Held-out splits by subject: every take of a subject lands in one split, so the test split
//! holds people the prior never saw. The choice is a rule, not a hand list: first, for each
//! skill family from the rarest, while the test split holds under [`SKILL_TEST_FRACTION`] of
//! the family's takes, the subject holding the share of them nearest 15 % (none that holds
//! over 30 % of any family, so training keeps most of every skill) goes to test; then subjects in the order of a fixed hash of
//! their id fill the test split to at least [`TEST_FRACTION`] of the takes of their source, and
//! the validation split to [`VALIDATION_FRACTION`].

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// Which use a clip is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// Trained on and retrieved from.
    Train,
    /// Held out for choosing training settings and checkpoints.
    Validation,
    /// Held out for judging: never trained on, never retrieved from when evaluating.
    Test,
}

impl Split {
    /// Every split, in report order.
    pub const ALL: [Split; 3] = [Split::Train, Split::Validation, Split::Test];

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Validation => "validation",
            Split::Test => "test",
        }
    }
}

/// Smallest share of a source's takes in the test split.
pub const TEST_FRACTION: f64 = 0.12;
/// Smallest share of a source's takes in the validation split.
pub const VALIDATION_FRACTION: f64 = 0.05;

/// Smallest share of each skill family's takes the test split should hold.
pub const SKILL_TEST_FRACTION: f64 = 0.10;

/// FNV-1a hash of a string: a fixed, platform-independent order.
pub fn fnv1a(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
}

/// The split of every subject, given how many takes each has and, per skill family, how many of
/// its takes name the skill (one source at a time; families in any order).
pub fn assign_subjects(
    takes_per_subject: &BTreeMap<String, usize>,
    skill_takes: &[BTreeMap<String, usize>],
) -> BTreeMap<String, Split> {
    let total: usize = takes_per_subject.values().sum();
    let mut out: BTreeMap<String, Split> = BTreeMap::new();
    let mut families: Vec<&BTreeMap<String, usize>> = skill_takes.iter().filter(|f| !f.is_empty()).collect();
    families.sort_by_key(|f| f.values().sum::<usize>());
    // A subject holding over 30 % of any family's takes stays out of the test split.
    let holds_much = |subject: &str| {
        families.iter().any(|f| f.get(subject).copied().unwrap_or(0) as f64 > 0.3 * f.values().sum::<usize>() as f64)
    };
    for family in &families {
        let family_total = family.values().sum::<usize>() as f64;
        let in_test = |out: &BTreeMap<String, Split>| {
            family.iter().filter(|(s, _)| out.get(*s) == Some(&Split::Test)).map(|(_, n)| *n).sum::<usize>() as f64
        };
        while in_test(&out) < SKILL_TEST_FRACTION * family_total {
            let candidate = family.iter().filter(|(s, _)| !out.contains_key(*s) && !holds_much(s)).min_by(|a, b| {
                let gap = |n: usize| (n as f64 / family_total - 0.15).abs();
                gap(*a.1).total_cmp(&gap(*b.1)).then_with(|| a.0.cmp(b.0))
            });
            let Some((subject, _)) = candidate else { break };
            out.insert(subject.clone(), Split::Test);
        }
    }
    let mut order: Vec<&String> = takes_per_subject.keys().filter(|s| !out.contains_key(*s)).collect();
    order.sort_by_key(|s| (fnv1a(s), s.to_string()));
    let count = |out: &BTreeMap<String, Split>, which: Split| {
        out.iter()
            .filter(|(_, s)| **s == which)
            .map(|(subject, _)| takes_per_subject.get(subject).copied().unwrap_or(0))
            .sum::<usize>() as f64
    };
    for subject in order {
        let split = if count(&out, Split::Test) < TEST_FRACTION * total as f64 {
            Split::Test
        } else if count(&out, Split::Validation) < VALIDATION_FRACTION * total as f64 {
            Split::Validation
        } else {
            Split::Train
        };
        out.insert(subject.clone(), split);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_hold_whole_subjects_and_fill_their_shares() {
        let subjects: BTreeMap<String, usize> = (1..=60).map(|s| (format!("{s:02}"), 5 + s % 7)).collect();
        let total: usize = subjects.values().sum();
        let split = assign_subjects(&subjects, &[]);
        let share = |which: Split| {
            subjects.iter().filter(|(s, _)| split[*s] == which).map(|(_, n)| *n).sum::<usize>() as f64 / total as f64
        };
        assert!(share(Split::Test) >= TEST_FRACTION && share(Split::Test) < TEST_FRACTION + 0.05);
        assert!(
            share(Split::Validation) >= VALIDATION_FRACTION && share(Split::Validation) < VALIDATION_FRACTION + 0.05
        );
        assert_eq!(split, assign_subjects(&subjects, &[]), "the assignment is deterministic");
        // A rare skill held by five subjects gets one of them, not the one holding most of it.
        let rare: BTreeMap<String, usize> = [("07", 8), ("08", 2), ("09", 1), ("10", 1), ("11", 1)]
            .into_iter()
            .map(|(s, n)| (s.to_owned(), n))
            .collect();
        let split = assign_subjects(&subjects, &[rare]);
        assert_eq!(split["08"], Split::Test);
        assert_ne!(split["07"], Split::Test);
    }
}
