//! The retrieval database: crops, placement against the feature path, the semantic check of
//! crops and their mirrors, and reports from before the corpus.

use super::*;
use crate::corpus::tags::MotionTags;
use crate::corpus::{window_starts, CorpusClip, CorpusWindow, DropReport, Source};
use crate::motion::test_support::walking_poses;

/// A corpus of hand-made clips `(name, split, poses)`, windowed and captioned as
/// [`Corpus::build`] does.
pub(in crate::generation::rgdno) fn tiny_corpus(clips: Vec<(&str, Split, Vec<Pose>)>) -> Corpus {
    let mut corpus =
        Corpus { clips: Vec::new(), joints: Vec::new(), windows: Vec::new(), drops: DropReport::default() };
    for (name, split, poses) in clips {
        for (start, frames) in window_starts(poses.len()) {
            let tags = MotionTags::measure(&poses[start..start + frames]);
            let captions = captions(&tags, "walk", corpus.windows.len());
            corpus.windows.push(CorpusWindow { clip: corpus.clips.len(), start, frames, tags, captions });
        }
        corpus.clips.push(CorpusClip {
            name: name.into(),
            source: Source::Cmu,
            take: name.into(),
            subject: name.into(),
            description: "walk".into(),
            split,
            take_frame: 0,
            offset: corpus.joints.len(),
            frames: poses.len(),
        });
        corpus.joints.extend(poses);
    }
    corpus
}

#[test]
fn crops_start_every_stride_for_each_factor_and_a_short_clip_is_taken_whole() {
    let corpus = tiny_corpus(vec![
        ("long", Split::Train, walking_poses(250, 0.0)),
        ("short", Split::Train, walking_poses(60, 0.0)),
        ("held", Split::Test, walking_poses(250, 0.0)),
    ]);
    let database = RetrievalDatabase::from_corpus(&corpus).unwrap();
    assert_eq!(database.clips(), 2, "the test clip is held out");
    assert!((database.seconds() - 310.0 / FPS).abs() < 1e-9);
    let crops = database.crops(100, &RetrievalConfig::default()).unwrap();
    // 250 frames: 101 poses start at 0..=140 (8), 151 at 0..=80 (5), 201 at 0, 20, 40, 251
    // none; the 60-frame clip whole; all twice (mirrored).
    assert_eq!(crops.len(), 2 * (8 + 5 + 3) + 2, "{crops:?}");
    assert!(crops.iter().all(|c| c.clip < 2 && c.start + c.poses <= [250, 60][c.clip as usize]));
    assert!(crops.contains(&Crop { clip: 1, start: 0, poses: 60, mirrored: true }));
    let bad = RetrievalConfig { resize_factors: vec![0.0], ..RetrievalConfig::default() };
    assert!(database.crops(100, &bad).unwrap_err().to_string().contains("resize factors"));
}

#[test]
fn the_database_of_a_packed_corpus_file_is_the_database_of_the_corpus_it_holds() {
    let corpus = tiny_corpus(vec![
        ("first", Split::Train, walking_poses(150, 0.0)),
        ("held", Split::Test, walking_poses(120, 0.3)),
        ("third", Split::Train, walking_poses(180, -0.5)),
    ]);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("corpus.safetensors.gz");
    crate::corpus::file::save(&corpus, &path).unwrap();
    let packed = RetrievalDatabase::from_packed_corpus(&PackedCorpus::open(&path).unwrap()).unwrap();
    let whole = RetrievalDatabase::from_corpus(&crate::corpus::file::load(&path).unwrap()).unwrap();
    assert_eq!(packed.clips(), 2, "the test clip is held out");
    assert_eq!(format!("{packed:?}"), format!("{whole:?}"));
}

#[test]
fn a_placed_crop_is_what_its_features_recover() {
    let corpus = tiny_corpus(vec![("turn", Split::Train, walking_poses(200, 0.8))]);
    let database = RetrievalDatabase::from_corpus(&corpus).unwrap();
    let frames = 60;
    for crop in [
        Crop { clip: 0, start: 17, poses: 61, mirrored: false },
        Crop { clip: 0, start: 30, poses: 151, mirrored: true },
    ] {
        let mut placed = Vec::new();
        assert!(database.place(&crop, frames, &mut placed));
        assert_eq!(placed.len(), frames * POSE);
        let features = database.features(&crop, frames, &Device::Cpu).unwrap();
        assert_eq!(features.dims(), [frames, FEATURE_DIM]);
        let recovered = recover_from_ric(&features.unsqueeze(0).unwrap()).unwrap();
        let recovered = recovered.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let worst = placed.iter().zip(&recovered).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
        assert!(worst < 1e-4, "{crop:?}: {worst} m");
        // Placed: the first pelvis at x = z = 0, the floor at the lowest joint.
        assert!(placed[0].abs() < 1e-6 && placed[2].abs() < 1e-6);
    }
}

#[test]
fn a_report_written_before_the_corpus_still_reads() {
    let old = r#"{"clip": "humanoid3d_roll", "label": "a person does a forward roll", "mirrored": false,
                  "speed": 1.25, "sequence": 3, "start": 40, "frames": 150}"#;
    let source: CandidateSource = serde_json::from_str(old).unwrap();
    assert_eq!(
        (source.caption.as_str(), source.clip_index, source.window),
        ("a person does a forward roll", 3, [0, 0])
    );
}

#[test]
fn the_semantic_check_reads_the_crops_windows_and_their_mirrors() {
    let corpus = tiny_corpus(vec![("left", Split::Train, walking_poses(240, 0.8))]);
    let database = RetrievalDatabase::from_corpus(&corpus).unwrap();
    let crop = Crop { clip: 0, start: 60, poses: 101, mirrored: false };
    let source = database.source(&crop, 100);
    assert!(source.caption.contains("turns left"), "{source}");
    assert_eq!(source.window, [40, 160]);
    assert_eq!(source.to_string(), format!("left, frames 60..161 at ×1.00 of window 40..160: {:?}", source.caption));
    let mirrored = Crop { mirrored: true, ..crop };
    assert!(database.source(&mirrored, 100).caption.contains("turns right"));
    let windows = database.consistent_windows(&Heard::new("a person walks and turns right", false));
    assert!(!database.crop_is_consistent(&crop, &windows));
    assert!(database.crop_is_consistent(&mirrored, &windows));
}
