//! Validation of a problem file: every setting is checked once, at the edge; each error names
//! the dotted key at fault (`ocp.q`, `domain.lo[1]`, …).

use super::*;

fn check_vec(key: &str, v: &[f64], n: usize, allow_inf: bool) -> Result<(), ConfigError> {
    if v.len() != n {
        return Err(invalid(
            key,
            format!("expected {n} entries, got {}", v.len()),
        ));
    }
    for (i, x) in v.iter().enumerate() {
        if x.is_nan() || (!allow_inf && x.is_infinite()) {
            return Err(invalid(
                format!("{key}[{i}]"),
                format!("must be a finite number, got {x}"),
            ));
        }
    }
    Ok(())
}

/// Input bounds: one finite number per input (module doc of `validate`: why not ±inf).
fn check_input_bounds(key: &str, v: &[f64], n: usize) -> Result<(), ConfigError> {
    check_vec(key, v, n, true)?;
    if let Some(i) = v.iter().position(|x| x.is_infinite()) {
        return Err(invalid(
            format!("{key}[{i}]"),
            format!(
                "input bounds must be finite numbers, got {} (U scales the network's outputs \
                 and sets its clamp band and the actuator saturation; unbounded inputs mean \
                 nothing there)",
                v[i]
            ),
        ));
    }
    Ok(())
}

fn check_bounds(
    key_lo: &str,
    key_hi: &str,
    lo: &[f64],
    hi: &[f64],
    strict: bool,
) -> Result<(), ConfigError> {
    for (i, (l, h)) in lo.iter().zip(hi).enumerate() {
        if l > h || (strict && l >= h) {
            return Err(invalid(
                format!("{key_lo}[{i}]"),
                format!("lower bound {l} is not below {key_hi}[{i}] = {h}"),
            ));
        }
    }
    Ok(())
}

pub(crate) fn check_matrix(
    key: &str,
    m: &MatrixSpec,
    n: usize,
    definite: bool,
) -> Result<DMatrix<f64>, ConfigError> {
    let mat = m
        .to_dmatrix()
        .ok_or_else(|| invalid(key, "rows have different lengths"))?;
    if mat.nrows() != n || mat.ncols() != n {
        return Err(invalid(
            key,
            format!(
                "expected a {n}×{n} matrix (or {n} diagonal entries), got {}×{}",
                mat.nrows(),
                mat.ncols()
            ),
        ));
    }
    if mat.iter().any(|x| !x.is_finite()) {
        return Err(invalid(key, "entries must be finite numbers"));
    }
    let scale = mat.amax().max(1.0);
    if (&mat - mat.transpose()).amax() > 1e-12 * scale {
        return Err(invalid(key, "must be symmetric"));
    }
    let min_eig = mat.clone().symmetric_eigen().eigenvalues.min();
    if definite && min_eig <= 1e-12 * scale {
        return Err(invalid(
            key,
            format!("must be positive definite (smallest eigenvalue {min_eig:.3e})"),
        ));
    }
    if !definite && min_eig < -1e-12 * scale {
        return Err(invalid(
            key,
            format!("must be positive semidefinite (smallest eigenvalue {min_eig:.3e})"),
        ));
    }
    Ok(mat)
}

