//! Files: atomic writes, checked postcard envelopes and content hashes — the one copy.
//!
//! - `write_atomic(path, bytes)`: a temporary file in the same directory, fsync, rename, so
//!   a reader (or a resumed run) sees either the old file or the whole new one. A device or
//!   FIFO (`--out /dev/null`) is written in place, never replaced; a symlink is followed.
//! - `seal` / `decode_checked`: `magic (8 bytes) ‖ postcard(T) ‖ SHA-256(everything before)`
//!   with a format version inside `T`; a wrong magic, a checksum that does not match (one
//!   flipped byte anywhere), a decode error or another version is a [`FileError::Format`]
//!   naming the file and the fault.
//! - `hex(SHA-256(bytes))`: the content hashes that manifests and certificates record.
//!
//! A leaf module: it imports nothing of the crate, and every stage may use it.

use std::io::Write;
use std::path::Path;

pub(crate) mod run_dir;
pub use run_dir::RunDir;

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
    /// A file's checked body does not decode.
    #[error("{path}: not a valid ampc file: decode error: {source}")]
    Decode {
        /// The file.
        path: String,
        /// The decoder's error.
        source: postcard::Error,
    },
}

/// Length of the checksum that [`seal`] appends.
pub const CHECKSUM_LEN: usize = 32;

/// Appends the SHA-256 of `body` to it: the file's integrity check.
pub fn seal(mut body: Vec<u8>) -> Vec<u8> {
    use sha2::{Digest, Sha256};
    let h = Sha256::digest(&body);
    body.extend_from_slice(&h);
    body
}

/// The body of a [`seal`]ed byte string, or `None` if its checksum does not match.
pub fn unseal(bytes: &[u8]) -> Option<&[u8]> {
    use sha2::{Digest, Sha256};
    let n = bytes.len().checked_sub(CHECKSUM_LEN)?;
    let (body, sum) = bytes.split_at(n);
    (Sha256::digest(body).as_slice() == sum).then_some(body)
}

/// Checks the 8 magic bytes and the checksum of a [`seal`]ed postcard file, decodes it and
/// checks its format version; errors name `origin` and the fault (shared by the dataset,
/// checkpoint and model files).
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
    let Some(body) = unseal(bytes) else {
        // A file of an older format (no checksum) still names its version.
        if let Ok(v) = postcard::from_bytes::<T>(bytes) {
            if version_of(&v) != expected {
                return Err(fmt(format!(
                    "format version {} (this build reads {expected})",
                    version_of(&v)
                )));
            }
        }
        return Err(fmt(format!(
            "checksum mismatch: the {what} file is corrupt or was modified after it was written"
        )));
    };
    let v: T = postcard::from_bytes(body).map_err(|source| FileError::Decode {
        path: origin.to_string(),
        source,
    })?;
    if version_of(&v) != expected {
        return Err(fmt(format!(
            "format version {} (this build reads {expected})",
            version_of(&v)
        )));
    }
    Ok(v)
}

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, fsync, rename
/// (a set of one, see [`write_atomic_all`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    write_atomic_all(&[(path, bytes)])
}

/// Writes several files as one set: every file is first written in full to a temporary file
/// beside it (fsync); only when all are written are they renamed into place, in order. A
/// failure while writing (disk full, a read-only directory) leaves every previous file as it
/// was — never the new dataset beside the old CSV.
///
/// A destination that is not a regular file — `/dev/null`, a FIFO, a terminal — is written
/// in place after the set's regular files (a rename would replace the device node by a regular
/// file); a symbolic link is followed, so the file it names is replaced and the link kept.
pub fn write_atomic_all(files: &[(&Path, &[u8])]) -> Result<(), FileError> {
    let resolved: Vec<(std::path::PathBuf, bool)> = files
        .iter()
        .map(|(p, _)| destination(p))
        .collect::<Result<_, _>>()?;
    let (special, regular): (Vec<_>, Vec<_>) = files
        .iter()
        .zip(&resolved)
        .map(|((shown, bytes), (real, special))| (*shown, real.as_path(), *bytes, *special))
        .partition(|f| f.3);
    let regular: Vec<_> = regular.into_iter().map(|f| (f.0, f.1, f.2)).collect();
    write_regular(&regular)?;
    for (shown, real, bytes, _) in special {
        let res = std::fs::OpenOptions::new()
            .write(true)
            .open(real)
            .and_then(|mut f| f.write_all(bytes));
        res.map_err(|source| FileError::Io {
            path: shown.display().to_string(),
            source,
        })?;
    }
    Ok(())
}

