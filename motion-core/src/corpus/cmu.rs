//! The CMU Graphics Lab Motion Capture Database in the shared form of `../shared/data/cmu/`
//! (see its `PROVENANCE.md`): one `[frames, 22, 3]` float16 array per take in
//! `smpl22_20fps_f16.npz` (metres, y up, the 22 joints in HumanML3D order, 20 fps, world
//! positions as captured: not canonicalised, floor not adjusted, not retargeted) and one line
//! per take in `index.tsv` (take, description, subject category, ...).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::source::{RawTake, Source};
use crate::files::{read_text, FileError};
use crate::import::ImportError;
use crate::limits::MOCAP_FILE_BYTES;
use crate::skeleton::{Pose, NUM_JOINTS};

/// File name of the positions inside a CMU folder.
pub const POSITIONS_FILE: &str = "smpl22_20fps_f16.npz";
/// File name of the per-take index inside a CMU folder.
pub const INDEX_FILE: &str = "index.tsv";

/// One take of the database as shared: its id, what CMU says of it and its 20 fps positions.
#[derive(Debug, Clone)]
pub struct CmuTake {
    /// CMU trial id, `<subject>_<trial>` (`07_01`).
    pub take: String,
    /// CMU's per-take description (`walk`, `playground - climb`); empty when CMU has none.
    pub description: String,
    /// The subject's category (`Subject #7 (walk)`), used when the take has no description.
    pub subject_category: String,
    /// Joint positions at 20 fps, as captured.
    pub poses: Vec<Pose>,
}

impl CmuTake {
    /// The subject id, the part of the take id before `_` (`07`).
    pub fn subject(&self) -> &str {
        self.take.split('_').next().unwrap_or(&self.take)
    }

    /// What CMU says of the take: its description, else what its subject's category says in
    /// brackets (`Subject #7 (walk)` → `walk`), else nothing.
    pub fn what(&self) -> String {
        if !self.description.is_empty() {
            return self.description.clone();
        }
        let category = self.subject_category.as_str();
        match (category.find('('), category.rfind(')')) {
            (Some(a), Some(b)) if b > a + 1 => category[a + 1..b].trim().to_owned(),
            _ => String::new(),
        }
    }
}

impl From<CmuTake> for RawTake {
    fn from(take: CmuTake) -> Self {
        RawTake {
            source: Source::Cmu,
            subject: take.subject().to_owned(),
            description: take.what(),
            take: take.take,
            poses: take.poses,
            screen: true,
            hold_frames: 0,
        }
    }
}

/// Reads every take of a CMU folder, in take order. Errors name the file and the line or
/// array; a take in the index without positions (or the reverse) is an error, so a damaged
/// copy is never read as a smaller database.
pub fn read_cmu_folder(folder: &Path) -> Result<Vec<CmuTake>, ImportError> {
    let index_path = folder.join(INDEX_FILE);
    let index = read_index(&index_path)?;
    let positions_path = folder.join(POSITIONS_FILE);
    let arrays = read_positions(&positions_path)?;
    let mut takes = Vec::with_capacity(index.len());
    let mut by_take: HashMap<String, Vec<Pose>> = arrays.into_iter().collect();
    for entry in index {
        let poses = by_take.remove(&entry.take).ok_or_else(|| ImportError::Invalid {
            path: positions_path.clone(),
            location: format!("array {}", entry.take),
            message: format!("the take is listed in {} (line {}) but has no positions", INDEX_FILE, entry.line),
        })?;
        takes.push(CmuTake {
            take: entry.take,
            description: entry.description,
            subject_category: entry.subject_category,
            poses,
        });
    }
    if let Some(extra) = by_take.keys().min() {
        return Err(ImportError::Invalid {
            path: index_path,
            location: format!("take {extra}"),
            message: format!("{POSITIONS_FILE} has positions for a take the index does not list"),
        });
    }
    takes.sort_by(|a, b| a.take.cmp(&b.take));
    Ok(takes)
}

struct IndexEntry {
    line: usize,
    take: String,
    description: String,
    subject_category: String,
}

