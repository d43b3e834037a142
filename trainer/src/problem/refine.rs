//! `[refine]`: adaptive refinement with local certificates — target ε, budget of OCP
//! solves, initial grid, rounds, and the retraining settings of each round.

use super::{invalid, ConfigError, Schedule, TrainSettings};
use serde::{Deserialize, Serialize};

/// The default of [`RefineSettings::target_eps`] as a fraction of the input range in the
/// certificate's norm, ‖S_u⁻¹(u_hi − u_lo)‖₂ ([`default_target_eps`]): 2.5 %. Unscaled
/// (`u_scale = 1`) on the pendulum's |u| ≤ 15 N·m this is the paper's 0.75 N·m; with the
/// default scales (half-widths of U, scaled range 2√nu) it is 0.05·√nu, i.e. 2.5 % of each
/// input's range.
pub const DEFAULT_TARGET_FRACTION: f64 = 0.025;

/// The default target ε of a problem whose `[refine]` does not give `target_eps`:
/// [`DEFAULT_TARGET_FRACTION`] × ‖S_u⁻¹(u_hi − u_lo)‖₂ with S_u = `[ocp] u_scale` (default
/// the half-widths of U), the range of the inputs in the norm the cells are bounded in. A
/// fixed number (the former 0.75) means 37.5 % of the range in the default scaled norm —
/// weak — and 2.5 % only where S_u = 1 and |u| ≤ 15. Falls back to 0.75 when the range is
/// not finite and positive.
pub fn default_target_eps(ocp: &super::OcpSettings) -> f64 {
    let s = ocp.u_scale_or_default();
    let range = ocp
        .u_lo
        .iter()
        .zip(&ocp.u_hi)
        .zip(&s)
        .map(|((l, h), s)| ((h - l) / s).powi(2))
        .sum::<f64>()
        .sqrt();
    if range.is_finite() && range > 0.0 {
        DEFAULT_TARGET_FRACTION * range
    } else {
        0.75
    }
}

/// The default of [`RefineSettings::min_cell`]: 1/64 of X per axis.
pub const DEFAULT_MIN_CELL: f64 = 1.0 / 64.0;

fn is_default_min_cell(v: &f64) -> bool {
    *v == DEFAULT_MIN_CELL
}

