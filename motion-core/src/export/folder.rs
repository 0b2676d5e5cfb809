//! An output folder written as a whole: every file of a run goes into a staging folder beside
//! the target, and the finished folder takes the target's place in one rename. A run that fails
//! or is killed leaves the target as it was; two runs into one folder leave one run's files, never
//! a mix.
//!
//! On Linux an existing target is swapped with `renameat2(RENAME_EXCHANGE)`, so there is no moment
//! at which the target is missing; elsewhere it is moved aside and back on failure. Staging and
//! replaced folders are hidden siblings (`.<name>.staging-<pid>-<n>`); those of a process that no
//! longer runs are removed by the next run into the same target.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use candle_core::Tensor;

use super::error::ExportError;

/// Files whose presence marks a folder as a previous output of ours, which may be replaced.
const OUTPUT_MARKERS: [&str; 4] = ["export.json", "report.json", "joints.npy", "viewer.html"];

/// Staging folders made by this process (to keep their names unique).
static STAGED: AtomicUsize = AtomicUsize::new(0);

/// A folder of outputs being written; see the module docs.
#[derive(Debug)]
pub struct OutputFolder {
    target: PathBuf,
    staging: PathBuf,
    committed: bool,
}

impl OutputFolder {
    /// Checks that `target` can take the outputs and creates the staging folder beside it. Call it
    /// before the work, so a bad `--out` fails at once: `target` must not be a file, its parent
    /// must be writable, and an existing non-empty `target` must be an earlier output folder
    /// (holding one of `export.json`, `report.json`, `joints.npy`, `viewer.html`), since the whole
    /// folder is replaced.
    pub fn create(target: &Path) -> Result<Self, ExportError> {
        let fail = |message: String| ExportError::Write { path: target.into(), message };
        let name = target
            .file_name()
            .filter(|name| !name.is_empty() && *name != "." && *name != "..")
            .ok_or_else(|| fail("an output folder needs a name of its own (not `.`, `..` or `/`)".into()))?
            .to_string_lossy()
            .into_owned();
        let parent = match target.parent().filter(|p| !p.as_os_str().is_empty()) {
            Some(parent) => parent.to_path_buf(),
            None => PathBuf::from("."),
        };
        match std::fs::metadata(target) {
            Ok(meta) if !meta.is_dir() => return Err(fail("exists and is not a folder".into())),
            Ok(_) => {
                let mut entries = std::fs::read_dir(target).map_err(|e| fail(e.to_string()))?;
                let ours = OUTPUT_MARKERS.iter().any(|marker| target.join(marker).exists());
                if entries.next().is_some() && !ours {
                    return Err(fail(format!(
                        "exists and is not an output folder of mogen (it holds none of {}); the whole folder \
                         would be replaced, so choose a new or empty folder",
                        OUTPUT_MARKERS.join(", ")
                    )));
                }
            }
            Err(_) => {}
        }
        std::fs::create_dir_all(&parent)
            .map_err(|e| ExportError::Write { path: parent.clone(), message: format!("cannot create: {e}") })?;
        remove_abandoned(&parent, &name);
        let n = STAGED.fetch_add(1, Ordering::Relaxed);
        let staging = parent.join(format!(".{name}.staging-{}-{n}", std::process::id()));
        std::fs::create_dir(&staging).map_err(|e| ExportError::Write {
            path: staging.clone(),
            message: format!("cannot create the staging folder beside the output ({e})"),
        })?;
        Ok(OutputFolder { target: target.to_path_buf(), staging, committed: false })
    }

    /// The folder to write into until [`OutputFolder::commit`].
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// Where the files will be.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Writes `bytes` as `name` (a path relative to the folder) in one buffered write.
    pub fn write(&self, name: &str, bytes: &[u8]) -> Result<(), ExportError> {
        let path = self.staging.join(name);
        let fail = |e: std::io::Error| ExportError::Write { path: self.target.join(name), message: e.to_string() };
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(fail)?;
        }
        std::fs::write(&path, bytes).map_err(fail)
    }

    /// Writes `tensor` as a little-endian f32 NumPy array (`.npy` version 1.0), built in memory.
    pub fn write_npy(&self, name: &str, tensor: &Tensor) -> Result<(), ExportError> {
        let bytes = crate::npy::npy_bytes(tensor)
            .map_err(|e| ExportError::Write { path: self.target.join(name), message: e })?;
        self.write(name, &bytes)
    }

    /// Hard-links (or copies) into the staging folder every file of the existing target that it
    /// does not hold yet, for commands that add files to an output folder.
    pub fn keep_existing(&self) -> Result<(), ExportError> {
        if self.target.is_dir() {
            link_missing(&self.target, &self.staging)?;
        }
        Ok(())
    }

    /// Puts the finished folder in place of the target and removes what it replaced.
    pub fn commit(mut self) -> Result<PathBuf, ExportError> {
        let fail = |message: String| ExportError::Write { path: self.target.clone(), message };
        sync_folder(&self.staging);
        if self.target.exists() {
            swap_into_place(&self.staging, &self.target).map_err(|e| fail(e.to_string()))?;
            // The staging name now holds the replaced folder.
            let _ = std::fs::remove_dir_all(&self.staging);
        } else {
            std::fs::rename(&self.staging, &self.target).map_err(|e| fail(e.to_string()))?;
        }
        self.committed = true;
        Ok(self.target.clone())
    }
}

impl Drop for OutputFolder {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}

/// Exchanges `staging` and `target` in one step (Linux).
#[cfg(target_os = "linux")]
fn swap_into_place(staging: &Path, target: &Path) -> std::io::Result<()> {
    use rustix::fs::{renameat_with, RenameFlags, CWD};
    renameat_with(CWD, staging, CWD, target, RenameFlags::EXCHANGE).map_err(std::io::Error::from)
}

