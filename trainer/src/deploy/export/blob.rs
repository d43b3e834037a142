//! The postcard blob for `controller-core` ([`render_postcard`]):
//! `postcard(body) ‖ crc32(body).to_le_bytes()`, the body as `controller_core::blob` reads
//! it (magic, version, dimensions, f32 domain, the clamp band per device tanh, fallback,
//! folded f32 layers, model hash). The magic, the format version and the CRC are the
//! decoder's own (`controller_core::blob::{MAGIC, FORMAT_VERSION, crc32}`).

use controller_core::blob::{crc32, FORMAT_VERSION, MAGIC};
use serde::Serialize;

use super::{ExportModel, ExportReport};

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

/// The postcard blob: `postcard(body) ++ crc32(body).to_le_bytes()`.
pub fn render_postcard(model: &ExportModel, report: &ExportReport) -> Vec<u8> {
    let folded = model.folded();
    let (x_lo, x_hi) = model.domain_f32();
    let (lo_l, hi_l) = model.clamp_band(model.eps + report.f32_allowance[0]);
    let (lo_f, hi_f) = model.clamp_band(model.eps + report.f32_allowance[1]);
    // The fallback is the same for both bands (it lies in U_d ⊆ both bands).
    let fallback = model.fallback_f32(&lo_l, &hi_l);
    let body = BlobBody {
        magic: MAGIC,
        version: FORMAT_VERSION,
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
