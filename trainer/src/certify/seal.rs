//! The certificate file's own checksum: `certificate.json` carries
//! `"checksum": "sha256:<hex>"`, the SHA-256 of the file's exact bytes (trailing whitespace
//! aside, so `trainer certify --json > c.json`'s final newline does not matter) with that hex
//! replaced by 64 zeros.
//!
//! ```text
//! checksum = SHA-256( trim_end(text) with "sha256:<hex>" → "sha256:000…0" )
//! ```
//!
//! The model, dataset and problem are bound by the hashes inside the certificate
//! (`hash`, `dataset_hash`, `problem_hash`); the checksum binds the certificate's own numbers
//! (ε, domain, band, tiers), so an edited or damaged file is refused by every reader
//! (`export`, the pipeline's export stage, the report) instead of being baked into a
//! controller. The checksum is over the text, not over re-serialised values, so it does not
//! depend on how a JSON library prints or parses floating-point numbers. A file that was
//! reformatted (e.g. by `jq`) does not match: regenerate it.

use serde::Serialize;
use serde_json::Value;

/// The JSON key of the checksum.
pub const KEY: &str = "checksum";
const PREFIX: &str = "sha256:";
const ZEROS: &str = "0000000000000000000000000000000000000000000000000000000000000000";

/// Why a certificate file's checksum does not verify.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SealError {
    /// Not JSON, or not a JSON object.
    #[error("{origin}: not a JSON certificate: {why}")]
    NotJson {
        /// The file.
        origin: String,
        /// The parser's message.
        why: String,
    },
    /// The `checksum` value is not `sha256:` + 64 lowercase hex digits.
    #[error("{origin}: `checksum` is {found:?}, not \"sha256:\" followed by 64 hex digits")]
    Malformed {
        /// The file.
        origin: String,
        /// The value found.
        found: String,
    },
    /// The bytes changed since the file was written.
    #[error(
        "{origin}: checksum mismatch (the file says sha256:{stored}…, its contents hash to \
         sha256:{actual}…): the certificate was edited or damaged after it was written — \
         regenerate it with `trainer certify` or `trainer refine`"
    )]
    Mismatch {
        /// The file.
        origin: String,
        /// First 12 hex digits of the stored checksum.
        stored: String,
        /// First 12 hex digits of the contents' checksum.
        actual: String,
    },
    /// Serialisation failed (a non-finite number in a value that must be JSON).
    #[error("cannot serialise the certificate: {0}")]
    Serialise(String),
}

/// Whether a certificate text carried a checksum.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Seal {
    /// It did, and it matches the contents.
    Verified,
    /// It carries none (a certificate written before checksums existed): nothing verified.
    Absent,
}

fn digest(text: &str) -> String {
    crate::io::sha256_hex(text.trim_end().as_bytes())
}

/// `value` as pretty JSON with its `checksum` key set (any earlier checksum is replaced).
pub fn sealed_json<T: Serialize>(value: &T) -> Result<String, SealError> {
    let mut v = serde_json::to_value(value).map_err(|e| SealError::Serialise(e.to_string()))?;
    let o = v
        .as_object_mut()
        .ok_or_else(|| SealError::Serialise("a certificate is a JSON object".into()))?;
    o.insert(KEY.into(), Value::String(format!("{PREFIX}{ZEROS}")));
    let text = serde_json::to_string_pretty(&v).map_err(|e| SealError::Serialise(e.to_string()))?;
    let placeholder = format!("\"{PREFIX}{ZEROS}\"");
    let sum = digest(&text);
    Ok(text.replacen(&placeholder, &format!("\"{PREFIX}{sum}\""), 1))
}

