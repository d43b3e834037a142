//! The postcard blob for `controller-core` ([`render_postcard`]):
//! `postcard(body) ‖ crc32(body).to_le_bytes()`, the body as `controller_core::blob` reads
//! it (magic, version, dimensions, f32 domain, the clamp band per device tanh, fallback,
//! folded f32 layers, model hash).

use serde::Serialize;

use super::{ExportModel, ExportReport};

/// Magic of the postcard blob.
pub const BLOB_MAGIC: [u8; 4] = *b"AMPC";
/// Blob format version (`controller_core::FORMAT_VERSION`).
pub const BLOB_VERSION: u16 = 1;
/// The blob's body (see `controller_core::blob`), serialised with postcard.
#[derive(Serialize)]
struct BlobBody<'a> {
    magic: [u8; 4],
    version: u16,
    nx: u32,
    nu: u32,
    x_lo: Vec<f32>,
    x_hi: Vec<f32>,
    clamp_lo_libm: Vec<f32>,
    clamp_hi_libm: Vec<f32>,
    clamp_lo_fast: Vec<f32>,
    clamp_hi_fast: Vec<f32>,
    fallback: Vec<f32>,
    layers: Vec<BlobLayer>,
    hash: &'a str,
}

#[derive(Serialize)]
struct BlobLayer {
    n_in: u32,
    n_out: u32,
    w: Vec<f32>,
    b: Vec<f32>,
}

/// CRC-32 (IEEE), as `controller_core::blob::crc32`.
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

/// The postcard blob: `postcard(body) ++ crc32(body).to_le_bytes()`.
pub fn render_postcard(model: &ExportModel, report: &ExportReport) -> Vec<u8> {
    let folded = model.folded();
    let (x_lo, x_hi) = model.domain_f32();
    let (lo_l, hi_l) = model.clamp_band(model.eps + report.f32_allowance[0]);
    let (lo_f, hi_f) = model.clamp_band(model.eps + report.f32_allowance[1]);
    // The fallback is the same for both bands (it lies in U_d ⊆ both bands).
    let fallback = model.fallback_f32(&lo_l, &hi_l);
    let body = BlobBody {
        magic: BLOB_MAGIC,
        version: BLOB_VERSION,
        nx: model.nx() as u32,
        nu: model.nu() as u32,
        x_lo,
        x_hi,
        clamp_lo_libm: lo_l,
        clamp_hi_libm: hi_l,
        clamp_lo_fast: lo_f,
        clamp_hi_fast: hi_f,
        fallback,
        layers: folded
            .f32_layers
            .iter()
            .map(|(i, o, w, b)| BlobLayer {
                n_in: *i as u32,
                n_out: *o as u32,
                w: w.clone(),
                b: b.clone(),
            })
            .collect(),
        hash: &model.hash,
    };
    let mut bytes = postcard::to_stdvec(&body).expect("postcard serialises plain data");
    let c = crc32(&bytes);
    bytes.extend_from_slice(&c.to_le_bytes());
    bytes
}
