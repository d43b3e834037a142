//! `[domain]` and `[sampling]`: the box X that is sampled and certified, and how its
//! states are chosen (grid, random, Halton).

use serde::{Deserialize, Serialize};

/// The state domain X (`[domain]`): the box that is sampled and certified.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Domain {
    /// Lower corner (finite).
    pub lo: Vec<f64>,
    /// Upper corner (finite).
    pub hi: Vec<f64>,
}

/// How dataset states are chosen in X.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SamplerKind {
    /// Full tensor grid with per-axis counts, endpoints included.
    Grid,
    /// Uniform random states (seeded).
    Random,
    /// Halton low-discrepancy sequence (scrambled by the seed's offset).
    Halton,
    /// Points chosen by adaptive refinement (`trainer refine`); not a sampling plan, so
    /// rejected in `[sampling]`.
    Adaptive,
    /// Points (and labels) imported from another solver's CSV (`trainer import`); not a
    /// sampling plan, so rejected in `[sampling]`.
    Imported,
}

/// Sampler settings (`[sampling]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SamplingSettings {
    /// Sampler (default grid).
    pub sampler: SamplerKind,
    /// Grid points per axis (grid only; default: the paper's 35 × 10).
    pub counts: Vec<usize>,
    /// Number of states (random / halton; default 350).
    pub n: usize,
    /// Seed (default 0).
    pub seed: u64,
}

impl Default for SamplingSettings {
    fn default() -> Self {
        SamplingSettings {
            sampler: SamplerKind::Grid,
            counts: vec![35, 10],
            n: 350,
            seed: 0,
        }
    }
}
