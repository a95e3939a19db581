//! The output policy: every output of a run is checked before the run starts and all of them
//! are committed together when it ends, so a run either leaves all its files or none, and never
//! replaces one of its own inputs.

use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use super::FileError;

/// Which file a path names. Existing files are compared by device and inode (Unix), so a
/// hard link, a symlink or `./x` names the same file as `x`; files still to be made by their
/// canonical folder and name.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Identity {
    #[cfg(unix)]
    Inode(u64, u64),
    Path(PathBuf),
}

fn identity(path: &Path) -> Option<Identity> {
    if let Ok(meta) = std::fs::metadata(path) {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            let _ = &meta;
            return Some(Identity::Inode(meta.dev(), meta.ino()));
        }
        #[cfg(not(unix))]
        {
            let _ = meta;
            return path.canonicalize().ok().map(Identity::Path);
        }
    }
    let name = path.file_name()?;
    let dir = folder_of(path).canonicalize().ok()?;
    Some(Identity::Path(dir.join(name)))
}

fn folder_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// A unique temporary name beside `path` (same folder, so the final rename is atomic).
fn temp_beside(path: &Path, tag: &str) -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let mut name = OsString::from(".");
    name.push(path.file_name().unwrap_or_default());
    name.push(format!(
        ".{tag}-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    folder_of(path).join(name)
}

struct Planned {
    path: PathBuf,
    what: String,
    id: Identity,
    bytes: Option<Vec<u8>>,
}

/// The outputs of one run. [`Outputs::input`] and [`Outputs::output`] before any work (each
/// output is checked then: its folder exists and is writable, its extension is one the run
/// writes, it is not an input or another output); [`Outputs::set`] as results are ready;
/// [`Outputs::commit`] at the end writes every file to a temporary beside it and renames them
/// all. A run that fails before the commit, or a commit that fails, leaves no file behind.
#[derive(Default)]
pub struct Outputs {
    inputs: Vec<(PathBuf, Identity)>,
    planned: Vec<Planned>,
}

impl Outputs {
    pub fn new() -> Outputs {
        Outputs::default()
    }

    /// Records an input of the run. A missing input is the reader's error to report, so it is
    /// only remembered by path.
    pub fn input(&mut self, path: &Path) -> &mut Outputs {
        if let Some(id) = identity(path) {
            self.inputs.push((path.to_path_buf(), id));
        }
        self
    }

    /// Records an input found while reading another (a glTF file's external `.bin`), after
    /// the outputs were planned: refused when a planned output is that file, so the commit can
    /// never replace it.
    pub fn late_input(&mut self, path: &Path) -> Result<&mut Outputs, FileError> {
        let Some(id) = identity(path) else {
            return Ok(self);
        };
        if let Some(o) = self.planned.iter().find(|o| o.id == id) {
            return Err(FileError::SameFile {
                path: o.path.clone(),
                what: o.what.clone(),
                other: format!("the input {}", path.display()),
            });
        }
        self.inputs.push((path.to_path_buf(), id));
        Ok(self)
    }

    /// Checks and reserves an output path for `what` (e.g. "report"), whose extension must be
    /// one of `extensions` (lower case, without the dot; empty: any).
    pub fn output(
        &mut self,
        path: &Path,
        what: &str,
        extensions: &[&str],
    ) -> Result<&mut Outputs, FileError> {
        let bad = |reason: String| FileError::BadOutput {
            path: path.to_path_buf(),
            what: what.to_string(),
            reason,
        };
        if path.file_name().is_none() {
            return Err(bad("not a file name".into()));
        }
        let dir = folder_of(path);
        if !dir.is_dir() {
            return Err(bad(format!("the folder {} does not exist", dir.display())));
        }
        if let Ok(meta) = std::fs::symlink_metadata(path) {
            let meta = if meta.file_type().is_symlink() {
                std::fs::metadata(path).unwrap_or(meta)
            } else {
                meta
            };
            if !meta.is_file() {
                return Err(bad("it exists and is not a regular file".into()));
            }
        }
        let id = identity(path).ok_or_else(|| bad("cannot resolve the path".into()))?;
        if let Some((p, _)) = self.inputs.iter().find(|(_, i)| *i == id) {
            return Err(FileError::SameFile {
                path: path.to_path_buf(),
                what: what.to_string(),
                other: format!("the input {}", p.display()),
            });
        }
        if let Some(o) = self.planned.iter().find(|o| o.id == id) {
            return Err(FileError::SameFile {
                path: path.to_path_buf(),
                what: what.to_string(),
                other: format!("the {} {}", o.what, o.path.display()),
            });
        }
        if !extensions.is_empty() {
            let ext = path
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase());
            if !ext.as_deref().is_some_and(|e| extensions.contains(&e)) {
                let list: Vec<String> = extensions.iter().map(|e| format!(".{e}")).collect();
                return Err(bad(format!("the extension must be {}", list.join(" or "))));
            }
        }
        // Writable: make and remove an empty file where the temporary will go.
        let probe = temp_beside(path, "probe");
        std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&probe)
            .map_err(|e| bad(format!("the folder is not writable ({e})")))?;
        let _ = std::fs::remove_file(&probe);
        self.planned.push(Planned {
            path: path.to_path_buf(),
            what: what.to_string(),
            id,
            bytes: None,
        });
        Ok(self)
    }

    /// The content of a planned output.
    ///
    /// # Panics
    /// If `path` was not planned with [`Outputs::output`] (a programming error of the caller).
    pub fn set(&mut self, path: &Path, bytes: Vec<u8>) {
        let o = self
            .planned
            .iter_mut()
            .find(|o| o.path == path)
            .unwrap_or_else(|| panic!("output {} was not planned", path.display()));
        o.bytes = Some(bytes);
    }

    /// Writes every planned output that has content: each to a temporary beside it (synced),
    /// then renames them all into place. On failure the temporaries are removed and the
    /// targets keep their old content (a rename failing after others succeeded, which needs
    /// the folder to change under the run, is reported with the path).
    pub fn commit(self) -> Result<Vec<PathBuf>, FileError> {
        let mut temps: Vec<(PathBuf, &Path)> = Vec::new();
        let cleanup = |temps: &[(PathBuf, &Path)]| {
            for (t, _) in temps {
                let _ = std::fs::remove_file(t);
            }
        };
        for o in &self.planned {
            let Some(bytes) = &o.bytes else { continue };
            let tmp = temp_beside(&o.path, "tmp");
            let written = (|| {
                let mut f = std::fs::File::create(&tmp)?;
                temps.push((tmp.clone(), &o.path));
                f.write_all(bytes)?;
                f.sync_all()
            })();
            if let Err(source) = written {
                cleanup(&temps);
                return Err(FileError::Write {
                    path: o.path.clone(),
                    source,
                });
            }
        }
        let mut done = Vec::new();
        for (i, (tmp, path)) in temps.iter().enumerate() {
            if let Err(source) = std::fs::rename(tmp, path) {
                cleanup(&temps[i..]);
                return Err(FileError::Write {
                    path: path.to_path_buf(),
                    source,
                });
            }
            done.push(path.to_path_buf());
        }
        for p in &done {
            // Make the renames durable (best effort: not every platform can sync a folder).
            if let Ok(d) = std::fs::File::open(folder_of(p)) {
                let _ = d.sync_all();
            }
        }
        Ok(done)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("foldfree-out-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn outputs_are_checked_by_identity_and_committed_together() {
        let d = dir("id");
        let input = d.join("in.obj");
        std::fs::write(&input, b"input").unwrap();
        let mut o = Outputs::new();
        o.input(&input);
        // The same file under another spelling, and through a hard link.
        let dotted = d.join(".").join("in.obj");
        assert!(matches!(
            o.output(&dotted, "map", &["obj"]),
            Err(FileError::SameFile { .. })
        ));
        let link = d.join("link.obj");
        std::fs::hard_link(&input, &link).unwrap();
        assert!(matches!(
            o.output(&link, "map", &["obj"]),
            Err(FileError::SameFile { .. })
        ));
        // Unknown extension, missing folder, two outputs on one file.
        assert!(matches!(
            o.output(&d.join("out.txt"), "map", &["obj"]),
            Err(FileError::BadOutput { .. })
        ));
        assert!(matches!(
            o.output(&d.join("no/such/out.obj"), "map", &["obj"]),
            Err(FileError::BadOutput { .. })
        ));
        o.output(&d.join("out.obj"), "map", &["obj"]).unwrap();
        assert!(matches!(
            o.output(&d.join("out.obj"), "report", &["json"]),
            Err(FileError::SameFile { .. })
        ));
        assert!(matches!(
            o.output(&d.join("./out.obj"), "picture", &[]),
            Err(FileError::SameFile { .. })
        ));
        o.output(&d.join("r.json"), "report", &["json"]).unwrap();
        // Nothing exists before the commit; both after it; no temporaries left.
        o.set(&d.join("out.obj"), b"map".to_vec());
        o.set(&d.join("r.json"), b"{}".to_vec());
        assert!(!d.join("out.obj").exists());
        o.commit().unwrap();
        assert_eq!(std::fs::read(d.join("out.obj")).unwrap(), b"map");
        assert_eq!(std::fs::read(d.join("r.json")).unwrap(), b"{}");
        assert_eq!(std::fs::read(&input).unwrap(), b"input");
        let left = std::fs::read_dir(&d).unwrap().count();
        assert_eq!(left, 4, "in.obj, link.obj, out.obj, r.json");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_run_dropped_before_commit_leaves_nothing() {
        let d = dir("drop");
        {
            let mut o = Outputs::new();
            o.output(&d.join("a.obj"), "map", &["obj"]).unwrap();
            o.set(&d.join("a.obj"), b"x".to_vec());
        }
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 0);
        std::fs::remove_dir_all(&d).unwrap();
    }
}