/// `ocp.x_ref` / `ocp.u_ref`: one finite entry per state (input), named in the messages for an
/// expression plant, inside `[lo, hi]` of each box in `within` (keys of lo and hi, lo, hi).
fn check_setpoint(
    key: &str,
    v: &[f64],
    names: Option<&[String]>,
    within: &[(&str, &str, &[f64], &[f64])],
) -> Result<(), ConfigError> {
    let n = within.first().map_or(v.len(), |w| w.2.len());
    let what = if key.ends_with("x_ref") {
        "state"
    } else {
        "input"
    };
    let name = |i: usize| names.and_then(|n| n.get(i)).map(|s| format!(" ({s})"));
    if v.len() != n {
        let list = names.map_or(String::new(), |n| format!(": {}", n.join(", ")));
        return Err(invalid(
            key,
            format!(
                "expected {n} entries, one per {what}{list}; got {}",
                v.len()
            ),
        ));
    }
    for (i, x) in v.iter().enumerate() {
        let at = format!("{key}[{i}]");
        let nm = name(i).unwrap_or_default();
        if !x.is_finite() {
            return Err(invalid(
                at,
                format!("{what}{nm} must be a finite number, got {x}"),
            ));
        }
        for (klo, khi, lo, hi) in within {
            if !(lo[i] <= *x && *x <= hi[i]) {
                return Err(invalid(
                    at,
                    format!(
                        "{what}{nm} = {x} lies outside [{klo}[{i}], {khi}[{i}]] = [{}, {}]",
                        lo[i], hi[i]
                    ),
                ));
            }
        }
    }
    Ok(())
}

impl ProblemConfig {
    /// Checks every setting once; the error names the key at fault. The sections are
    /// checked in this order (the first fault is reported): name, system, OCP, constraints,
    /// domain, setpoint, solver, training, closed loop, robust design, plots, sampling,
    /// refinement, certify.
    pub fn validate(&self) -> Result<(), ConfigError> {
        crate::io::check_path_component(&self.name).map_err(|r| invalid("name", r))?;
        self.system.validate().map_err(|(k, r)| invalid(k, r))?;
        let (nx, nu) = (self.system.nx(), self.system.nu());
        self.ocp.validate(nx, nu)?;
        self.constraint_set()
            .map_err(|e| invalid(e.key.clone(), e.reason()))?;
        self.validate_online_check()?;
        self.domain.validate(nx)?;
        self.validate_setpoint()?;
        self.solver.validate()?;
        self.training.validate()?;
        self.validate_sequence_weights()?;
        self.closed_loop.validate(nx)?;
        self.robust.validate(nx, nu)?;
        self.closed_loop.validate_seeds()?;
        self.validate_mismatch()?;
        self.validate_safety()?;
        self.plots.validate()?;
        self.sampling.validate(nx)?;
        self.refine.validate(nx)?;
        self.certify.validate()?;
        Ok(())
    }

    /// `training.sequence_weights`: only with `outputs = "sequence"`, exactly `ocp.horizon`
    /// values, each finite and ≥ 0, the first > 0.
    fn validate_sequence_weights(&self) -> Result<(), ConfigError> {
        if self.training.outputs.is_first() && !self.training.sequence_form.is_open() {
            return Err(invalid(
                "training.sequence_form",
                "needs training.outputs = \"sequence\"",
            ));
        }
        let Some(w) = &self.training.sequence_weights else {
            return Ok(());
        };
        let key = "training.sequence_weights";
        if self.training.outputs.is_first() {
            return Err(invalid(key, "needs training.outputs = \"sequence\""));
        }
        if w.len() != self.ocp.horizon {
            return Err(invalid(
                key,
                format!(
                    "needs one weight per step of ocp.horizon = {}, got {}",
                    self.ocp.horizon,
                    w.len()
                ),
            ));
        }
        if let Some(k) = w.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(invalid(
                format!("{key}[{k}]"),
                format!("must be finite and ≥ 0, got {}", w[k]),
            ));
        }
        if w[0] <= 0.0 {
            return Err(invalid(format!("{key}[0]"), "u₀'s weight must be > 0"));
        }
        Ok(())
    }

    /// The setpoint: inside X (where the net is trained and certified) and the state
    /// bounds (else it cannot be held); u_ref inside the input bounds.
    fn validate_setpoint(&self) -> Result<(), ConfigError> {
        let o = &self.ocp;
        let expr = self.system.expr_model();
        if let Some(xr) = &o.x_ref {
            check_setpoint(
                "ocp.x_ref",
                xr,
                expr.map(|m| m.state_names()),
                &[
                    ("domain.lo", "domain.hi", &self.domain.lo, &self.domain.hi),
                    ("ocp.x_lo", "ocp.x_hi", &o.x_lo, &o.x_hi),
                ],
            )?;
        }
        if let Some(ur) = &o.u_ref {
            check_setpoint(
                "ocp.u_ref",
                ur,
                expr.map(|m| m.input_names()),
                &[("ocp.u_lo", "ocp.u_hi", &o.u_lo, &o.u_hi)],
            )?;
        }
        Ok(())
    }
}

