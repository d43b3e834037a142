//! `controller-core`: fixed-size f32 inference of a certified approximate MPC law.
//!
//! This crate is `no_std`, allocation-free and `unsafe`-free. The inference code and the
//! baked weights arrive with the embedded-side work; for now it holds only the shared
//! contract constants.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs, unsafe_code)]

/// Version of the weight/certificate format this core understands.
pub const FORMAT_VERSION: u16 = 1;
