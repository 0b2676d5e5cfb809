//! The labelled HDM05 subset of `../shared/data/hdm05/` (CC BY-SA 3.0; see its
//! `PROVENANCE.md`): `<train|test>/<class>/HDM_<actor>.asf` with the actor's
//! `HDM_<actor>_<motion>_<nr>_120.amc` clips, read with the ASF/AMC importer. The folders' own
//! train/test division is not used: splits are by actor like every other source. The clips are
//! cut to one repetition (a hop lasts 0.8 s), so each is held still for up to
//! `HOLD_FRAMES` at both ends to reach a window's length.

use std::path::Path;

use super::source::{RawTake, Source, HOLD_FRAMES};
use crate::files::FileError;
use crate::import::asf_amc::{AsfAmcClip, AsfAmcOptions};
use crate::import::{resample, ImportError};

/// An I/O error naming `path`.
fn io(path: &Path) -> impl Fn(std::io::Error) -> ImportError + '_ {
    move |e| FileError::io(path, &e).into()
}

/// What each of HDM05's motion names does, as a description.
fn describe(motion: &str) -> Option<&'static str> {
    Some(match motion {
        "depositFloorR" => "bend down and put something on the floor with the right hand",
        "elbowToKnee1RepsLelbowStart" => "touch the left elbow to the right knee and the right elbow to the left knee",
        "grabHighR" => "reach up high and grab something with the right hand",
        "hopBothLegs1hops" => "hop once on both legs",
        "jogLeftCircle4StepsRstart" => "jog four steps in a circle to the left",
        "kickLFront1Reps" => "kick forward with the left leg",
        "lieDownFloor" => "lie down on the floor",
        "rotateArmsBothBackward1Reps" => "rotate both arms backwards",
        "sneak2StepsLStart" => "sneak two steps",
        "squat1Reps" => "squat down and stand up",
        "throwBasketball" => "throw a basketball",
        _ => return None,
    })
}

/// Every clip under `folder` (searched two levels down), in file-name order. A motion name the
/// table does not know is described by its own name.
pub fn read_hdm05_folder(folder: &Path) -> Result<Vec<RawTake>, ImportError> {
    let mut amcs = Vec::new();
    for part in std::fs::read_dir(folder).map_err(io(folder))? {
        let part = part.map_err(io(folder))?.path();
        if !part.is_dir() {
            continue;
        }
        for class in std::fs::read_dir(&part).map_err(io(&part))? {
            let class = class.map_err(io(&part))?.path();
            if !class.is_dir() {
                continue;
            }
            for file in std::fs::read_dir(&class).map_err(io(&class))? {
                let file = file.map_err(io(&class))?.path();
                if file.extension().is_some_and(|e| e == "amc") {
                    amcs.push(file);
                }
            }
        }
    }
    amcs.sort_by_key(|p| p.file_name().map(|n| n.to_owned()));
    if amcs.is_empty() {
        return Err(ImportError::Empty { path: folder.into() });
    }
    let mut takes = Vec::with_capacity(amcs.len());
    for amc in amcs {
        let stem = amc.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        // HDM_<actor>_<motion>_<nr>_<fps>
        let parts: Vec<&str> = stem.split('_').collect();
        let (Some(actor), Some(motion)) = (parts.get(1), parts.get(2)) else {
            return Err(ImportError::Invalid {
                path: amc.clone(),
                location: "file name".into(),
                message: "not of the form HDM_<actor>_<motion>_<nr>_<fps>.amc".into(),
            });
        };
        let asf = amc.with_file_name(format!("HDM_{actor}.asf"));
        let (clip, _) = AsfAmcClip::read(&asf, &amc, &AsfAmcOptions::default())?;
        takes.push(RawTake {
            source: Source::Hdm05,
            take: stem.clone(),
            subject: (*actor).to_owned(),
            description: describe(motion).map_or_else(|| (*motion).to_owned(), str::to_owned),
            poses: resample(&clip, 1.0, None),
            screen: true,
            hold_frames: HOLD_FRAMES,
        });
    }
    Ok(takes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped HDM05 clip laid out as the shared folder is: `<part>/<class>/`.
    fn folder() -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        let class = dir.path().join("train").join("4");
        std::fs::create_dir_all(&class).unwrap();
        let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mocap/hdm05");
        for name in ["HDM_bk.asf", "HDM_bk_hopBothLegs1hops_020_120.amc"] {
            std::fs::copy(fixtures.join(name), class.join(name)).unwrap();
        }
        dir
    }

    #[test]
    fn a_clip_is_read_with_its_actor_and_described_by_its_motion() {
        let dir = folder();
        let takes = read_hdm05_folder(dir.path()).unwrap();
        assert_eq!(takes.len(), 1);
        let t = &takes[0];
        assert_eq!((t.subject.as_str(), t.description.as_str()), ("bk", "hop once on both legs"));
        assert_eq!(t.take, "HDM_bk_hopBothLegs1hops_020_120");
        assert_eq!(t.poses.len(), 10, "55/120 s at 20 fps");
        assert_eq!(t.hold_frames, HOLD_FRAMES);
    }

    #[test]
    fn a_missing_skeleton_and_an_empty_folder_are_named() {
        let dir = folder();
        std::fs::remove_file(dir.path().join("train/4/HDM_bk.asf")).unwrap();
        let e = read_hdm05_folder(dir.path()).err().unwrap().to_string();
        assert!(e.contains("HDM_bk.asf"), "{e}");
        let empty = tempfile::tempdir().unwrap();
        let e = read_hdm05_folder(empty.path()).err().unwrap().to_string();
        assert!(e.contains("no frames") || e.contains(&empty.path().display().to_string()), "{e}");
    }
}
