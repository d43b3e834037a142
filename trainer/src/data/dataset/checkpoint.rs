//! The labelling checkpoint `<out>.partial`: an append-only log, so that checkpointing costs
//! O(new work) per batch instead of rewriting everything labelled so far.
//!
//! ```text
//! file    = frame(opening) frame(batch)*
//! frame   = len: u64 LE ‖ seal(postcard(payload))        (seal: payload ‖ SHA-256)
//! opening = (CHECKPOINT_MAGIC, CHECKPOINT_VERSION, Header)
//! batch   = Vec<Record> ‖ Vec<u64> ‖ Vec<Vec<f64>>        (the records of one batch of chunks,
//!                                                          then the indices among them where the
//!                                                          starts disagree, absent in older files
//!                                                          and when empty without sequences; then
//!                                                          the records' sequences when kept)
//! ```
//! The first frame and the first batch are written together atomically (so the file exists
//! only with work in it); every later batch is appended and synced. A reader keeps the frames
//! up to the first incomplete or damaged one (a run killed mid-append) and drops the rest: a
//! damaged frame costs its batch, never a wrong label.

use super::{DatasetError, Header, Record};
use crate::io::{seal, unseal, write_atomic};
use std::io::Write;
use std::path::Path;

/// Magic bytes of a checkpoint's opening frame.
pub const CHECKPOINT_MAGIC: [u8; 8] = *b"AMPCCKPT";
/// Checkpoint format version.
pub const CHECKPOINT_VERSION: u32 = 1;

fn frame(payload: Vec<u8>) -> Vec<u8> {
    let body = seal(payload);
    let mut out = (body.len() as u64).to_le_bytes().to_vec();
    out.extend_from_slice(&body);
    out
}

/// The bytes of a checkpoint holding `records` (the opening frame and one batch).
pub fn encode(header: &Header, records: &[Record]) -> Vec<u8> {
    let mut out = frame(
        postcard::to_allocvec(&(CHECKPOINT_MAGIC, CHECKPOINT_VERSION, header)).unwrap_or_default(),
    );
    out.extend(frame(postcard::to_allocvec(records).unwrap_or_default()));
    out
}

/// Writes a new checkpoint holding `records` (atomically).
pub fn create(path: &Path, header: &Header, records: &[Record]) -> Result<(), DatasetError> {
    create_with(path, header, records, &[])
}

/// [`create`] with the indices where the starts disagree.
pub fn create_with(
    path: &Path,
    header: &Header,
    records: &[Record],
    disagree: &[u64],
) -> Result<(), DatasetError> {
    let mut out = frame(
        postcard::to_allocvec(&(CHECKPOINT_MAGIC, CHECKPOINT_VERSION, header)).unwrap_or_default(),
    );
    out.extend(frame(batch(records, disagree)));
    Ok(write_atomic(path, &out)?)
}

/// A batch frame's payload: the records, then the disagreeing indices when there are any
/// or sequences follow, then the records' sequences when any is kept (so a batch without
/// either is byte for byte the older format).
fn batch(records: &[Record], disagree: &[u64]) -> Vec<u8> {
    let mut p = postcard::to_allocvec(records).unwrap_or_default();
    let seqs = records.iter().any(|r| !r.seq.is_empty());
    if !disagree.is_empty() || seqs {
        p.extend(postcard::to_allocvec(disagree).unwrap_or_default());
    }
    if seqs {
        let s: Vec<&Vec<f64>> = records.iter().map(|r| &r.seq).collect();
        p.extend(postcard::to_allocvec(&s).unwrap_or_default());
    }
    p
}

/// The rest of a batch frame after its records: the disagreeing indices and the sequences
/// (both possibly absent); `None` if it does not decode.
fn batch_tail(rest: &[u8], records: &mut [Record]) -> Option<Vec<u64>> {
    if rest.is_empty() {
        return Some(Vec::new());
    }
    let (d, rest) = postcard::take_from_bytes::<Vec<u64>>(rest).ok()?;
    if !rest.is_empty() {
        let seqs: Vec<Vec<f64>> = postcard::from_bytes(rest).ok()?;
        if seqs.len() != records.len() {
            return None;
        }
        for (r, s) in records.iter_mut().zip(seqs) {
            r.seq = s;
        }
    }
    Some(d)
}

/// Appends one batch of records to the checkpoint and syncs it.
pub fn append(path: &Path, records: &[Record]) -> Result<(), DatasetError> {
    append_with(path, records, &[])
}

/// [`append`] with the indices where the starts disagree.
pub fn append_with(path: &Path, records: &[Record], disagree: &[u64]) -> Result<(), DatasetError> {
    let io = |source| DatasetError::Io {
        path: path.display().to_string(),
        source,
    };
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(path)
        .map_err(io)?;
    f.write_all(&frame(batch(records, disagree))).map_err(io)?;
    f.sync_data().map_err(io)
}

/// The header and records of a checkpoint, keeping the frames before the first incomplete or
/// damaged one; `None` if the opening frame itself is unreadable (not a checkpoint of this
/// format).
pub fn read(bytes: &[u8]) -> Option<(Header, Vec<Record>)> {
    read_with(bytes).map(|(h, r, _)| (h, r))
}

/// [`read`] with the indices where the starts disagree.
pub fn read_with(bytes: &[u8]) -> Option<(Header, Vec<Record>, Vec<u64>)> {
    let mut frames = Frames { rest: bytes };
    let (magic, version, header): ([u8; 8], u32, Header) =
        postcard::from_bytes(frames.next()?).ok()?;
    if magic != CHECKPOINT_MAGIC || version != CHECKPOINT_VERSION {
        return None;
    }
    let (mut records, mut disagree) = (Vec::new(), Vec::new());
    for f in frames {
        match postcard::take_from_bytes::<Vec<Record>>(f) {
            Ok((mut batch, rest)) => {
                let Some(d) = batch_tail(rest, &mut batch) else {
                    break;
                };
                records.extend(batch);
                disagree.extend(d);
            }
            Err(_) => break,
        }
    }
    Some((header, records, disagree))
}

/// Reads the checkpoint file at `path` (see [`read`]).
pub fn load(path: &Path) -> Result<Option<(Header, Vec<Record>)>, DatasetError> {
    let bytes = std::fs::read(path).map_err(|source| DatasetError::Io {
        path: path.display().to_string(),
        source,
    })?;
    Ok(read(&bytes))
}

/// The verified payloads of the frames, in order, up to the first bad one.
struct Frames<'a> {
    rest: &'a [u8],
}

impl<'a> Iterator for Frames<'a> {
    type Item = &'a [u8];
    fn next(&mut self) -> Option<&'a [u8]> {
        let (len, rest) = self.rest.split_first_chunk::<8>()?;
        let len = usize::try_from(u64::from_le_bytes(*len)).ok()?;
        if rest.len() < len {
            self.rest = &[];
            return None;
        }
        let (body, rest) = rest.split_at(len);
        let Some(payload) = unseal(body) else {
            self.rest = &[];
            return None;
        };
        self.rest = rest;
        Some(payload)
    }
}