/// Parses `index.tsv`: a header naming at least `take`, `description` and `subject_category`,
/// then one tab-separated line per take.
fn read_index(path: &Path) -> Result<Vec<IndexEntry>, ImportError> {
    let text = read_text(path, &MOCAP_FILE_BYTES)?;
    let invalid = |line: usize, message: String| ImportError::Invalid {
        path: path.to_path_buf(),
        location: format!("line {line}"),
        message,
    };
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l));
    let (_, header) = lines.next().ok_or_else(|| ImportError::Empty { path: path.to_path_buf() })?;
    let columns: Vec<&str> = header.split('\t').collect();
    let column = |name: &str| {
        columns.iter().position(|c| *c == name).ok_or_else(|| invalid(1, format!("no `{name}` column in the header")))
    };
    let (take_col, desc_col, cat_col) = (column("take")?, column("description")?, column("subject_category")?);
    let mut entries = Vec::new();
    for (line, row) in lines.filter(|(_, l)| !l.trim().is_empty()) {
        let fields: Vec<&str> = row.split('\t').collect();
        let field = |col: usize| {
            fields.get(col).map(|s| s.trim().to_owned()).ok_or_else(|| {
                invalid(line, format!("{} tab-separated fields; column {} is missing", fields.len(), col + 1))
            })
        };
        let take = field(take_col)?;
        let valid = take.split_once('_').is_some_and(|(s, t)| {
            !s.is_empty() && !t.is_empty() && s.bytes().chain(t.bytes()).all(|b| b.is_ascii_digit())
        });
        if !valid {
            return Err(invalid(line, format!("take id {take:?} is not of the form <subject>_<trial>")));
        }
        entries.push(IndexEntry { line, take, description: field(desc_col)?, subject_category: field(cat_col)? });
    }
    if entries.is_empty() {
        return Err(ImportError::Empty { path: path.to_path_buf() });
    }
    Ok(entries)
}

/// Reads the npz of positions: every array must be `[frames ≥ 2, 22, 3]` of finite values.
fn read_positions(path: &Path) -> Result<Vec<(String, Vec<Pose>)>, ImportError> {
    let size = std::fs::metadata(path).map_err(|e| FileError::io(path, &e))?.len();
    MOCAP_FILE_BYTES.check(size, path.display())?;
    let invalid =
        |location: String, message: String| ImportError::Invalid { path: PathBuf::from(path), location, message };
    let arrays = candle_core::Tensor::read_npz(path).map_err(|e| invalid("npz".into(), e.to_string()))?;
    arrays
        .into_iter()
        .map(|(name, tensor)| {
            let dims = tensor.dims().to_vec();
            if dims.len() != 3 || dims[1] != NUM_JOINTS || dims[2] != 3 || dims[0] < 2 {
                return Err(invalid(format!("array {name}"), format!("shape {dims:?}, expected [frames ≥ 2, 22, 3]")));
            }
            let values = tensor
                .to_dtype(candle_core::DType::F64)
                .and_then(|t| t.flatten_all())
                .and_then(|t| t.to_vec1::<f64>())
                .map_err(|e| invalid(format!("array {name}"), e.to_string()))?;
            if let Some(i) = values.iter().position(|v| !v.is_finite()) {
                return Err(invalid(format!("array {name}"), format!("value {i} is not finite")));
            }
            let poses = values
                .chunks_exact(3 * NUM_JOINTS)
                .map(|frame| std::array::from_fn(|j| DVec3::new(frame[3 * j], frame[3 * j + 1], frame[3 * j + 2])))
                .collect();
            Ok((name, poses))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_lines_name_the_line_of_a_bad_take_id() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("index.tsv");
        std::fs::write(&path, "take\tdescription\tsubject_category\n07_01\twalk\tSubject #7\nx7\trun\tS\n").unwrap();
        let e = read_index(&path).err().unwrap().to_string();
        assert!(e.contains("index.tsv") && e.contains("line 3") && e.contains("\"x7\""), "{e}");
        std::fs::write(&path, "take\tdescription\n").unwrap();
        let e = read_index(&path).err().unwrap().to_string();
        assert!(e.contains("line 1") && e.contains("subject_category"), "{e}");
    }
}
