//! The shipped corpus (`fixtures/corpus/corpus.safetensors.gz`) loads and holds what its data
//! card says: at least 7.5 hours after the drops, every split with whole subjects, a test split
//! of at least 10 % of the takes, windows with captions, descriptions in words, and sound joints.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use motion_core::corpus::caption::readable_description;
use motion_core::corpus::stats::CorpusStats;
use motion_core::corpus::{file, Source, Split};

#[test]
fn the_shipped_corpus_holds_its_hours_splits_and_captions() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/corpus/corpus.safetensors.gz");
    let corpus = file::load(&path).unwrap();
    let stats = CorpusStats::of(&corpus);
    assert!(stats.kept_minutes() >= 7.5 * 60.0, "{:.1} min", stats.kept_minutes());
    for source in Source::ALL {
        assert!(stats.per_source.contains_key(&source), "{source:?}");
    }
    // Whole subjects per split.
    let mut split_of: BTreeMap<(Source, &str), BTreeSet<Split>> = BTreeMap::new();
    for c in &corpus.clips {
        split_of.entry((c.source, c.subject.as_str())).or_default().insert(c.split);
    }
    assert!(split_of.values().all(|s| s.len() == 1));
    let takes = |which: Option<Split>| {
        let held = |c: &&motion_core::corpus::CorpusClip| which.is_none_or(|w| c.split == w);
        corpus
            .clips
            .iter()
            .filter(|c| !matches!(c.source, Source::Shipped | Source::Accad))
            .filter(held)
            .map(|c| &c.take)
            .collect::<BTreeSet<_>>()
            .len()
    };
    assert!(takes(Some(Split::Test)) as f64 >= 0.10 * takes(None) as f64);
    // ACCAD's two performers train (`fixtures/corpus/DATA_CARD.md`): their crawls, carried boxes,
    // side steps and hops are retrieved from.
    let accad: Vec<_> = corpus.clips.iter().filter(|c| c.source == Source::Accad).collect();
    assert!(accad.iter().all(|c| c.split == Split::Train));
    assert!(stats.per_source[&Source::Accad].1 >= 20.0, "{:?}", stats.per_source[&Source::Accad]);
    for skill in ["crawl", "carrying a box", "side step", "hop"] {
        assert!(accad.iter().any(|c| c.description.contains(skill)), "no ACCAD take of {skill}");
    }
    assert!(takes(Some(Split::Validation)) > 0);
    assert!(corpus
        .windows
        .iter()
        .all(|w| (3..=5).contains(&w.captions.len()) && w.captions.iter().all(|c| !c.is_empty())));
    // Every description is in words (a corpus built before `readable_description` holds file
    // names such as `Reach_Left002`, which mirroring cannot mirror).
    for c in &corpus.clips {
        assert_eq!(readable_description(&c.description), c.description, "clip {}", c.name);
    }
    let s = &stats.soundness;
    assert!(s.bone_spread_max_m < 0.005 && s.deepest_under_floor_m <= 0.0305, "{s:?}");
    assert!((s.stance_toe_median_m - 0.015).abs() < 0.01, "{s:?}");
}
