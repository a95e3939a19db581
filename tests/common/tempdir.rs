//! A per-test scratch directory, removed on drop.

use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};

/// `<temp>/foldfree-<pid>-<test>`: the process id keeps parallel test binaries apart, the
/// test name keeps parallel tests of one binary apart.
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(test: &str) -> TempDir {
        let dir = std::env::temp_dir().join(format!("foldfree-{}-{}", std::process::id(), test));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).expect("create the test's temp dir");
        TempDir(dir)
    }

    pub fn join(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }

    /// Names of the entries in the directory, sorted.
    pub fn entries(&self) -> BTreeSet<String> {
        fs::read_dir(&self.0)
            .expect("list the temp dir")
            .map(|e| {
                e.expect("read a temp dir entry")
                    .file_name()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect()
    }

    /// Asserts that no hidden (temporary) file is left in the directory.
    pub fn assert_no_temp_files(&self, context: &str) {
        let hidden: Vec<String> = self
            .entries()
            .into_iter()
            .filter(|n| n.starts_with('.'))
            .collect();
        assert!(
            hidden.is_empty(),
            "{context}: temporary files left behind: {hidden:?}"
        );
    }
}

impl AsRef<Path> for TempDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}
