//! `blob`: the weights as a postcard blob, decoded into fixed-size arrays with validation.
//!
//! Wire format (version [`FORMAT_VERSION`]): `body ++ crc32(body)` where the CRC-32
//! (IEEE 802.3, reflected, init/xorout `0xFFFF_FFFF`) is 4 bytes little-endian and
//! `body` is the postcard encoding of
//! ```text
//! magic: [u8; 4] = b"AMPC", version: u16, nx: u32, nu: u32,
//! x_lo: Vec<f32>, x_hi: Vec<f32>, clamp_lo_libm: Vec<f32>, clamp_hi_libm: Vec<f32>,
//! clamp_lo_fast: Vec<f32>, clamp_hi_fast: Vec<f32>, fallback: Vec<f32>,
//! layers: Vec<{ n_in: u32, n_out: u32, w: Vec<f32> (row-major, out × in), b: Vec<f32> }>,
//! hash: String
//! ```
//! (postcard: integers as varints, f32 as 4 bytes LE, sequences and strings prefixed
//! with their length as a varint). The trainer writes it with `serde` + `postcard`; this
//! decoder reads it with postcard's primitive decoders into the compile-time shapes, and
//! rejects anything else with a [`DecodeError`] — never a panic (proptest fuzzing in
//! this module; `#[no_panic]` with the `no-panic` feature).

use crate::controller::{Controller, InvalidController};
use crate::layer::Dense;
use crate::mlp::{Hidden, Network};

/// Format version of the blob this decoder reads.
pub const FORMAT_VERSION: u16 = crate::FORMAT_VERSION;
/// First four bytes of every blob.
pub const MAGIC: [u8; 4] = *b"AMPC";

/// Why a blob was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecodeError {
    /// Shorter than the checksum, or ended in the middle of a field.
    Truncated,
    /// The CRC-32 does not match the body.
    Checksum,
    /// Not an `AMPC` blob.
    BadMagic,
    /// A format version this decoder does not know.
    UnsupportedVersion(u16),
    /// Dimensions (nx, nu, layer count or sizes, vector lengths) differ from this build's.
    Dimensions,
    /// A field could not be decoded (bad varint, invalid UTF-8, bytes after the hash).
    Malformed,
    /// The decoded parameters are unusable (NaN weight, empty box, fallback outside band).
    Invalid(InvalidController),
    /// The blob holds another model than the certificate it is to run under (their content
    /// hashes differ): running it would not be covered by that certificate.
    CertificateMismatch,
}

/// CRC-32 (IEEE), bitwise: small and table-free.
pub fn crc32(data: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &byte in data {
        crc ^= u32::from(byte);
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

/// A cursor over the body.
pub struct Reader<'a> {
    buf: &'a [u8],
}

impl<'a> Reader<'a> {
    fn take<T: serde::Deserialize<'a>>(&mut self) -> Result<T, DecodeError> {
        match postcard::take_from_bytes::<T>(self.buf) {
            Ok((v, rest)) => {
                self.buf = rest;
                Ok(v)
            }
            Err(postcard::Error::DeserializeUnexpectedEnd) => Err(DecodeError::Truncated),
            Err(_) => Err(DecodeError::Malformed),
        }
    }

    fn dim(&mut self, expected: usize) -> Result<(), DecodeError> {
        let n: u32 = self.take()?;
        if usize::try_from(n).ok() == Some(expected) {
            Ok(())
        } else {
            Err(DecodeError::Dimensions)
        }
    }

    /// Reads a `Vec<f32>` of exactly `out.len()` finite values.
    fn floats(&mut self, out: &mut [f32]) -> Result<(), DecodeError> {
        self.dim(out.len())?;
        for v in out.iter_mut() {
            *v = self.take()?;
            if !v.is_finite() {
                return Err(DecodeError::Invalid(InvalidController::NonFinite));
            }
        }
        Ok(())
    }
}

/// A network that can be read from a blob into its compile-time shape.
pub trait Decode<const I: usize>: Network<I> + Sized {
    /// Number of layers.
    const LAYERS: usize;
    /// Reads the layers (without the leading layer count).
    fn decode(r: &mut Reader<'_>) -> Result<Self, DecodeError>;
}

impl<const I: usize, const O: usize> Decode<I> for Dense<I, O> {
    const LAYERS: usize = 1;
    fn decode(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        r.dim(I)?;
        r.dim(O)?;
        let mut layer = Dense::new([[0.0; I]; O], [0.0; O]);
        r.floats(layer.w.as_flattened_mut())?;
        r.floats(&mut layer.b)?;
        Ok(layer)
    }
}

impl<const I: usize, const H: usize, N: Decode<H>> Decode<I> for Hidden<I, H, N> {
    const LAYERS: usize = 1 + N::LAYERS;
    fn decode(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let layer = Dense::<I, H>::decode(r)?;
        let next = N::decode(r)?;
        Ok(Hidden::new(layer, next))
    }
}

/// A decoded blob: the controller for this build's tanh, and the model's content hash.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decoded<'a, const NX: usize, const NU: usize, N> {
    /// The controller, validated.
    pub controller: Controller<NX, NU, N>,
    /// Content hash of the trained model.
    pub hash: &'a str,
}