/// Checks the checksum of a certificate text read from `origin` (named in every error).
pub fn verify(text: &str, origin: &str) -> Result<Seal, SealError> {
    let v: Value = serde_json::from_str(text).map_err(|e| SealError::NotJson {
        origin: origin.into(),
        why: e.to_string(),
    })?;
    let o = v.as_object().ok_or_else(|| SealError::NotJson {
        origin: origin.into(),
        why: "not a JSON object".into(),
    })?;
    let Some(stored) = o.get(KEY) else {
        return Ok(Seal::Absent);
    };
    let malformed = || SealError::Malformed {
        origin: origin.into(),
        found: stored.to_string(),
    };
    let hex = stored
        .as_str()
        .and_then(|s| s.strip_prefix(PREFIX))
        .filter(|h| h.len() == 64 && h.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f')))
        .ok_or_else(malformed)?;
    let quoted = format!("\"{PREFIX}{hex}\"");
    // The value as written: exactly one occurrence (the hex is the hash of the file itself).
    if text.matches(&quoted).count() != 1 {
        return Err(malformed());
    }
    let actual = digest(&text.replacen(&quoted, &format!("\"{PREFIX}{ZEROS}\""), 1));
    if actual != hex {
        return Err(SealError::Mismatch {
            origin: origin.into(),
            stored: hex[..12].into(),
            actual: actual[..12].into(),
        });
    }
    Ok(Seal::Verified)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn sample() -> Value {
        json!({"eps": 0.748_123_456_789_012_3, "domain_lo": [-3.5, -8.0],
               "guarantee": "estimated", "hash": "ab"})
    }

    #[test]
    fn a_sealed_certificate_verifies_and_keeps_its_values() {
        let text = sealed_json(&sample()).unwrap();
        assert_eq!(verify(&text, "c.json"), Ok(Seal::Verified));
        assert_eq!(verify(&format!("{text}\n"), "c.json"), Ok(Seal::Verified));
        let mut back: Value = serde_json::from_str(&text).unwrap();
        assert!(back[KEY].as_str().unwrap().starts_with(PREFIX));
        back.as_object_mut().unwrap().remove(KEY);
        assert_eq!(back, sample());
        // Sealing a sealed value again gives the same text (the old checksum is replaced).
        let again: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(sealed_json(&again).unwrap(), text);
    }

    #[test]
    fn every_single_byte_change_of_a_value_is_refused() {
        let text = sealed_json(&sample()).unwrap();
        // ε edited by one digit, a bound changed, the tier upgraded.
        for (from, to) in [
            ("0.7481234567890123", "0.7481234567890124"),
            ("-8.0", "-9.0"),
            ("\"estimated\"", "\"sound\""),
        ] {
            assert!(text.contains(from), "{from} not in {text}");
            let bad = text.replacen(from, to, 1);
            match verify(&bad, "runs/p/certificate.json") {
                Err(SealError::Mismatch { origin, .. }) => {
                    assert_eq!(origin, "runs/p/certificate.json")
                }
                other => panic!("{from} → {to}: {other:?}"),
            }
        }
        // Every byte flipped: refused (or no longer JSON).
        let bytes = text.as_bytes();
        for i in 0..bytes.len() {
            let mut b = bytes.to_vec();
            b[i] ^= 0x01;
            let Ok(s) = String::from_utf8(b) else {
                continue;
            };
            assert_ne!(verify(&s, "c.json"), Ok(Seal::Verified), "byte {i}");
        }
    }

    #[test]
    fn a_missing_or_malformed_checksum_is_named() {
        let plain = serde_json::to_string_pretty(&sample()).unwrap();
        assert_eq!(verify(&plain, "old.json"), Ok(Seal::Absent));
        let mut v = sample();
        v[KEY] = json!("md5:abc");
        let e = verify(&v.to_string(), "x.json").unwrap_err();
        assert!(matches!(e, SealError::Malformed { .. }), "{e}");
        assert!(e.to_string().starts_with("x.json: `checksum`"), "{e}");
        let e = verify("[1, 2]", "y.json").unwrap_err();
        assert!(
            e.to_string().starts_with("y.json: not a JSON certificate"),
            "{e}"
        );
    }
}