/// Whether `path` names a device, a FIFO or a socket (followed through symbolic links): a
/// destination [`write_atomic`] writes in place, with no room for files beside it.
pub fn is_special(path: &Path) -> bool {
    destination(path).is_ok_and(|(_, special)| special)
}

/// Where `path` is really written, and whether that is a special file (not a regular file, not
/// a directory: a device, a FIFO, a socket) to be written in place. A symbolic link resolves
/// to the file it names; a missing file is a new regular file.
fn destination(path: &Path) -> Result<(std::path::PathBuf, bool), FileError> {
    let io = |source| FileError::Io {
        path: path.display().to_string(),
        source,
    };
    let is_link = std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
    let real = if is_link {
        match std::fs::canonicalize(path) {
            Ok(r) => r,
            // A dangling link: the file it names does not exist yet.
            Err(_) => {
                let target = std::fs::read_link(path).map_err(io)?;
                match path.parent() {
                    Some(d) if target.is_relative() => d.join(target),
                    _ => target,
                }
            }
        }
    } else {
        path.to_path_buf()
    };
    let special = match std::fs::metadata(&real) {
        Ok(m) => !m.is_file() && !m.is_dir(),
        Err(_) => false,
    };
    Ok((real, special))
}

/// The regular files of [`write_atomic_all`]: `(name shown in errors, path, bytes)`.
fn write_regular(files: &[(&Path, &Path, &[u8])]) -> Result<(), FileError> {
    let mut tmps = Vec::with_capacity(files.len());
    let cleanup = |tmps: &[std::path::PathBuf]| {
        for t in tmps {
            let _ = std::fs::remove_file(t);
        }
    };
    for (shown, path, bytes) in files {
        let io = |source| FileError::Io {
            path: shown.display().to_string(),
            source,
        };
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        if let Err(e) = std::fs::create_dir_all(dir) {
            cleanup(&tmps);
            return Err(io(not_a_directory(dir).unwrap_or(e)));
        }
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
        tmps.push(tmp.clone());
        let res = (|| {
            let mut f = std::fs::File::create(&tmp)?;
            f.write_all(bytes)?;
            f.sync_all()
        })();
        if let Err(e) = res {
            cleanup(&tmps);
            return Err(io(e));
        }
    }
    for (k, ((shown, path, _), tmp)) in files.iter().zip(&tmps).enumerate() {
        if let Err(e) = std::fs::rename(tmp, path) {
            cleanup(&tmps[k..]);
            return Err(FileError::Io {
                path: shown.display().to_string(),
                source: e,
            });
        }
    }
    Ok(())
}

/// Why the directory `dir` cannot be made when one of its ancestors (or itself) exists and
/// is not a directory (`--out afile/x.bin` with `afile` a regular file): an error naming
/// that path, instead of "File exists (os error 17)". `None` when no such path exists.
fn not_a_directory(dir: &Path) -> Option<std::io::Error> {
    let bad = dir
        .ancestors()
        .filter(|a| !a.as_os_str().is_empty())
        .find(|a| std::fs::metadata(a).is_ok_and(|m| !m.is_dir()))?;
    Some(std::io::Error::new(
        std::io::ErrorKind::NotADirectory,
        format!(
            "cannot create the directory {}: {} is a file, not a directory",
            dir.display(),
            bad.display()
        ),
    ))
}

/// Checks that `name` is one normal path component — a run's directory or a file's stem
/// under an output directory: not empty, not `.` or `..`, no `/`, `\\` or NUL (so
/// `name = ".."` cannot write a run's files into the current directory). The message says
/// what is wrong, quoting the name.
pub fn check_path_component(name: &str) -> Result<(), String> {
    let why = if name.is_empty() {
        "is empty"
    } else if name == "." || name == ".." {
        "is `.` or `..`, which names a directory above or at the output root"
    } else if name.contains(['/', '\\']) {
        "contains a path separator (`/` or `\\`)"
    } else if name.contains('\0') {
        "contains a NUL character"
    } else {
        return Ok(());
    };
    Err(format!(
        "{} {why}: it must be one normal path component (e.g. `pendulum_2`)",
        quote(name)
    ))
}

