//! Checking a finished run of the `foldfree` binary.

/// Panics with the exit status, stdout and stderr unless the run succeeded.
pub fn check_ok(out: &std::process::Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed ({}):\nstdout: {}\nstderr: {}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
