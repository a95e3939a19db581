//! Files in and out, with one policy for every command: inputs are read with a size bound that
//! does not trust the file system's metadata; outputs are planned before any work (folder,
//! extension, identity against the inputs and each other) and committed together at the end.
#![forbid(unsafe_code)]

mod outputs;
mod read;

pub use outputs::Outputs;
pub use read::{byte_limit, read_bounded, BYTES_PER_ELEMENT, DEFAULT_MAX_ELEMENTS};

use std::path::PathBuf;

/// What went wrong with a file. Everything but [`FileError::Write`] is the request's fault
/// (exit code 2): a missing or unreadable input, a file too large for the limit, an output path
/// that cannot be written or names an input.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// An input cannot be opened or read.
    #[error("{}: cannot read: {reason}", path.display())]
    Unreadable { path: PathBuf, reason: String },
    /// An input is larger than the limit of the run.
    #[error("{}: more than {limit} bytes, the limit of this run ({why}); raise the limit to read it", path.display())]
    TooLarge {
        path: PathBuf,
        limit: u64,
        why: String,
    },
    /// An output path is unusable (no folder, not writable, unknown extension, a directory).
    #[error("{}: cannot write the {what} here: {reason}", path.display())]
    BadOutput {
        path: PathBuf,
        what: String,
        reason: String,
    },
    /// An output names an input or another output of the same run (same file, by identity).
    #[error("{}: refusing to overwrite {other} with the {what}", path.display())]
    SameFile {
        path: PathBuf,
        what: String,
        other: String,
    },
    /// Writing or renaming failed after the work was done (disk full, permissions changed);
    /// nothing of this run is left behind.
    #[error("{}: writing failed: {source}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

impl FileError {
    /// 1 for a failure of the file system while writing, 2 for everything the request decides.
    pub fn exit_code(&self) -> i32 {
        match self {
            FileError::Write { .. } => 1,
            _ => 2,
        }
    }
}
