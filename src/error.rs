//! The crate-level error: one variant per layer, so a caller can tell bad input (exit code 2)
//! from a failure of the machine or the solver (exit code 1).

use std::path::PathBuf;

/// Any error foldfree returns.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The input mesh is unusable (names the file and the face / edge / vertex).
    #[error(transparent)]
    Mesh(#[from] crate::mesh::MeshError),
    /// Vulkan is missing or failed.
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
    /// A numerical solve failed (no convergence, non-finite values, flipped result).
    #[error(transparent)]
    Solve(#[from] crate::linalg::SolveError),
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Planar approximation failed (bad input: 2, solver: 1).
    #[error(transparent)]
    Approx(#[from] crate::approx::ApproxError),
    /// Volumetric maps: bad tet mesh / constraints (exit 2) or a failed solve (exit 1).
    #[error(transparent)]
    Vol(#[from] crate::vol::VolError),
    /// An input cannot be read, or an output path is unusable or names an input (exit 2); or
    /// writing the outputs failed at the end (exit 1, nothing left behind).
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    /// An option outside its range (exit 2), from an option type's `validate()`.
    #[error(transparent)]
    Option(#[from] OptionError),
    /// The request itself is wrong (bad option combination, refusing to overwrite the input).
    #[error("{0}")]
    Usage(String),
    /// A flip-free result was written, but the solver's stop test was not met (iteration cap,
    /// Ctrl-C); the message says how far from it the run was. Exit code 3.
    #[error("{0}")]
    NotConverged(String),
}

impl Error {
    /// Process exit code for the CLI: 2 for bad input or usage, 3 for a written result that did
    /// not converge, 1 for everything else.
    pub fn exit_code(&self) -> i32 {
        match self {
            Error::Mesh(_) | Error::Usage(_) | Error::Option(_) => 2,
            Error::Gpu(crate::gpu::GpuError::NoSuchDevice(_)) => 2,
            Error::Gpu(_) | Error::Solve(_) | Error::Io { .. } => 1,
            Error::NotConverged(_) => 3,
            Error::Approx(e) => e.exit_code(),
            Error::Vol(e) => e.exit_code(),
            Error::File(e) => e.exit_code(),
        }
    }
}

/// A setting outside its meaningful range: what every option type's `validate()` returns
/// (`AdmmOptions`, `CutOptions`, `PackOptions`, `VolmapOptions`), in one message shape,
/// `OPTIONS option KEY = VALUE is outside its range RANGE`. `key` is the setting's name in a
/// tuning file ([`crate::tuning`]), so a host can point at the line that set it.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{options} option {key} = {value} is outside its range {range}")]
pub struct OptionError {
    /// Which option type: `ADMM`, `cut`, `pack`, `volmap`.
    pub options: &'static str,
    /// The setting's key (a dotted path for nested settings, e.g. `post.max_iters`).
    pub key: String,
    pub value: String,
    pub range: String,
}

impl OptionError {
    pub fn new(
        options: &'static str,
        key: &str,
        value: impl std::fmt::Display,
        range: &str,
    ) -> OptionError {
        OptionError {
            options,
            key: key.to_string(),
            value: value.to_string(),
            range: range.to_string(),
        }
    }

    /// The rejection of `key` by the `validate()` of the option type `options`.
    pub fn reject<T>(
        options: &'static str,
        key: &str,
        value: impl std::fmt::Display,
        range: &str,
    ) -> std::result::Result<T, OptionError> {
        Err(OptionError::new(options, key, value, range))
    }
}

/// Result alias used across the crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

#[cfg(test)]
mod tests {
    use super::*;

    /// The CLI's documented exit codes (README, `foldfree param --help`).
    #[test]
    fn exit_codes_follow_the_documented_contract() {
        assert_eq!(Error::Usage("bad flag".into()).exit_code(), 2);
        assert_eq!(Error::NotConverged("cap".into()).exit_code(), 3);
        let solve = crate::linalg::SolveError::Failed { what: "x".into() };
        assert_eq!(Error::Solve(solve).exit_code(), 1);
    }
}
