//! The motion database built from the shipped catalog, as `mogen data build` does.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use e2e_tests::fixtures;
use motion_core::database::catalog::Catalog;
use motion_core::database::{DatabaseConfig, DatabaseSource, MotionDatabase};

fn small_config() -> DatabaseConfig {
    DatabaseConfig { speeds: vec![1.0], loop_seconds: 4.0, ..DatabaseConfig::default() }
}

#[test]
fn database_builds_saves_and_loads_with_seconds_per_label() {
    let (sources, _) = Catalog::read(&fixtures().join("mocap/catalog.json")).unwrap().load().unwrap();
    let db = MotionDatabase::build(&sources, &small_config()).unwrap();
    let per_label = db.seconds_per_label();
    assert!(per_label.contains_key("a person walks forward"));
    assert!(per_label.contains_key("a person kicks with the left leg and turns right"), "mirrored label");
    assert!(per_label.values().all(|s| *s > 0.0));
    assert!(db.windows().iter().all(|w| w.frames >= 40 && w.frames <= 196));

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db.safetensors");
    db.save(&path).unwrap();
    let back = MotionDatabase::load(&path).unwrap();
    assert_eq!(back.sequences(), db.sequences());
    // RG-DNO's sources: the saved file, and the catalog built in memory, give the same windows.
    let (from_file, _) = DatabaseSource::File(path.clone()).open().unwrap();
    let catalog = DatabaseSource::Catalog { path: fixtures().join("mocap/catalog.json"), config: small_config() };
    let (built, _) = catalog.open().unwrap();
    assert_eq!((from_file.windows(), built.windows()), (db.windows(), db.windows()));
    assert_eq!(back.windows(), db.windows());
    let w = db.windows()[7];
    assert_eq!(back.window_slice(&w, 3, 10), db.window_slice(&w, 3, 10));

    // A truncated or foreign file is an error naming the file, never a panic.
    let bytes = std::fs::read(&path).unwrap();
    for cut in [0, 7, 100, bytes.len() / 2, bytes.len() - 1] {
        std::fs::write(&path, &bytes[..cut]).unwrap();
        let err = MotionDatabase::load(&path).unwrap_err().to_string();
        assert!(err.contains("db.safetensors"), "{err}");
    }
}

#[test]
fn bad_catalogs_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("catalog.json");
    std::fs::write(&path, r#"{"clips": [{"file": "x.txt", "format": "fbx", "label": "a"}]}"#).unwrap();
    assert!(Catalog::read(&path).unwrap_err().to_string().contains("fbx"));
    std::fs::write(&path, r#"{"clips": [{"file": "missing.txt", "format": "deepmimic", "label": "walk"}]}"#).unwrap();
    let err = Catalog::read(&path).unwrap().load().err().unwrap().to_string();
    assert!(err.contains("missing.txt"), "{err}");
    // Opened as RG-DNO's source, the error names the catalog and the clip.
    let err = DatabaseSource::catalog(&path).open().err().unwrap().to_string();
    assert!(err.contains("catalog.json") && err.contains("missing.txt"), "{err}");
}