impl OcpSettings {
    /// `[ocp]` for a system of `nx` states and `nu` inputs: sampling time, horizon, weights,
    /// bounds and the per-stage bounds of a robust design.
    fn validate(&self, nx: usize, nu: usize) -> Result<(), ConfigError> {
        let o = self;
        if !(o.ts.is_finite() && o.ts > 0.0) {
            return Err(invalid(
                "ocp.ts",
                format!("must be finite and > 0, got {}", o.ts),
            ));
        }
        if !(o.setpoint_tol.is_finite() && o.setpoint_tol > 0.0) {
            return Err(invalid(
                "ocp.setpoint_tol",
                format!("must be finite and > 0, got {}", o.setpoint_tol),
            ));
        }
        if o.horizon == 0 {
            return Err(invalid("ocp.horizon", "must be at least 1"));
        }
        if o.rk4_substeps == 0 {
            return Err(invalid("ocp.rk4_substeps", "must be at least 1"));
        }
        super::limits::check_ocp_sizes(o.horizon, o.rk4_substeps)?;
        check_matrix("ocp.q", &o.q, nx, false)?;
        check_matrix("ocp.r", &o.r, nu, true)?;
        check_matrix("ocp.p", &o.p, nx, false)?;
        check_vec("ocp.x_lo", &o.x_lo, nx, true)?;
        check_vec("ocp.x_hi", &o.x_hi, nx, true)?;
        // State bounds may be ±inf (no bound on that state: its row is left out of the OCP);
        // input bounds may not: U scales the network's outputs, sets the clamp band
        // U ⊕ [−ε, ε] and the actuator saturation, none of which means anything unbounded.
        check_input_bounds("ocp.u_lo", &o.u_lo, nu)?;
        check_input_bounds("ocp.u_hi", &o.u_hi, nu)?;
        check_bounds("ocp.x_lo", "ocp.x_hi", &o.x_lo, &o.x_hi, false)?;
        check_bounds("ocp.u_lo", "ocp.u_hi", &o.u_lo, &o.u_hi, false)?;
        if let Some(st) = &o.stages {
            st.validate(o.horizon, nx, nu)?;
        }
        for (key, v, n) in [
            ("ocp.x_scale", &o.x_scale, nx),
            ("ocp.u_scale", &o.u_scale, nu),
        ] {
            if let Some(v) = v {
                check_scale(key, v, n)?;
            }
        }
        Ok(())
    }
}

/// `ocp.x_scale` / `ocp.u_scale`: one finite entry > 0 per state (input).
fn check_scale(key: &str, v: &[f64], n: usize) -> Result<(), ConfigError> {
    check_vec(key, v, n, false)?;
    if let Some(i) = v.iter().position(|s| *s <= 0.0) {
        return Err(invalid(
            format!("{key}[{i}]"),
            format!(
                "a scale of the certificate's norm must be finite and > 0, got {}",
                v[i]
            ),
        ));
    }
    Ok(())
}