/// Adaptive refinement settings (`[refine]`, used by `trainer refine`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RefineSettings {
    /// Target certified ε (`--target-eps` overrides), in the certificate's norm
    /// ‖S_u⁻¹(κ − κ_NN)‖₂ (`[ocp] u_scale`; unscaled where all scales are 1). Default: 2.5 %
    /// of the input range in that norm ([`default_target_eps`], set when a problem file is
    /// read without this key); [`RefineSettings::default`] alone holds 0.75 (the pendulum's).
    pub target_eps: f64,
    /// Budget of OCP solves (default 50 000; `--budget` overrides).
    pub budget: usize,
    /// Points per axis of the initial grid (default: 9 per axis for up to 4 states, else
    /// the largest count per axis whose grid has at most 50 000 points, at least 2).
    pub initial: Vec<usize>,
    /// Largest number of refinement rounds (default 80).
    pub max_rounds: usize,
    /// Wall-clock budget in seconds (default: none). Checked after each round and before
    /// every solve of a round after the first: once spent, the run stops with its best
    /// certificate (resumable). A round cut while its new corners are solved returns the
    /// last complete round (stop reason `max_seconds_in_round`), its checkpoint keeps the
    /// solves done. The first round of a run always completes. The result then depends on
    /// the machine's speed and load, not only on the settings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_seconds: Option<f64>,
    /// Adam epochs of each warm-started retraining (default 60).
    pub round_epochs: usize,
    /// Learning rate of the warm-started retrainings (default 1e-3, cosine decay).
    pub round_learning_rate: f64,
    /// Retrain only when a failing cell's corner error exceeds this fraction of the target
    /// (default 0.6); otherwise a round only splits cells.
    pub retrain_at: f64,
    /// Safety factor on the estimated MPC parts of the local certificate (default 2).
    pub safety: f64,
    /// Regional floor c of the local certificate (default 0.5; 0 = off): a cell's estimated
    /// range of ∂_kκ has half-width at least c × the spread of ∂_kκ over its corners and the
    /// labelled points one cell width outside them, and its curvature estimate is at least
    /// c × the difference quotients of ∂_kκ towards those points
    /// (`certify::local::Regional`).
    pub floor: f64,
    /// Use the second-order form on a cell only where its centre, solved, has the corners'
    /// active set and agrees with the curvature estimate (default true; the centre solves
    /// count against the budget and join the data).
    pub centre_check: bool,
    /// The per-cell check of `trainer refine --check` (`[refine.check]`).
    pub check: CheckSettings,
    /// Points whose error exceeds this fraction of the target are repeated `emphasis`
    /// times in the training set (default 0.5).
    pub emphasis_at: f64,
    /// Repetitions of such points (default 4; 1 = no emphasis).
    pub emphasis: usize,
    /// Cells narrower than this fraction of the domain on every axis are not split
    /// (default 1e-5).
    pub min_width: f64,
    /// Smallest cell around a state the MPC leaves unlabelled, as a fraction of X per axis
    /// (default 1/64 = 0.015625): a cell with an unlabelled corner is split (after the
    /// others, with what budget remains) until it is no wider than this on every axis, then
    /// excluded from the certified domain — listed in the certificate with its box and
    /// unlabelled states, flagged by the exported controller — so that ε is finite over
    /// the rest. Not serialised at its default (hashes of existing problems unchanged).
    #[serde(skip_serializing_if = "is_default_min_cell")]
    pub min_cell: f64,
    /// Restrict the certified domain to the MPC's feasible set (default false): a leaf cell
    /// whose corners are all hard-infeasible (the OCP's soft fallback needed slack, or no
    /// label for infeasibility) is excluded — not bounded, not split, not trained on — and
    /// listed in the certificate (`local.excluded`). Whether a whole cell is outside
    /// the feasible set is an estimate from its corners; `refine --check` counts the fresh
    /// states that are feasible yet fall in an excluded cell. A robust design with an
    /// enforced terminal region turns it on (`robust.terminal_constraint`).
    pub exclude_infeasible: bool,
    /// Whether `trainer run` refines after Theorem 1 (default `"auto"`: when both nets'
    /// Theorem-1 ε are vacuous and nx ≤ 3; `"on"`: always; `"off"`: never). Not serialised
    /// at its default. `trainer refine` ignores it.
    #[serde(skip_serializing_if = "RefineSwitch::is_auto")]
    pub enabled: RefineSwitch,
    /// The network and its first training (defaults: 2-32-32-1 tanh, 600 epochs, batch 64,
    /// learning rate 3e-3 with cosine decay, λ = (1, 0.1, 0), saturation-aware loss). A
    /// `[refine.training]` table changes only the keys it names: the others keep these
    /// refine defaults (not those of `[training]`).
    #[serde(deserialize_with = "over_refine_defaults")]
    pub training: TrainSettings,
}

/// `[refine] enabled`: when `trainer run` refines (see [`RefineSettings::enabled`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RefineSwitch {
    /// When Theorem 1 is vacuous for both nets and nx ≤ 3.
    #[default]
    Auto,
    /// Always.
    On,
    /// Never.
    Off,
}

impl RefineSwitch {
    fn is_auto(&self) -> bool {
        *self == RefineSwitch::Auto
    }
}

