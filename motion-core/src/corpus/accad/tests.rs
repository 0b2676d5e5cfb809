use super::*;
use crate::import::bvh::Rig;

const TAKE: &str = "Male2_bvh/Male2_C22_RunWithBox.bvh";

/// The shipped ACCAD take laid out as `fetch.sh` lays out the takes, with its manifest line.
fn folder() -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mocap/accad/Male2_C22_RunWithBox.bvh");
    std::fs::create_dir_all(dir.path().join("Male2_bvh")).unwrap();
    std::fs::copy(&source, dir.path().join(TAKE)).unwrap();
    let hash = sha256_hex(&std::fs::read(&source).unwrap());
    let manifest = dir.path().join("MANIFEST.sha256");
    std::fs::write(&manifest, format!("{hash}  {TAKE}\n")).unwrap();
    (dir, manifest)
}

#[test]
fn motion_names_become_descriptions_in_words() {
    for (name, words) in [
        ("WalkToHopToWalk1", "walk then hop then walk"),
        ("WalkWithBox", "walk carrying a box"),
        ("PutDownBoxToRun", "put down a box then run"),
        ("WalkTurnLeft135", "walk turn left 135 degrees"),
        ("RunTurnAround", "run turn around"),
        ("SwayT2", "sway"),
        ("CrawlForward", "crawl forward"),
        ("QuickSidestepLeft", "quick sidestep left"),
        ("Extended1", "extended"),
    ] {
        assert_eq!(describe(name), words, "{name}");
    }
}

#[test]
fn a_listed_take_is_read_on_the_accad_rig_and_described() {
    let (dir, manifest) = folder();
    let takes = read_accad_folder(dir.path(), &manifest).unwrap();
    assert_eq!(takes.len(), 1);
    let t = &takes[0];
    assert_eq!(
        (t.source, t.take.as_str(), t.subject.as_str(), t.description.as_str()),
        (Source::Accad, "Male2_C22_RunWithBox", "Male2", "run carrying a box")
    );
    assert_eq!(t.poses.len(), 16, "24 frame times of 0.0333333 s (just under 0.8 s) at 20 fps");
    let (clip, _) = BvhClip::read(&dir.path().join(TAKE), &BvhOptions::default()).unwrap();
    assert_eq!(clip.rig(), Rig::Accad);
    // Centimetres detected: a standing person, pelvis about 0.9 m up before the floor is set.
    let pelvis = t.poses[0][0];
    assert!((0.7..1.2).contains(&pelvis.y), "{pelvis:?}");
    assert!(t.poses.iter().flatten().all(|v| v.is_finite()));
}

#[test]
fn a_changed_or_missing_take_is_named() {
    let (dir, manifest) = folder();
    let path = dir.path().join(TAKE);
    let mut bytes = std::fs::read(&path).unwrap();
    let last = bytes.len() - 2;
    bytes[last] = if bytes[last] == b'1' { b'2' } else { b'1' };
    std::fs::write(&path, &bytes).unwrap();
    let e = read_accad_folder(dir.path(), &manifest).err().unwrap().to_string();
    assert!(e.contains("Male2_C22_RunWithBox.bvh") && e.contains("SHA-256"), "{e}");
    std::fs::remove_file(&path).unwrap();
    let e = read_accad_folder(dir.path(), &manifest).err().unwrap().to_string();
    assert!(e.contains("Male2_C22_RunWithBox.bvh"), "{e}");
    std::fs::write(&manifest, "not a manifest line\n").unwrap();
    let e = read_accad_folder(dir.path(), &manifest).err().unwrap().to_string();
    assert!(e.contains("MANIFEST.sha256") && e.contains("line 1"), "{e}");
}
