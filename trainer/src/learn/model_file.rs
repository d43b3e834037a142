//! The model file of a [`TrainedModel`]: its encoding, the checks on reading it, and how it
//! stores the problem file of its labels — an optional trailer after the postcard-encoded
//! model, inside the sealed body,
//!
//! ```text
//! file = magic … postcard(TrainedModel) ‖ [ "AMPCPROB" ‖ postcard(String: problem TOML) ]
//!        ‖ [ "AMPCSEQN" ‖ postcard(Mlp: the sequence net) ] ‖ SHA-256
//! ```
//!
//! The second trailer holds a sequence net (`crate::learn::sequence`); on reading, its u₀
//! rows must be exactly the model's network (else the file is refused), so that what is
//! certified and exported is the sequence net's u₀.
//!
//! The trailer is optional both ways: postcard ignores bytes after a complete value, so a
//! reader that does not look for it reads the model alone, and a file without it (or of a
//! network without a problem, e.g. an ONNX import) reads back with no stored problem. The
//! checksum covers the trailer. The stored text is what
//! `ProblemConfig::to_toml_string` wrote; `trainer eval`/`export`/`refine` take the
//! problem from it when no `--config` is given.

use super::train::{TrainedModel, MODEL_MAGIC, MODEL_VERSION};
use crate::data::dataset::DatasetError;
use crate::io::write_atomic;
use serde::Serialize;
use std::path::Path;

/// Marks the start of the trailer.
pub const PROBLEM_MAGIC: [u8; 8] = *b"AMPCPROB";
/// Marks the start of the sequence net's trailer.
pub const SEQUENCE_MAGIC: [u8; 8] = *b"AMPCSEQN";

/// The sequence net's trailer (if any) and what follows it: the net, and the bytes before
/// it; an error naming `origin` if it does not decode.
fn split_sequence<'a>(
    rest: &'a [u8],
    origin: &str,
) -> Result<(&'a [u8], Option<super::mlp::Mlp>), DatasetError> {
    // The problem trailer's text is length-prefixed, so the marker is searched after it.
    let at = match rest.strip_prefix(&PROBLEM_MAGIC[..]) {
        Some(tail) => match postcard::take_from_bytes::<String>(tail) {
            Ok((_, after)) => rest.len() - after.len(),
            Err(_) => return Ok((rest, None)),
        },
        None => 0,
    };
    let Some(tail) = rest[at..].strip_prefix(&SEQUENCE_MAGIC[..]) else {
        return Ok((rest, None));
    };
    match postcard::take_from_bytes::<super::mlp::Mlp>(tail) {
        Ok((m, [])) => Ok((&rest[..at], Some(m))),
        Ok((_, extra)) => Err(DatasetError::Format {
            path: origin.to_string(),
            reason: format!("{} unexpected bytes after the sequence net", extra.len()),
        }),
        Err(source) => Err(DatasetError::Decode {
            path: origin.to_string(),
            part: "sequence net",
            source,
        }),
    }
}

/// Appends the trailer holding `toml` (if any) to an encoded model body.
pub fn append(body: &mut Vec<u8>, toml: Option<&str>) {
    if let Some(t) = toml {
        body.extend_from_slice(&PROBLEM_MAGIC);
        body.extend(postcard::to_allocvec(t).unwrap_or_default());
    }
}

/// The problem text stored in the bytes that follow an encoded model (`rest`): `None` if
/// there are none; an error naming `origin` if they are not one well-formed trailer.
pub fn read(rest: &[u8], origin: &str) -> Result<Option<String>, DatasetError> {
    let fmt = |reason: String| DatasetError::Format {
        path: origin.to_string(),
        reason,
    };
    if rest.is_empty() {
        return Ok(None);
    }
    let Some(tail) = rest.strip_prefix(&PROBLEM_MAGIC[..]) else {
        return Err(fmt(format!(
            "{} unexpected bytes after the model",
            rest.len()
        )));
    };
    match postcard::take_from_bytes::<String>(tail) {
        Ok((s, [])) => Ok(Some(s)),
        Ok((_, extra)) => Err(fmt(format!(
            "{} unexpected bytes after the stored problem",
            extra.len()
        ))),
        Err(source) => Err(DatasetError::Decode {
            path: origin.to_string(),
            part: "stored problem",
            source,
        }),
    }
}

