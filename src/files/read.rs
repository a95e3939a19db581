//! Bounded input reading.

use std::io::Read;
use std::path::Path;

use super::FileError;

/// The default element limit of every command (faces of a surface, tets of a volume): larger
/// than any mesh this engine is meant for on one device, small enough that a corrupt header or
/// a runaway file is refused before it takes the machine's memory.
pub const DEFAULT_MAX_ELEMENTS: usize = 20_000_000;

/// Bytes of text one element may take in a file, with its share of vertices, comments,
/// normals and texture coordinates (an OBJ face with its vertex takes ~50). The file size limit
/// of a run is this times its element limit.
pub const BYTES_PER_ELEMENT: u64 = 256;

/// The file size limit of a run allowed `elements` faces or tets: [`BYTES_PER_ELEMENT`] each,
/// and never under 1 MiB (headers and comments of a tiny mesh).
pub fn byte_limit(elements: usize) -> u64 {
    (elements as u64)
        .saturating_mul(BYTES_PER_ELEMENT)
        .max(1 << 20)
}

/// Reads a whole input file, refusing more than `limit` bytes. The bound is enforced while
/// reading (a FIFO, `/dev/zero` or a file that grows are not trusted by their metadata), and
/// only regular files are opened: opening a FIFO with no writer would block for ever.
pub fn read_bounded(path: &Path, limit: u64, why: &str) -> Result<Vec<u8>, FileError> {
    let unreadable = |reason: String| FileError::Unreadable {
        path: path.to_path_buf(),
        reason,
    };
    let meta = std::fs::metadata(path).map_err(|e| unreadable(e.to_string()))?;
    if meta.is_dir() {
        return Err(unreadable("is a directory".into()));
    }
    if !meta.is_file() {
        return Err(unreadable(
            "not a regular file (a pipe, socket or device); save it to a file first".into(),
        ));
    }
    let too_large = || FileError::TooLarge {
        path: path.to_path_buf(),
        limit,
        why: why.to_string(),
    };
    if meta.len() > limit {
        return Err(too_large());
    }
    let f = std::fs::File::open(path).map_err(|e| unreadable(e.to_string()))?;
    // Capacity from the metadata is a hint only, itself bounded by the limit.
    let mut bytes = Vec::with_capacity(meta.len().min(limit) as usize);
    f.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| unreadable(e.to_string()))?;
    if bytes.len() as u64 > limit {
        return Err(too_large());
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_are_enforced_while_reading() {
        let dir = std::env::temp_dir().join(format!("foldfree-read-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.txt");
        std::fs::write(&p, b"0123456789").unwrap();
        assert_eq!(read_bounded(&p, 10, "test").unwrap().len(), 10);
        assert!(matches!(
            read_bounded(&p, 9, "test"),
            Err(FileError::TooLarge { limit: 9, .. })
        ));
        assert!(matches!(
            read_bounded(&dir, 9, "test"),
            Err(FileError::Unreadable { .. })
        ));
        // A character device has no trustworthy length: refused, not read for ever.
        if Path::new("/dev/zero").exists() {
            assert!(matches!(
                read_bounded(Path::new("/dev/zero"), 1 << 20, "test"),
                Err(FileError::Unreadable { .. })
            ));
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
