//! Files: atomic writes, checked postcard envelopes and content hashes — the one copy.
//!
//! - `write_atomic(path, bytes)`: a temporary file in the same directory, fsync, rename, so
//!   a reader (or a resumed run) sees either the old file or the whole new one.
//! - `decode_checked`: `magic (8 bytes) ‖ postcard(T)` with a format version inside `T`;
//!   a wrong magic, a decode error or another version is a [`FileError::Format`] naming the file.
//! - `hex(SHA-256(bytes))`: the content hashes that manifests and certificates record.
//!
//! A leaf module: it imports nothing of the crate, and every stage may use it.

use std::io::Write;
use std::path::Path;

/// Errors of reading and writing the trainer's files; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A file is not of the expected kind or version, or is corrupt.
    #[error("{path}: not a valid ampc file: {reason}")]
    Format {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
}

/// Checks the 8 magic bytes, decodes a postcard file and checks its format version;
/// errors name `origin` (shared by the dataset and model files).
pub fn decode_checked<T: serde::de::DeserializeOwned>(
    bytes: &[u8],
    origin: &str,
    magic: &[u8; 8],
    what: &str,
    version_of: impl Fn(&T) -> u32,
    expected: u32,
) -> Result<T, FileError> {
    let fmt = |reason: String| FileError::Format {
        path: origin.to_string(),
        reason,
    };
    if bytes.len() < 8 || bytes[..8] != magic[..] {
        return Err(fmt(format!(
            "not an ampc {what} file (missing magic bytes)"
        )));
    }
    let v: T = postcard::from_bytes(bytes).map_err(|e| fmt(format!("decode error: {e}")))?;
    if version_of(&v) != expected {
        return Err(fmt(format!(
            "format version {} (this build reads {expected})",
            version_of(&v)
        )));
    }
    Ok(v)
}

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, fsync, rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    let io = |source| FileError::Io {
        path: path.display().to_string(),
        source,
    };
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(io)?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let res = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if res.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    res.map_err(io)
}

/// Lower-case hex of a byte string.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Lower-case hex SHA-256 of a byte string.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    hex(&Sha256::digest(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_atomic_replaces_and_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("ampc_io_{}", std::process::id()));
        let p = dir.join("sub").join("f.bin");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        let names: Vec<_> = std::fs::read_dir(dir.join("sub")).unwrap().collect();
        assert_eq!(names.len(), 1);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn decode_checked_names_the_file_and_the_fault() {
        let magic = *b"AMPCTEST";
        let mut bytes = magic.to_vec();
        bytes.extend(postcard::to_allocvec(&(magic, 3u32)).unwrap()[8..].iter());
        let ok = decode_checked::<([u8; 8], u32)>(&bytes, "t.bin", &magic, "test", |v| v.1, 3);
        assert_eq!(ok.unwrap().1, 3);
        let e = decode_checked::<([u8; 8], u32)>(&bytes, "t.bin", &magic, "test", |v| v.1, 4)
            .unwrap_err()
            .to_string();
        assert!(e.contains("t.bin") && e.contains("format version 3"), "{e}");
        let e = decode_checked::<([u8; 8], u32)>(b"XXXXXXXX", "u.bin", &magic, "test", |v| v.1, 3)
            .unwrap_err()
            .to_string();
        assert!(e.contains("u.bin") && e.contains("missing magic"), "{e}");
    }

    #[test]
    fn hex_is_lower_case_sha256() {
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