/// Decodes and validates a blob for a network of type `N` (see the module doc). The
/// controller has no excluded boxes (the blob does not hold them): load it with
/// [`decode_for`] to run it under its certificate, boxes included.
///
/// ```
/// use controller_core::{blob, demo::weights};
/// let d = blob::decode::<2, 1, weights::Net>(controller_core::demo::WEIGHTS_BLOB).unwrap();
/// assert_eq!(d.controller, controller_core::demo::CONTROLLER);
/// assert_eq!(blob::decode::<2, 1, weights::Net>(&[0; 3]), Err(blob::DecodeError::Truncated));
/// ```
#[cfg_attr(feature = "no-panic", no_panic::no_panic)]
pub fn decode<const NX: usize, const NU: usize, N>(
    blob: &[u8],
) -> Result<Decoded<'_, NX, NU, N>, DecodeError>
where
    N: Decode<NX> + Network<NX, Output = [f32; NU]>,
{
    let Some((body, crc)) = blob.split_last_chunk::<4>() else {
        return Err(DecodeError::Truncated);
    };
    if crc32(body) != u32::from_le_bytes(*crc) {
        return Err(DecodeError::Checksum);
    }
    let mut r = Reader { buf: body };
    if r.take::<[u8; 4]>()? != MAGIC {
        return Err(DecodeError::BadMagic);
    }
    let version: u16 = r.take()?;
    if version != FORMAT_VERSION {
        return Err(DecodeError::UnsupportedVersion(version));
    }
    r.dim(NX)?;
    r.dim(NU)?;
    let mut x_lo = [0.0; NX];
    let mut x_hi = [0.0; NX];
    r.floats(&mut x_lo)?;
    r.floats(&mut x_hi)?;
    let mut band = [[0.0; NU]; 4];
    for b in band.iter_mut() {
        r.floats(b)?;
    }
    let mut fallback = [0.0; NU];
    r.floats(&mut fallback)?;
    r.dim(N::LAYERS)?;
    let net = N::decode(&mut r)?;
    let hash: &str = r.take()?;
    if !r.buf.is_empty() {
        return Err(DecodeError::Malformed);
    }
    let [lo_libm, hi_libm, lo_fast, hi_fast] = band;
    let (clamp_lo, clamp_hi) = if cfg!(feature = "fast-tanh") {
        (lo_fast, hi_fast)
    } else {
        (lo_libm, hi_libm)
    };
    let controller = Controller::new(net, x_lo, x_hi, clamp_lo, clamp_hi, fallback);
    controller.validate().map_err(DecodeError::Invalid)?;
    Ok(Decoded { controller, hash })
}