impl StageBounds {
    /// `[ocp.stages]`: N rows of state and input bounds, N + 1 margins per constraint.
    fn validate(&self, horizon: usize, nx: usize, nu: usize) -> Result<(), ConfigError> {
        let st = self;
        for (key, rows, n_rows, dim) in [
            ("ocp.stages.x_lo", &st.x_lo, horizon, nx),
            ("ocp.stages.x_hi", &st.x_hi, horizon, nx),
            ("ocp.stages.u_lo", &st.u_lo, horizon, nu),
            ("ocp.stages.u_hi", &st.u_hi, horizon, nu),
        ] {
            if rows.len() != n_rows {
                return Err(invalid(
                    key,
                    format!("expected {n_rows} stages (N), got {}", rows.len()),
                ));
            }
            for (k, r) in rows.iter().enumerate() {
                let at = format!("{key}[{k}]");
                if key.contains(".u_") {
                    check_input_bounds(&at, r, dim)?;
                } else {
                    check_vec(&at, r, dim, true)?;
                }
            }
        }
        for (c, m) in st.margins.iter().enumerate() {
            if m.len() != horizon + 1 {
                return Err(invalid(
                    format!("ocp.stages.margins[{c}]"),
                    format!("expected {} stages (N + 1), got {}", horizon + 1, m.len()),
                ));
            }
            if let Some(k) = m.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
                return Err(invalid(
                    format!("ocp.stages.margins[{c}][{k}]"),
                    format!("must be finite and ≥ 0, got {}", m[k]),
                ));
            }
        }
        for k in 0..horizon {
            check_bounds(
                &format!("ocp.stages.x_lo[{k}]"),
                &format!("ocp.stages.x_hi[{k}]"),
                &st.x_lo[k],
                &st.x_hi[k],
                false,
            )?;
            check_bounds(
                &format!("ocp.stages.u_lo[{k}]"),
                &format!("ocp.stages.u_hi[{k}]"),
                &st.u_lo[k],
                &st.u_hi[k],
                false,
            )?;
        }
        Ok(())
    }
}

impl Domain {
    /// `[domain]`: X's finite bounds, lo < hi on every axis.
    fn validate(&self, nx: usize) -> Result<(), ConfigError> {
        check_vec("domain.lo", &self.lo, nx, false)?;
        check_vec("domain.hi", &self.hi, nx, false)?;
        check_bounds("domain.lo", "domain.hi", &self.lo, &self.hi, true)
    }
}

impl SolverSettings {
    /// `[solver]`: tolerance, iterations, retry budget, soft-constraint weights, degeneracy tolerance.
    fn validate(&self) -> Result<(), ConfigError> {
        let s = self;
        if !(s.tol.is_finite() && s.tol > 0.0 && s.tol < 1.0) {
            return Err(invalid(
                "solver.tol",
                format!("must be in (0, 1), got {}", s.tol),
            ));
        }
        if s.max_iter == 0 {
            return Err(invalid("solver.max_iter", "must be at least 1"));
        }
        if s.retry_budget > 1000 {
            return Err(invalid(
                "solver.retry_budget",
                format!("must be at most 1000 (× max_iter), got {}", s.retry_budget),
            ));
        }
        for (k, v) in [("solver.soft_l1", s.soft_l1), ("solver.soft_l2", s.soft_l2)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(k, format!("must be finite and ≥ 0, got {v}")));
            }
        }
        if s.soft_l1 <= 0.0 && s.soft_l2 <= 0.0 {
            return Err(invalid(
                "solver.soft_l1",
                "soft_l1 and soft_l2 cannot both be 0",
            ));
        }
        if !(s.degeneracy_tol.is_finite() && s.degeneracy_tol > 0.0) {
            return Err(invalid("solver.degeneracy_tol", "must be finite and > 0"));
        }
        if let Some(starts) = &s.starts {
            if starts.is_empty() {
                return Err(invalid("solver.starts", "must name at least one start"));
            }
            for (i, a) in starts.iter().enumerate() {
                if starts[..i].contains(a) {
                    return Err(invalid(
                        "solver.starts",
                        format!("names \"{}\" twice", a.as_str()),
                    ));
                }
            }
        }
        Ok(())
    }
}

