//! Errors of the volumetric pipeline. Input problems carry the file and the line or tet so a
//! user can find them; they map to exit code 2, solver / output failures to 1.

use std::path::PathBuf;

/// Anything the volumetric pipeline can fail with.
#[derive(Debug, thiserror::Error)]
pub enum VolError {
    /// A syntax problem at a known line (1-based).
    #[error("{}:{line}: {msg}", file.display())]
    Parse {
        file: PathBuf,
        line: usize,
        msg: String,
    },
    /// The file ended before a section announced as complete.
    #[error("{}:{line}: file truncated: {what}", file.display())]
    Truncated {
        file: PathBuf,
        line: usize,
        what: String,
    },
    /// A tet names a vertex that does not exist.
    #[error("{}:{line}: tet {tet} uses vertex index {index}, but there are {count} vertices", file.display())]
    BadIndex {
        file: PathBuf,
        line: usize,
        tet: usize,
        index: i64,
        count: usize,
    },
    /// A coordinate is NaN or infinite.
    #[error("{}:{line}: vertex {vertex} has a non-finite coordinate", file.display())]
    NonFinite {
        file: PathBuf,
        line: usize,
        vertex: usize,
    },
    /// A rest tet has negative volume (the rest shape must be a valid embedding).
    #[error("{}: rest tet {tet} is inverted (signed volume {volume:.3e} at unit scale)", file.display())]
    InvertedRest {
        file: PathBuf,
        tet: usize,
        volume: f64,
    },
    /// A rest tet has (numerically) zero volume: its Jacobian is undefined.
    #[error("{}: rest tet {tet} has zero volume ({volume:.3e} at unit scale)", file.display())]
    ZeroVolume {
        file: PathBuf,
        tet: usize,
        volume: f64,
    },
    /// Two meshes that must share connectivity (rest and init) do not, or the request is wrong.
    #[error("{0}")]
    Input(String),
    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A linear solve failed.
    #[error(transparent)]
    Solve(#[from] crate::linalg::SolveError),
    /// The result is unusable (inverted tets, NaN); it is not written.
    #[error("{0}")]
    BadResult(String),
    /// An input cannot be read, or an output path is unusable.
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    /// `--backend vulkan`: no device, a named device that is absent (exit 2), or a device
    /// failure (exit 1).
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
}

impl VolError {
    /// 2 for bad input, 1 for failures of the solver or the file system.
    pub fn exit_code(&self) -> i32 {
        match self {
            VolError::Io { .. } | VolError::Solve(_) | VolError::BadResult(_) => 1,
            VolError::File(e) => e.exit_code(),
            VolError::Gpu(crate::gpu::GpuError::NoSuchDevice(_)) => 2,
            VolError::Gpu(_) => 1,
            _ => 2,
        }
    }
}

/// Reads a text input file of at most `limit` bytes: a missing or unreadable file and invalid
/// UTF-8 (a binary file, at the line of the first bad byte) are bad input (exit 2).
pub(crate) fn read_text(path: &std::path::Path, limit: u64) -> Result<String, VolError> {
    let bytes = crate::files::read_bounded(path, limit, "the --max-tets limit")?;
    String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let line = 1 + e.as_bytes()[..at].iter().filter(|&&b| b == b'\n').count();
        VolError::Parse {
            file: path.to_path_buf(),
            line,
            msg: "not UTF-8 text (binary file?)".into(),
        }
    })
}

/// An option outside its range is bad input (exit 2), with the option type's message.
impl From<crate::OptionError> for VolError {
    fn from(e: crate::OptionError) -> Self {
        VolError::Input(e.to_string())
    }
}