/// [`decode`], then checks that the blob holds the model `cert` is about (equal content
/// hashes): a controller is only loaded under the certificate that covers it, and takes
/// that certificate's excluded boxes ([`crate::Certificate::excluded`]; the blob itself does
/// not carry them).
///
/// ```
/// use controller_core::{blob, demo::{weights, CERTIFICATE}};
/// let d = blob::decode_for::<2, 1, weights::Net>(controller_core::demo::WEIGHTS_BLOB, &CERTIFICATE);
/// assert!(d.is_ok());
/// let mut other = CERTIFICATE;
/// other.hash = "another model";
/// assert_eq!(
///     blob::decode_for::<2, 1, weights::Net>(controller_core::demo::WEIGHTS_BLOB, &other).err(),
///     Some(blob::DecodeError::CertificateMismatch)
/// );
/// ```
#[cfg_attr(feature = "no-panic", no_panic::no_panic)]
pub fn decode_for<'a, const NX: usize, const NU: usize, N>(
    blob: &'a [u8],
    cert: &crate::certificate::Certificate<NX, NU>,
) -> Result<Decoded<'a, NX, NU, N>, DecodeError>
where
    N: Decode<NX> + Network<NX, Output = [f32; NU]>,
{
    let mut d = decode::<NX, NU, N>(blob)?;
    if d.hash != cert.hash {
        return Err(DecodeError::CertificateMismatch);
    }
    d.controller = d.controller.with_excluded(cert.excluded);
    d.controller.validate().map_err(DecodeError::Invalid)?;
    Ok(d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demo::weights::Net;
    use proptest::prelude::*;

    fn dec(b: &[u8]) -> Result<Decoded<'_, 2, 1, Net>, DecodeError> {
        decode::<2, 1, Net>(b)
    }

    fn with_crc(mut body: Vec<u8>) -> Vec<u8> {
        let c = crc32(&body);
        body.extend_from_slice(&c.to_le_bytes());
        body
    }

    #[test]
    fn crc32_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn committed_blob_equals_compiled_weights_bit_for_bit() {
        let d = dec(crate::demo::WEIGHTS_BLOB).unwrap();
        assert_eq!(d.hash, crate::demo::CERTIFICATE.hash);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        d.controller.net.for_each_layer(&mut |_, _, w, bias| {
            a.extend(w.iter().chain(bias).map(|v| v.to_bits()))
        });
        crate::demo::CONTROLLER
            .net
            .for_each_layer(&mut |_, _, w, bias| {
                b.extend(w.iter().chain(bias).map(|v| v.to_bits()))
            });
        assert_eq!(a, b);
        assert_eq!(d.controller, crate::demo::CONTROLLER);
    }

    #[test]
    fn each_error_is_reported() {
        let good = crate::demo::WEIGHTS_BLOB;
        let body = &good[..good.len() - 4];
        assert_eq!(dec(&good[..3]).unwrap_err(), DecodeError::Truncated);
        let mut b = good.to_vec();
        b[10] ^= 1;
        assert_eq!(dec(&b).unwrap_err(), DecodeError::Checksum);
        let mut m = body.to_vec();
        m[0] = b'X';
        assert_eq!(dec(&with_crc(m)).unwrap_err(), DecodeError::BadMagic);
        let mut m = body.to_vec();
        m[4] = 9;
        assert_eq!(
            dec(&with_crc(m)).unwrap_err(),
            DecodeError::UnsupportedVersion(9)
        );
        let mut m = body.to_vec();
        m[5] = 3; // nx
        assert_eq!(dec(&with_crc(m)).unwrap_err(), DecodeError::Dimensions);
        assert_eq!(
            dec(&with_crc(body[..40].to_vec())).unwrap_err(),
            DecodeError::Truncated
        );
        let mut m = body.to_vec();
        m.push(0);
        assert_eq!(dec(&with_crc(m)).unwrap_err(), DecodeError::Malformed);
        // x_lo[0] = NaN: magic(4) version(1) nx(1) nu(1) len(1) → first float at 8.
        let mut m = body.to_vec();
        m[8..12].copy_from_slice(&f32::NAN.to_le_bytes());
        assert_eq!(
            dec(&with_crc(m)).unwrap_err(),
            DecodeError::Invalid(InvalidController::NonFinite)
        );
        // x_lo[0] = 1e30 > x_hi[0]
        let mut m = body.to_vec();
        m[8..12].copy_from_slice(&1e30f32.to_le_bytes());
        assert_eq!(
            dec(&with_crc(m)).unwrap_err(),
            DecodeError::Invalid(InvalidController::EmptyBox)
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig {
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x616d_7063),
        ..ProptestConfig::with_cases(20_000)
    })]

        #[test]
        fn random_bytes_never_panic(b in proptest::collection::vec(any::<u8>(), 0..800)) {
            let _ = dec(&b);
            let _ = dec(&with_crc(b));
        }

        #[test]
        fn mutated_blobs_never_panic_and_valid_ones_evaluate_safely(
            edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 1..6),
            cut in any::<usize>(),
            fix_crc in any::<bool>(),
            x in any::<[u32; 2]>(),
        ) {
            let good = crate::demo::WEIGHTS_BLOB;
            let mut body = good[..good.len() - 4].to_vec();
            for (i, v) in edits {
                let n = body.len();
                body[i % n] = v;
            }
            if cut % 4 == 0 {
                body.truncate(cut % (body.len() + 1));
            }
            let blob = if fix_crc { with_crc(body) } else { body };
            if let Ok(d) = dec(&blob) {
                let o = d.controller.evaluate(&x.map(f32::from_bits));
                prop_assert!(o.u[0].is_finite());
                prop_assert!(d.controller.clamp_lo[0] <= o.u[0] && o.u[0] <= d.controller.clamp_hi[0]);
            }
        }
    }
}