impl TrainSettings {
    /// `[training]`: the net's widths, the optimiser's settings, the loss weights.
    fn validate(&self) -> Result<(), ConfigError> {
        let t = self;
        if t.hidden.is_empty() || t.hidden.contains(&0) {
            return Err(invalid(
                "training.hidden",
                "needs at least one hidden layer, all widths ≥ 1",
            ));
        }
        super::limits::check_hidden("training.hidden", &t.hidden)?;
        if t.epochs == 0 {
            return Err(invalid("training.epochs", "must be at least 1"));
        }
        if t.batch_size == 0 {
            return Err(invalid("training.batch_size", "must be at least 1"));
        }
        if !(t.learning_rate.is_finite() && t.learning_rate > 0.0) {
            return Err(invalid("training.learning_rate", "must be finite and > 0"));
        }
        if let Some(i) = t.lambda.iter().position(|l| !(l.is_finite() && *l >= 0.0)) {
            return Err(invalid(
                format!("training.lambda[{i}]"),
                "must be finite and ≥ 0",
            ));
        }
        if t.lambda[0] <= 0.0 {
            return Err(invalid(
                "training.lambda[0]",
                "the value term's weight must be > 0",
            ));
        }
        if t.target_eps_d.is_some_and(|e| !(e.is_finite() && e > 0.0)) {
            return Err(invalid("training.target_eps_d", "must be finite and > 0"));
        }
        if t.log_every == 0 {
            return Err(invalid("training.log_every", "must be at least 1"));
        }
        if t.validation_n < 2 {
            return Err(invalid(
                "training.validation_n",
                format!(
                    "must be at least 2 (R² and the L_MPC estimate need validation states), got {}",
                    t.validation_n
                ),
            ));
        }
        Ok(())
    }
}

impl ClosedLoopSettings {
    /// `[closed_loop]` for `nx` states: steps, initial state, noise and mismatch fractions
    /// (the seed count: [`ClosedLoopSettings::validate_seeds`]).
    fn validate(&self, nx: usize) -> Result<(), ConfigError> {
        let c = self;
        if c.steps == 0 {
            return Err(invalid("closed_loop.steps", "must be at least 1"));
        }
        if let Some(x0) = &c.x0 {
            check_vec("closed_loop.x0", x0, nx, false)?;
        }
        for (k, v) in [
            ("closed_loop.noise_fraction", c.noise_fraction),
            ("closed_loop.mass_mismatch", c.mass_mismatch),
        ] {
            if !(v.is_finite() && (0.0..1.0).contains(&v)) {
                return Err(invalid(k, format!("must be in [0, 1), got {v}")));
            }
        }
        Ok(())
    }

    /// `closed_loop.seeds`: at most 1000.
    fn validate_seeds(&self) -> Result<(), ConfigError> {
        let c = self;
        if c.seeds > 1000 {
            return Err(invalid(
                "closed_loop.seeds",
                format!("at most 1000, got {}", c.seeds),
            ));
        }
        Ok(())
    }
}

impl ProblemConfig {
    /// `closed_loop.safety`: needs `[training] outputs = "sequence"` (the online check runs
    /// the network's whole sequence); `closed_loop.safety_runs` in 1 ..= 10⁷,
    /// `closed_loop.safety_mismatch_runs` ≤ 10⁷; `closed_loop.safety_decrease` in [0, 1].
    fn validate_safety(&self) -> Result<(), ConfigError> {
        let c = &self.closed_loop;
        let sigma = c.safety_decrease;
        if !(0.0..=1.0).contains(&sigma) {
            return Err(invalid(
                "closed_loop.safety_decrease",
                format!("must be in [0, 1] (0: the strict rule), got {sigma}"),
            ));
        }
        if !c.safety {
            return Ok(());
        }
        if self.training.outputs != super::training::Outputs::Sequence {
            return Err(invalid(
                "closed_loop.safety",
                "needs `[training] outputs = \"sequence\"`: the safety-augmented controller \
                 checks the network's whole input sequence",
            ));
        }
        if !(1..=10_000_000).contains(&c.safety_runs) {
            return Err(invalid(
                "closed_loop.safety_runs",
                format!("must be in 1 ..= 10000000, got {}", c.safety_runs),
            ));
        }
        if c.safety_mismatch_runs > 10_000_000 {
            return Err(invalid(
                "closed_loop.safety_mismatch_runs",
                format!("at most 10000000, got {}", c.safety_mismatch_runs),
            ));
        }
        Ok(())
    }