/// `[refine.training]` read over the refine defaults: the keys given replace those of
/// [`RefineSettings::default`]'s training settings, the rest keep them. (A plain
/// `#[serde(default)]` would fill a missing key from [`TrainSettings::default`], the
/// `[training]` defaults: `[refine.training] seed = 7` alone then meant a 2-10-10-1 net
/// without the saturation-aware loss.) Unknown keys and wrong types are still errors.
fn over_refine_defaults<'de, D: serde::Deserializer<'de>>(d: D) -> Result<TrainSettings, D::Error> {
    use serde::de::Error;
    let given = toml::Table::deserialize(d)?;
    let base =
        toml::Table::try_from(RefineSettings::default().training).map_err(D::Error::custom)?;
    let over = |keys: &mut dyn Iterator<Item = (&String, &toml::Value)>| {
        let mut t = base.clone();
        t.extend(keys.map(|(k, v)| (k.clone(), v.clone())));
        toml::Value::Table(t).try_into::<TrainSettings>()
    };
    over(&mut given.iter()).map_err(|e| {
        // Name the key at fault: the first one that fails on its own.
        let key = given
            .iter()
            .find(|kv| over(&mut std::iter::once(*kv)).is_err())
            .map(|(k, _)| k.as_str());
        match key {
            Some(k) => D::Error::custom(format!("refine.training.{k}: {}", e.message())),
            None => D::Error::custom(format!("refine.training: {}", e.message())),
        }
    })
}

impl Default for RefineSettings {
    fn default() -> Self {
        RefineSettings {
            target_eps: 0.75,
            budget: 50_000,
            initial: Vec::new(),
            max_rounds: 80,
            max_seconds: None,
            round_epochs: 60,
            round_learning_rate: 1e-3,
            retrain_at: 0.6,
            safety: 2.0,
            floor: 0.5,
            centre_check: true,
            check: CheckSettings::default(),
            emphasis_at: 0.5,
            emphasis: 4,
            min_width: 1e-5,
            min_cell: DEFAULT_MIN_CELL,
            exclude_infeasible: false,
            enabled: RefineSwitch::Auto,
            training: TrainSettings {
                hidden: vec![32, 32],
                epochs: 600,
                batch_size: 64,
                learning_rate: 3e-3,
                schedule: Schedule::Cosine,
                lambda: [1.0, 0.1, 0.0],
                validation_n: 0,
                log_every: 1_000_000,
                saturation_aware: true,
                ..TrainSettings::default()
            },
        }
    }
}

/// `[refine.check]`: the per-cell (stratified) check of `trainer refine --check N`: every
/// leaf cell gets at least one fresh MPC solve at a seeded random state inside it, cells
/// whose ε_C is near the target get more, and the check fails when the sampled
/// sensitivities miss their cells' estimated ranges more often than `tolerance`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CheckSettings {
    /// Extra states in every cell whose ε_C is at least `near` × the target (default 3).
    pub extra: usize,
    /// The fraction of the target above which a cell is "near" it (default 0.8).
    pub near: f64,
    /// Largest tolerated share of the per-cell states (regular labels) whose ∂κ/∂x lies
    /// outside their cell's estimated range (default 0.01).
    pub tolerance: f64,
    /// Times a failed check splits its offending cells and refines again before the verdict
    /// (default 2; 0 = report only).
    pub feedback: usize,
    /// Two converged solves at a check state (cold, and warm-started from the cell's nearest
    /// corner) differing by more than this fraction of the input band mark a jump of κ
    /// (different local optima); the cell is never certified (default 1e-3).
    pub jump_tol: f64,
}

impl Default for CheckSettings {
    fn default() -> Self {
        CheckSettings {
            extra: 3,
            near: 0.8,
            tolerance: 0.01,
            feedback: 2,
            jump_tol: 1e-3,
        }
    }
}