/// At most ~80 characters of `s` for an error message, in backquotes: the whole of a short
/// text, else its first 80 characters, `…` and its length (a 10 MB CSV field is not echoed).
pub fn quote(s: &str) -> String {
    const SHOWN: usize = 80;
    let n = s.chars().count();
    if n <= SHOWN {
        return format!("`{s}`");
    }
    let head: String = s.chars().take(SHOWN).collect();
    format!("`{head}…` ({n} characters)")
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
        let bytes = seal(postcard::to_allocvec(&(magic, 3u32)).unwrap());
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
        // Every single flipped bit is caught by the checksum.
        for i in 0..bytes.len() * 8 {
            let mut b = bytes.clone();
            b[i / 8] ^= 1 << (i % 8);
            assert!(
                decode_checked::<([u8; 8], u32)>(&b, "f.bin", &magic, "test", |v| v.1, 3).is_err(),
                "bit {i}"
            );
        }
        let mut b = bytes.clone();
        b[9] ^= 1;
        let e = decode_checked::<([u8; 8], u32)>(&b, "f.bin", &magic, "test", |v| v.1, 3)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("f.bin") && e.contains("checksum mismatch"),
            "{e}"
        );
        // A file of the previous, unsealed format names its version.
        let old = postcard::to_allocvec(&(magic, 2u32)).unwrap();
        let e = decode_checked::<([u8; 8], u32)>(&old, "o.bin", &magic, "test", |v| v.1, 3)
            .unwrap_err()
            .to_string();
        assert!(e.contains("format version 2 (this build reads 3)"), "{e}");
    }

    #[test]
    fn a_set_is_written_whole_or_not_at_all() {
        let dir = std::env::temp_dir().join(format!("ampc_io_set_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (a, b) = (dir.join("d.bin"), dir.join("d.csv"));
        write_atomic_all(&[(&a, b"old bin"), (&b, b"old csv")]).unwrap();
        // The second file cannot be written (its "directory" is a file): nothing changes.
        let bad = dir.join("d.bin").join("x.csv");
        let e = write_atomic_all(&[(&a, b"new bin"), (&bad, b"new csv")]).unwrap_err();
        // The error names the path and why (not only "File exists (os error 17)").
        let e = e.to_string();
        assert!(
            e.contains(&bad.display().to_string())
                && e.contains(&format!("{} is a file, not a directory", a.display())),
            "{e}"
        );
        assert_eq!(std::fs::read(&a).unwrap(), b"old bin");
        assert_eq!(std::fs::read(&b).unwrap(), b"old csv");
        let left: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
        assert_eq!(left.len(), 2, "no temporary file is left behind");
        write_atomic_all(&[(&a, b"new bin"), (&b, b"new csv")]).unwrap();
        assert_eq!(std::fs::read(&b).unwrap(), b"new csv");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_is_written_in_place_and_a_symlink_is_followed() {
        use std::os::unix::fs::FileTypeExt;
        let dir = std::env::temp_dir().join(format!("ampc_io_special_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        // A FIFO (as /dev/null is a device): written in place, not replaced by a file.
        let fifo = dir.join("pipe");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let f2 = fifo.clone();
            let reader = std::thread::spawn(move || std::fs::read(&f2).unwrap());
            write_atomic(&fifo, b"through the pipe").unwrap();
            // (checked before the join: a replaced FIFO would leave the reader waiting)
            let t = std::fs::symlink_metadata(&fifo).unwrap().file_type();
            assert!(t.is_fifo(), "the FIFO was replaced: {t:?}");
            assert_eq!(reader.join().unwrap(), b"through the pipe");
        }
        // A symlink: the file it names gets the bytes, the link stays a link.
        let real = dir.join("real.bin");
        let link = dir.join("link.bin");
        std::fs::write(&real, b"old").unwrap();
        std::os::unix::fs::symlink(&real, &link).unwrap();
        write_atomic(&link, b"new").unwrap();
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read(&real).unwrap(), b"new");
        // A dangling relative link: the file it names is created beside it.
        let dangling = dir.join("dangling.bin");
        std::os::unix::fs::symlink("made.bin", &dangling).unwrap();
        write_atomic(&dangling, b"made").unwrap();
        assert_eq!(std::fs::read(dir.join("made.bin")).unwrap(), b"made");
        assert!(std::fs::symlink_metadata(&dangling)
            .unwrap()
            .file_type()
            .is_symlink());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_name_is_one_normal_path_component() {
        for ok in ["pendulum", "a.b", "run-2", "...", ".hidden"] {
            assert!(check_path_component(ok).is_ok(), "{ok}");
        }
        for bad in ["", ".", "..", "a/b", "/", "a\\b", "a\0b"] {
            assert!(check_path_component(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn quote_keeps_at_most_80_characters() {
        assert_eq!(quote("abc"), "`abc`");
        let long = "é".repeat(10_000);
        let q = quote(&long);
        assert_eq!(q, format!("`{}…` (10000 characters)", "é".repeat(80)));
    }

    #[test]
    fn hex_is_lower_case_sha256() {
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
