//! ACCAD's Open Motion Project (The Ohio State University, CC BY 3.0: "Motion capture data from
//! ACCAD, The Ohio State University"): two performers' BVH takes, `Female1_bvh/` (81 takes) and
//! `Male2_bvh/` (149), as `fixtures/corpus/accad/fetch.sh` copies them from the public
//! repositories that hold them. Every file is checked against the SHA-256 list
//! `fixtures/corpus/accad/MANIFEST.sha256` (`sha256sum` format, paths relative to the folder)
//! before it is read, so a corpus is built from exactly the takes its data card names.
//!
//! Files are `<performer>_<code>_<Motion>.bvh` (`Female1_B20_WalkWithBox.bvh`,
//! `Male2_C24_QuickSidestepLeft.bvh`, at 30 or 120 fps, centimetres, MotionBuilder's rig
//! [`Rig::Accad`](crate::import::bvh::Rig::Accad)); the motion name becomes the take's
//! description in words ([`describe`]).

use std::path::Path;

use super::caption::split_camel_case;
use super::source::{RawTake, Source, HOLD_FRAMES};
use crate::files::{sha256_hex, FileError};
use crate::import::bvh::{BvhClip, BvhOptions};
use crate::import::{resample, ImportError};

/// Turn angles that a motion name ends with (`WalkTurnLeft135`), as opposed to take numbers
/// (`Walk1`, `SkipToWalk1`).
const ANGLES: [&str; 4] = ["45", "90", "135", "180"];

/// A take's motion name in words: split at capitals and digits, lower case, the take numbering
/// (`Walk1`, `SwayT2`) dropped, `To` between two motions read as "then", a box given its article
/// and a box held while moving read as carried, turn angles in degrees:
/// `WalkToHopToWalk1` → "walk then hop then walk", `WalkWithBox` → "walk carrying a box",
/// `WalkTurnLeft135` → "walk turn left 135 degrees", `PutDownBoxToRun` → "put down a box then run".
pub fn describe(motion: &str) -> String {
    let mut words: Vec<String> = split_camel_case(motion).iter().map(|w| w.to_ascii_lowercase()).collect();
    // "T2" is a second take: split as "t", "2".
    if words.len() >= 2 && words[words.len() - 2] == "t" && words[words.len() - 1].chars().all(|c| c.is_ascii_digit()) {
        words.truncate(words.len() - 2);
    }
    let mut out: Vec<String> = Vec::new();
    for (k, word) in words.iter().enumerate() {
        if word.chars().all(|c| c.is_ascii_digit()) {
            if ANGLES.contains(&word.as_str()) && k > 0 && ["left", "right", "around"].contains(&words[k - 1].as_str())
            {
                out.push(word.clone());
                out.push("degrees".into());
            }
            continue;
        }
        match word.as_str() {
            "to" if k > 0 => out.push("then".into()),
            "box" => {
                if out.last().is_some_and(|w| w == "with") {
                    out.pop();
                    if !out.is_empty() {
                        out.push("carrying".into());
                    }
                }
                out.push("a".into());
                out.push("box".into());
            }
            _ => out.push(word.clone()),
        }
    }
    out.join(" ")
}

/// The manifest's `(sha256, relative path)` lines, in file order.
fn manifest(path: &Path) -> Result<Vec<(String, String)>, ImportError> {
    let text = std::fs::read_to_string(path).map_err(|e| ImportError::from(FileError::io(path, &e)))?;
    let mut out = Vec::new();
    for (k, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let (hash, file) = line.split_once("  ").ok_or_else(|| ImportError::Invalid {
            path: path.into(),
            location: format!("line {}", k + 1),
            message: "not `<sha256>  <path>` (sha256sum's format)".into(),
        })?;
        out.push((hash.trim().to_owned(), file.trim().to_owned()));
    }
    if out.is_empty() {
        return Err(ImportError::Empty { path: path.into() });
    }
    Ok(out)
}

/// Every take the manifest lists, read from `folder` after its SHA-256 is checked, in the
/// manifest's order. A missing file, a changed file or a name not of the form
/// `<performer>_<code>_<Motion>.bvh` is an error naming the file.
pub fn read_accad_folder(folder: &Path, manifest_path: &Path) -> Result<Vec<RawTake>, ImportError> {
    let mut takes = Vec::new();
    for (hash, file) in manifest(manifest_path)? {
        let path = folder.join(&file);
        let bytes = std::fs::read(&path).map_err(|e| ImportError::from(FileError::io(&path, &e)))?;
        let found = sha256_hex(&bytes);
        if found != hash {
            return Err(ImportError::Invalid {
                path: path.clone(),
                location: "whole file".into(),
                message: format!(
                    "SHA-256 {found} is not the {hash} that {} lists: not the published take",
                    manifest_path.display()
                ),
            });
        }
        let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        // <performer>_<code>[_<code>]_<Motion>[_<n>]: codes are a capital and digits (A11, S2).
        let mut parts = stem.split('_');
        let performer = parts.next().unwrap_or_default().to_owned();
        let is_code = |p: &str| {
            p.len() >= 2
                && p.starts_with(|c: char| c.is_ascii_uppercase())
                && p[1..].chars().all(|c| c.is_ascii_digit())
        };
        let motion: String = parts.filter(|p| !is_code(p)).collect();
        let description = describe(&motion);
        if performer.is_empty() || description.is_empty() {
            return Err(ImportError::Invalid {
                path,
                location: "file name".into(),
                message: "not of the form <performer>_<code>_<Motion>.bvh".into(),
            });
        }
        let (clip, _) = BvhClip::read(&path, &BvhOptions::default())?;
        takes.push(RawTake {
            source: Source::Accad,
            take: stem.clone(),
            subject: performer,
            description,
            poses: resample(&clip, 1.0, None),
            screen: true,
            hold_frames: HOLD_FRAMES,
        });
    }
    Ok(takes)
}

#[cfg(test)]
mod tests;