impl<C: Serialize + serde::de::DeserializeOwned> TrainedModel<C> {
    /// Encodes the model.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut body = postcard::to_allocvec(self).unwrap_or_default();
        append(&mut body, self.problem_toml.as_deref());
        if let Some(seq) = &self.sequence {
            body.extend_from_slice(&SEQUENCE_MAGIC);
            body.extend(postcard::to_allocvec(seq).unwrap_or_default());
        }
        crate::io::seal(body)
    }
    /// Writes the model atomically.
    pub fn save(&self, path: &Path) -> Result<(), DatasetError> {
        Ok(write_atomic(path, &self.to_bytes())?)
    }
    /// Decodes and checks a model; `origin` names it in errors.
    pub fn from_bytes(bytes: &[u8], origin: &str) -> Result<Self, DatasetError> {
        let fmt = |reason: String| DatasetError::Format {
            path: origin.to_string(),
            reason,
        };
        let mut m: TrainedModel<C> = crate::io::decode_checked(
            bytes,
            origin,
            &MODEL_MAGIC,
            "model",
            |m: &TrainedModel<C>| m.version,
            MODEL_VERSION,
        )?;
        let w = m.mlp.widths();
        let shapes_ok = m.mlp.layers.iter().zip(w.windows(2)).all(|(l, p)| {
            l.inp == p[0] && l.out == p[1] && l.w.len() == l.inp * l.out && l.b.len() == l.out
        }) && m.mlp.in_center.len() == w[0]
            && m.mlp.in_half.len() == w[0]
            && m.mlp.out_center.len() == m.mlp.nu()
            && m.mlp.out_half.len() == m.mlp.nu()
            && m.mlp.layers.windows(2).all(|p| p[0].out == p[1].inp);
        if !shapes_ok || m.mlp.layers.is_empty() {
            return Err(fmt("inconsistent layer shapes".into()));
        }
        let body = crate::io::unseal(bytes).unwrap_or_default();
        let rest = postcard::take_from_bytes::<Self>(body).map_or(&[][..], |(_, r)| r);
        let (rest, seq) = split_sequence(rest, origin)?;
        m.problem_toml = read(rest, origin)?;
        if let Some(seq) = &seq {
            let nu = m.mlp.nu();
            if seq.nu() <= nu || seq.nu() % nu != 0 || super::sequence::first_rows(seq, nu) != m.mlp
            {
                return Err(fmt(format!(
                    "the sequence net ({} outputs) does not have the model's net as its first \
                     {nu} rows",
                    seq.nu()
                )));
            }
        }
        m.sequence = seq;
        Ok(m)
    }
    /// SHA-256 (hex) of the network's parameters and scaling: what a certificate is about
    /// (for an imported network: of the file it was imported from, [`Self::source_hash`]).
    pub fn content_hash(&self) -> String {
        use sha2::{Digest, Sha256};
        if let Some(h) = &self.source_hash {
            return h.clone();
        }
        crate::io::hex(&Sha256::digest(
            postcard::to_allocvec(&self.mlp).unwrap_or_default(),
        ))
    }

    /// Reads a model file.
    pub fn load(path: &Path) -> Result<Self, DatasetError> {
        let bytes = std::fs::read(path).map_err(|source| DatasetError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_bytes(&bytes, &path.display().to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_malformed_trailers() {
        let mut body = vec![1u8, 2, 3];
        append(&mut body, None);
        assert_eq!(body, [1, 2, 3]);
        append(&mut body, Some("name = \"x\"\n"));
        assert_eq!(
            read(&body[3..], "m.bin").unwrap().as_deref(),
            Some("name = \"x\"\n")
        );
        assert_eq!(read(&[], "m.bin").unwrap(), None);
        assert!(read(&body[4..], "m.bin").is_err());
        let mut longer = body[3..].to_vec();
        longer.push(0);
        let e = read(&longer, "m.bin").unwrap_err().to_string();
        assert!(
            e.starts_with("m.bin: ") && e.contains("1 unexpected"),
            "{e}"
        );
        let e = read(&body[3..body.len() - 1], "m.bin").unwrap_err();
        // A truncated stored problem keeps the decoder's error as its source.
        assert!(
            matches!(
                e,
                DatasetError::Decode {
                    part: "stored problem",
                    ..
                }
            ),
            "{e}"
        );
        assert!(std::error::Error::source(&e).is_some());
    }
}