    /// `closed_loop.mismatch`: each entry a parameter of the plant (the message lists
    /// them) and a relative change in (0, 1); no parameter twice.
    fn validate_mismatch(&self) -> Result<(), ConfigError> {
        let Some(list) = &self.closed_loop.mismatch else {
            return Ok(());
        };
        let names = self.system.parameter_names();
        for (i, m) in list.iter().enumerate() {
            let key = format!("closed_loop.mismatch[{i}]");
            if !names.contains(&m.parameter) {
                let known = if names.is_empty() {
                    "it has none".to_string()
                } else {
                    format!("its parameters are {}", names.join(", "))
                };
                return Err(invalid(
                    format!("{key}.parameter"),
                    format!("`{}` is no parameter of the plant; {known}", m.parameter),
                ));
            }
            if !(m.relative.is_finite() && m.relative > 0.0 && m.relative < 1.0) {
                return Err(invalid(
                    format!("{key}.relative"),
                    format!("must be in (0, 1), got {}", m.relative),
                ));
            }
            if list[..i].iter().any(|o| o.parameter == m.parameter) {
                return Err(invalid(
                    format!("{key}.parameter"),
                    format!("`{}` is listed twice", m.parameter),
                ));
            }
        }
        Ok(())
    }
}

impl PlotSettings {
    /// `[plots]`: the error map's grid and the PNG scale.
    fn validate(&self) -> Result<(), ConfigError> {
        let pl = self;
        if let Some(i) = pl
            .error_map_grid
            .iter()
            .position(|&n| !(2..=2000).contains(&n))
        {
            return Err(invalid(
                format!("plots.error_map_grid[{i}]"),
                format!("must be in 2..=2000, got {}", pl.error_map_grid[i]),
            ));
        }
        if !(pl.png_scale.is_finite() && (0.1..=8.0).contains(&pl.png_scale)) {
            return Err(invalid(
                "plots.png_scale",
                format!("must be in [0.1, 8], got {}", pl.png_scale),
            ));
        }
        Ok(())
    }
}

impl SamplingSettings {
    /// `[sampling]` for `nx` states: the plan's size (adaptive and imported datasets are
    /// not sampled).
    fn validate(&self, nx: usize) -> Result<(), ConfigError> {
        let sm = self;
        match sm.sampler {
            SamplerKind::Grid => {
                if sm.counts.len() != nx {
                    return Err(invalid(
                        "sampling.counts",
                        format!("expected {nx} per-axis counts, got {}", sm.counts.len()),
                    ));
                }
                if let Some(i) = sm.counts.iter().position(|&c| c == 0) {
                    return Err(invalid(
                        format!("sampling.counts[{i}]"),
                        "must be at least 1",
                    ));
                }
                let total = sm.counts.iter().try_fold(1usize, |a, &c| a.checked_mul(c));
                if total.is_none_or(|t| t > 100_000_000) {
                    return Err(invalid("sampling.counts", "grid has more than 1e8 points"));
                }
            }
            SamplerKind::Random | SamplerKind::Halton => {
                if sm.n == 0 || sm.n > 100_000_000 {
                    return Err(invalid("sampling.n", "must be between 1 and 1e8"));
                }
            }
            SamplerKind::Adaptive => {
                return Err(invalid(
                    "sampling.sampler",
                    "\"adaptive\" datasets are made by `trainer refine`, not sampled",
                ));
            }
            SamplerKind::Imported => {
                return Err(invalid(
                    "sampling.sampler",
                    "\"imported\" datasets are made by `trainer import`, not sampled",
                ));
            }
        }
        Ok(())
    }
}