/// Moves `target` aside, `staging` into place, and `target`'s old content to `staging`'s name;
/// on failure the target is moved back.
#[cfg(not(target_os = "linux"))]
fn swap_into_place(staging: &Path, target: &Path) -> std::io::Result<()> {
    let aside = staging.with_extension("previous");
    std::fs::rename(target, &aside)?;
    if let Err(e) = std::fs::rename(staging, target) {
        let _ = std::fs::rename(&aside, target);
        return Err(e);
    }
    std::fs::rename(&aside, staging)
}

/// Flushes the staging folder's files to disk before they replace the target (a crash of the
/// machine then cannot leave empty files in place of the old ones).
fn sync_folder(dir: &Path) {
    for entry in walk(dir) {
        if let Ok(file) = std::fs::File::open(&entry) {
            let _ = file.sync_all();
        }
    }
}

/// The files under `dir`, recursively.
fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(dir) = pending.pop() {
        for entry in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            let path = entry.path();
            match entry.file_type() {
                Ok(kind) if kind.is_dir() => pending.push(path),
                Ok(kind) if kind.is_file() => files.push(path),
                _ => {}
            }
        }
    }
    files
}

fn link_missing(from: &Path, to: &Path) -> Result<(), ExportError> {
    for file in walk(from) {
        let Ok(relative) = file.strip_prefix(from) else { continue };
        let dest = to.join(relative);
        if dest.exists() {
            continue;
        }
        let fail = |e: std::io::Error| ExportError::Write { path: file.clone(), message: e.to_string() };
        if let Some(parent) = dest.parent() {
            std::fs::create_dir_all(parent).map_err(fail)?;
        }
        if std::fs::hard_link(&file, &dest).is_err() {
            std::fs::copy(&file, &dest).map_err(fail)?;
        }
    }
    Ok(())
}

/// Removes the staging folders of `name` in `parent` left by processes that no longer run
/// (killed mid-run). Only on Linux, where `/proc` says which processes run.
fn remove_abandoned(parent: &Path, name: &str) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let prefix = format!(".{name}.staging-");
    for entry in std::fs::read_dir(parent).into_iter().flatten().flatten() {
        let file_name = entry.file_name().to_string_lossy().into_owned();
        let Some(rest) = file_name.strip_prefix(&prefix) else { continue };
        let Some(pid) = rest.split('-').next().and_then(|pid| pid.parse::<u32>().ok()) else { continue };
        if !Path::new(&format!("/proc/{pid}")).exists() {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folder_appears_whole_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("run");
        // A failed run (dropped before commit): no target, no staging left behind.
        let failed = OutputFolder::create(&target).unwrap();
        failed.write("a.txt", b"one").unwrap();
        drop(failed);
        assert!(!target.exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        // A first run, then a second that replaces it completely.
        let first = OutputFolder::create(&target).unwrap();
        first.write("report.json", b"1").unwrap();
        first.write("sample_0/motion.bvh", b"1").unwrap();
        first.write("old.txt", b"1").unwrap();
        assert!(!target.exists(), "nothing is visible before the commit");
        first.commit().unwrap();
        let second = OutputFolder::create(&target).unwrap();
        second.write("report.json", b"2").unwrap();
        assert_eq!(std::fs::read(target.join("report.json")).unwrap(), b"1", "the old run stays until the commit");
        second.commit().unwrap();
        assert_eq!(std::fs::read(target.join("report.json")).unwrap(), b"2");
        assert!(!target.join("old.txt").exists() && !target.join("sample_0").exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "no staging folders left");
        // Adding to a folder keeps its other files.
        let adding = OutputFolder::create(&target).unwrap();
        adding.write("viewer.html", b"3").unwrap();
        adding.keep_existing().unwrap();
        adding.commit().unwrap();
        assert_eq!(std::fs::read(target.join("report.json")).unwrap(), b"2");
        assert_eq!(std::fs::read(target.join("viewer.html")).unwrap(), b"3");
    }

    #[test]
    fn bad_targets_fail_before_any_work_naming_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("file");
        std::fs::write(&file, b"x").unwrap();
        let err = OutputFolder::create(&file).unwrap_err().to_string();
        assert!(err.contains("file: exists and is not a folder"), "{err}");
        let foreign = dir.path().join("photos");
        std::fs::create_dir(&foreign).unwrap();
        std::fs::write(foreign.join("holiday.jpg"), b"x").unwrap();
        let err = OutputFolder::create(&foreign).unwrap_err().to_string();
        assert!(err.contains("photos: exists and is not an output folder of mogen"), "{err}");
        let err = OutputFolder::create(Path::new(".")).unwrap_err().to_string();
        assert!(err.contains("a name of its own"), "{err}");
        let under_file = file.join("out");
        let err = OutputFolder::create(&under_file).unwrap_err().to_string();
        assert!(err.contains("file: cannot create"), "{err}");
    }

    #[test]
    fn staging_folders_of_dead_processes_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        // A pid above the kernel's maximum (2^22): the staging folder of a process gone.
        let abandoned = dir.path().join(".run.staging-4294967295-0");
        std::fs::create_dir(&abandoned).unwrap();
        let live = dir.path().join(format!(".run.staging-{}-999", std::process::id()));
        std::fs::create_dir(&live).unwrap();
        let folder = OutputFolder::create(&dir.path().join("run")).unwrap();
        assert!(!abandoned.exists());
        assert!(live.exists(), "a running process's staging folder is kept");
        drop(folder);
    }
}