impl RefineSettings {
    /// Checks the settings (errors name the key).
    pub fn validate(&self, nx: usize) -> Result<(), ConfigError> {
        if !(self.target_eps.is_finite() && self.target_eps > 0.0) {
            return Err(invalid("refine.target_eps", "must be positive and finite"));
        }
        if let Some(s) = self.max_seconds.filter(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(invalid(
                "refine.max_seconds",
                format!("must be positive and finite, got {s}"),
            ));
        }
        if self.budget == 0 {
            return Err(invalid("refine.budget", "must be at least 1"));
        }
        if !self.initial.is_empty() && self.initial.len() != nx {
            return Err(invalid(
                "refine.initial",
                format!("expected {nx} per-axis counts, got {}", self.initial.len()),
            ));
        }
        if let Some(i) = self.initial.iter().position(|&c| !(2..=8193).contains(&c)) {
            return Err(invalid(
                format!("refine.initial[{i}]"),
                "must be in 2..=8193 (the lattice has 40 bisection levels below it)",
            ));
        }
        let grid = self
            .initial_counts(nx)
            .iter()
            .try_fold(1usize, |a, &c| a.checked_mul(c));
        if grid.is_none_or(|g| g > self.budget) {
            return Err(invalid(
                "refine.initial",
                format!(
                    "the initial grid ({:?} points per axis) needs more solves than the budget {}",
                    self.initial_counts(nx),
                    self.budget
                ),
            ));
        }
        if !(self.safety.is_finite() && self.safety >= 1.0) {
            return Err(invalid("refine.safety", "must be at least 1"));
        }
        if !(self.floor.is_finite() && self.floor >= 0.0) {
            return Err(invalid("refine.floor", "must be ≥ 0 and finite"));
        }
        let c = &self.check;
        if !(c.near.is_finite() && c.near >= 0.0) {
            return Err(invalid("refine.check.near", "must be ≥ 0 and finite"));
        }
        if !(c.tolerance.is_finite() && (0.0..1.0).contains(&c.tolerance)) {
            return Err(invalid("refine.check.tolerance", "must be in [0, 1)"));
        }
        if !(c.jump_tol.is_finite() && c.jump_tol > 0.0) {
            return Err(invalid(
                "refine.check.jump_tol",
                "must be positive and finite",
            ));
        }
        if !(self.round_learning_rate.is_finite() && self.round_learning_rate > 0.0) {
            return Err(invalid("refine.round_learning_rate", "must be positive"));
        }
        if !(self.retrain_at.is_finite() && self.retrain_at >= 0.0) {
            return Err(invalid("refine.retrain_at", "must be ≥ 0"));
        }
        if !(self.min_width.is_finite() && self.min_width > 0.0 && self.min_width < 1.0) {
            return Err(invalid("refine.min_width", "must be in (0, 1)"));
        }
        if !(self.min_cell.is_finite() && self.min_cell > 0.0 && self.min_cell <= 1.0) {
            return Err(invalid(
                "refine.min_cell",
                format!("must be in (0, 1], got {}", self.min_cell),
            ));
        }
        if !(self.emphasis_at.is_finite() && self.emphasis_at >= 0.0) || self.emphasis == 0 {
            return Err(invalid(
                "refine.emphasis",
                "emphasis ≥ 1 and emphasis_at ≥ 0",
            ));
        }
        let t = &self.training;
        if t.hidden.is_empty() || t.hidden.contains(&0) || t.epochs == 0 || t.batch_size == 0 {
            return Err(invalid(
                "refine.training",
                "hidden widths, epochs and batch_size must be positive",
            ));
        }
        super::limits::check_hidden("refine.training.hidden", &t.hidden)?;
        if !(t.learning_rate.is_finite() && t.learning_rate > 0.0) {
            return Err(invalid(
                "refine.training.learning_rate",
                format!("must be positive and finite, got {}", t.learning_rate),
            ));
        }
        if let Some(i) = t.lambda.iter().position(|l| !(l.is_finite() && *l >= 0.0)) {
            return Err(invalid(
                format!("refine.training.lambda[{i}]"),
                format!("must be finite and ≥ 0, got {}", t.lambda[i]),
            ));
        }
        Ok(())
    }

    /// Whether these are the default settings (then not serialised).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// Initial grid counts for an `nx`-dimensional domain.
    pub fn initial_counts(&self, nx: usize) -> Vec<usize> {
        if self.initial.is_empty() {
            // 9 per axis up to nx = 4 (as always); for larger nx the largest count whose
            // grid has at most 50 000 points (the default budget), at least 2.
            let fits = |c: usize| (c as f64).powi(nx as i32) <= 50_000.0;
            let c = (2..=9).rev().find(|&c| fits(c)).unwrap_or(2);
            vec![c; nx]
        } else {
            self.initial.clone()
        }
    }
}
