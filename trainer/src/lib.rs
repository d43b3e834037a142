//! `trainer`: from a control problem to a certified neural-network controller.
#![deny(missing_docs)]
// Numerical kernels index several arrays with one loop variable; explicit indices read
// closer to the equations than zipped iterators.
#![allow(clippy::needless_range_loop)]

pub mod io;
pub mod rng;

pub mod problem;

pub mod mpc;

pub mod data;

pub mod learn;

pub mod certify;

pub mod robust;

pub mod deploy;

pub mod study;

pub mod pipeline;
