//! Held-out splits by subject: every take of a subject lands in one split, so the test split
//! holds people the prior never saw. Subjects are taken in the order of a fixed hash of their
//! id (not by hand): the first ones fill the test split to at least [`TEST_FRACTION`] of the
//! takes of their source, the next ones the validation split to [`VALIDATION_FRACTION`].

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

/// FNV-1a hash of a string: a fixed, platform-independent order.
pub fn fnv1a(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
}

/// The split of every subject, given how many takes each has (one source at a time).
pub fn assign_subjects(takes_per_subject: &BTreeMap<String, usize>) -> BTreeMap<String, Split> {
    let total: usize = takes_per_subject.values().sum();
    let mut order: Vec<&String> = takes_per_subject.keys().collect();
    order.sort_by_key(|s| (fnv1a(s), s.to_string()));
    let mut out = BTreeMap::new();
    let (mut test, mut validation) = (0usize, 0usize);
    for subject in order {
        let n = takes_per_subject[subject];
        let split = if (test as f64) < TEST_FRACTION * total as f64 {
            test += n;
            Split::Test
        } else if (validation as f64) < VALIDATION_FRACTION * total as f64 {
            validation += n;
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
        let split = assign_subjects(&subjects);
        let share = |which: Split| {
            subjects.iter().filter(|(s, _)| split[*s] == which).map(|(_, n)| *n).sum::<usize>() as f64 / total as f64
        };
        assert!(share(Split::Test) >= TEST_FRACTION && share(Split::Test) < TEST_FRACTION + 0.05);
        assert!(
            share(Split::Validation) >= VALIDATION_FRACTION && share(Split::Validation) < VALIDATION_FRACTION + 0.05
        );
        assert_eq!(split, assign_subjects(&subjects), "the assignment is deterministic");
    }
}
