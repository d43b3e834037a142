//! [`CustomPlant`]: a plant implemented in Rust in the crate of a library user — the
//! extension point for plants that are neither built in nor written as expressions.
//!
//! The user writes ẋ = f(x, u) once, generically over the number type, as [`Dynamics`] for
//! a `serde` struct that holds the plant's parameters, and wraps it:
//! `CustomPlant::new("duffing", "1", Duffing { .. })`. Downstream it is the same discrete
//! map as a built-in's, `F(x, u) = Φ_h^M(x, u)` (M = `ocp.rk4_substeps` classical RK4 steps
//! of size h = Ts/M, the built-ins' RK4 code), with exact `∂F/∂x`, `∂F/∂u` and `∇²(λᵀF)` by
//! forward-mode AD (num-dual) with `NZ = nx + nu` directions, `NZ` a constant chosen by the
//! expression plants' `by_nz!` dispatch (`nx + nu ≤` [`MAX_NZ`]).
//!
//! **Object safety.** [`ErasedPlant`] is a plant's object-safe face (f64 slices in and out).
//! A blanket impl provides it for every `T: Dynamics + Serialize + DeserializeOwned + Send +
//! Sync + 'static`, so `System::Custom` holds an `Arc<dyn ErasedPlant>` and stays `Clone`,
//! `Send` and `Sync`.
//!
//! **What files record.** A custom plant serialises (in `problem.toml`, in a dataset's
//! stored problem, and in the bytes of the problem hash) as
//! ```toml
//! [system]
//! kind = "custom"
//! name = "duffing"          # declared by the plant's program
//! version = "1"             # declared too: a new version for new equations
//! states = ["q", "v"]       # optional names (plots, reports)
//! inputs = ["force"]
//! fingerprint = "…"         # f(x, u) at fixed probe points, 9 significant digits, hashed
//! [system.parameters]       # the plant struct's serde record
//! delta = 0.3
//! ```
//! Two plants under one name therefore hash differently when their version, parameters or
//! fingerprint differ — the fingerprint catches equations edited without a new version
//! (at the probe points: it is a check, not a proof of equality).
//!
//! **Reading back.** Only a program that has the plant can rebuild it:
//! [`ProblemConfig::from_toml_str_with`](crate::problem::ProblemConfig::from_toml_str_with)
//! takes that program's plants as prototypes, finds the file's plant by name, checks the
//! version and the names, rebuilds the struct from `[system.parameters]` (keys the file
//! omits come from the prototype; keys the struct does not have are errors) and checks the
//! fingerprint when the file has one. Anywhere else — the `trainer` command line — reading
//! `kind = "custom"` is an error that names the plant: a custom plant is never replaced by
//! another. (The prototypes reach serde's `TryFrom` through a thread-local set for the
//! duration of that one call.)

use super::nz::by_nz;
use super::{ad_hessian, ad_linearize, rk4, Dynamics, MAX_NZ};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::cell::RefCell;
use std::fmt;
use std::sync::Arc;

/// The object-safe face of a plant: sizes, f and F in `f64`, F's exact derivatives, and
/// its parameter record. Provided by a blanket impl for every `serde` struct implementing
/// [`Dynamics`]; implement it by hand only for a plant that is not an ODE (its derivatives
/// must then be exact: the solver, the sensitivities and the robust design trust them).
pub trait ErasedPlant: Send + Sync + 'static {
    /// State dimension n_x.
    fn nx(&self) -> usize;
    /// Input dimension n_u.
    fn nu(&self) -> usize;
    /// `dx = f(x, u)` in f64.
    fn rhs_f64(&self, x: &[f64], u: &[f64], dx: &mut [f64]);
    /// `out = F(x, u)`: `substeps` RK4 steps over `ts`.
    fn step(&self, ts: f64, substeps: usize, x: &[f64], u: &[f64], out: &mut [f64]);
    /// `f = F(x, u)`, `jx = ∂F/∂x` (row-major nx×nx), `ju = ∂F/∂u` (row-major nx×nu).
    #[allow(clippy::too_many_arguments)]
    fn linearize(
        &self,
        ts: f64,
        substeps: usize,
        x: &[f64],
        u: &[f64],
        f: &mut [f64],
        jx: &mut [f64],
        ju: &mut [f64],
    );
    /// `hess = ∇²_{(x,u)} (λᵀF(x, u))`, row-major (nx+nu)×(nx+nu).
    fn lagrangian_hessian(
        &self,
        ts: f64,
        substeps: usize,
        x: &[f64],
        u: &[f64],
        lam: &[f64],
        hess: &mut [f64],
    );
    /// The parameter record as a TOML table (the struct's `serde` serialisation).
    fn parameters(&self) -> Result<toml::Table, RecordError>;
    /// The same kind of plant built from a parameter record.
    fn rebuild(&self, parameters: &toml::Table) -> Result<Arc<dyn ErasedPlant>, RecordError>;
}

/// Calls the AD kernels with the dual size `NZ` as a method (the form `by_nz!` expects);
/// one function per size (`inline(never)`) keeps the dispatch small — inlined, the custom
/// Hessian measured 1.2–1.5× the built-in's (BENCHMARKS.md).
struct Ad<'a, T>(&'a T);

impl<T: Dynamics> Ad<'_, T> {
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn lin<const NZ: usize>(
        &self,
        ts: f64,
        m: usize,
        x: &[f64],
        u: &[f64],
        f: &mut [f64],
        jx: &mut [f64],
        ju: &mut [f64],
    ) {
        ad_linearize::<T, NZ, NZ>(self.0, ts, m, x, u, f, jx, ju)
    }
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn hess<const NZ: usize>(
        &self,
        ts: f64,
        m: usize,
        x: &[f64],
        u: &[f64],
        lam: &[f64],
        h: &mut [f64],
    ) {
        ad_hessian::<T, NZ, NZ>(self.0, ts, m, x, u, lam, h)
    }
}

impl<T> ErasedPlant for T
where
    T: Dynamics + Serialize + DeserializeOwned + Send + Sync + 'static,
{
    fn nx(&self) -> usize {
        T::NX
    }
    fn nu(&self) -> usize {
        T::NU
    }
    fn rhs_f64(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        Dynamics::rhs(self, &x[..T::NX], &u[..T::NU], &mut dx[..T::NX]);
    }
    fn step(&self, ts: f64, substeps: usize, x: &[f64], u: &[f64], out: &mut [f64]) {
        let nx = T::NX;
        out[..nx].copy_from_slice(&x[..nx]);
        rk4::<T, f64, MAX_NZ>(self, &mut out[..nx], &u[..T::NU], ts, substeps);
    }
    fn linearize(
        &self,
        ts: f64,
        m: usize,
        x: &[f64],
        u: &[f64],
        f: &mut [f64],
        jx: &mut [f64],
        ju: &mut [f64],
    ) {
        let ad = Ad(self);
        by_nz!(T::NX + T::NU, ad.lin(ts, m, x, u, f, jx, ju))
    }
    fn lagrangian_hessian(
        &self,
        ts: f64,
        m: usize,
        x: &[f64],
        u: &[f64],
        lam: &[f64],
        hess: &mut [f64],
    ) {
        let ad = Ad(self);
        by_nz!(T::NX + T::NU, ad.hess(ts, m, x, u, lam, hess))
    }
    fn parameters(&self) -> Result<toml::Table, RecordError> {
        toml::Table::try_from(self).map_err(RecordError::Serialise)
    }
    fn rebuild(&self, parameters: &toml::Table) -> Result<Arc<dyn ErasedPlant>, RecordError> {
        let t: T = parameters
            .clone()
            .try_into()
            .map_err(RecordError::Deserialise)?;
        Ok(Arc::new(t))
    }
}

/// The `[system]` table of a custom plant (without `kind`), as written and hashed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CustomSpec {
    /// The plant's name, declared by its program.
    pub name: String,
    /// Its version, declared by its program (a new one for new equations).
    pub version: String,
    /// State names, in order (empty: `x1`, `x2`, …).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub states: Vec<String>,
    /// Input names, in order (empty: `u1`, …).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub inputs: Vec<String>,
    /// f(x, u) at fixed probe points (always written; checked when a file has it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fingerprint: Option<String>,
    /// The plant struct's parameter record.
    #[serde(default, skip_serializing_if = "toml::Table::is_empty")]
    pub parameters: toml::Table,
}

/// A custom plant that cannot be built or read; `key` is the problem-file key at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("custom plant `{plant}`: `{key}`: {reason}")]
pub struct CustomPlantError {
    /// The plant's name.
    pub plant: String,
    /// The dotted key at fault (`system.version`, `system.parameters.k`, …).
    pub key: String,
    /// What is wrong.
    pub reason: String,
    /// The TOML error `reason` states, when the parameter record does not convert.
    #[source]
    pub source: Option<Box<RecordError>>,
}

impl CustomPlantError {
    /// The error of a parameter record that does not convert (key `system.parameters`).
    fn record(plant: &str, e: RecordError) -> Self {
        CustomPlantError {
            plant: plant.to_string(),
            key: "system.parameters".into(),
            reason: e.to_string(),
            source: Some(Box::new(e)),
        }
    }
}

/// A plant's parameter record that does not convert to or from TOML.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RecordError {
    /// The plant struct does not serialise as a TOML table.
    #[error(
        "the plant's parameters do not serialise as a TOML table (use a struct with named \
         fields): {0}"
    )]
    Serialise(toml::ser::Error),
    /// A record does not deserialise into the plant struct.
    #[error("{0}")]
    Deserialise(toml::de::Error),
}

/// A plant implemented in Rust by the library's user, with its name, version, names and
/// parameter record (see the module doc). Equality, `Debug` and serialisation go by the
/// record ([`CustomSpec`]).
#[derive(Clone, Serialize, Deserialize)]
#[serde(try_from = "CustomSpec", into = "CustomSpec")]
pub struct CustomPlant {
    spec: CustomSpec,
    imp: Arc<dyn ErasedPlant>,
}

impl CustomPlant {
    /// Wraps `plant` under `name` and `version` (both non-empty), after checking its sizes
    /// (`nx ≥ 1`, `nu ≥ 1`, `nx + nu ≤` [`MAX_NZ`]) and its parameter record.
    pub fn new(
        name: &str,
        version: &str,
        plant: impl ErasedPlant,
    ) -> Result<Self, CustomPlantError> {
        let spec = CustomSpec {
            name: name.to_string(),
            version: version.to_string(),
            states: vec![],
            inputs: vec![],
            fingerprint: None,
            parameters: toml::Table::new(),
        };
        Self::build(spec, Arc::new(plant))
    }

    /// The plant with state and input names (used by plots and reports; part of the record).
    pub fn with_names(
        mut self,
        states: &[&str],
        inputs: &[&str],
    ) -> Result<Self, CustomPlantError> {
        self.spec.states = states.iter().map(|s| s.to_string()).collect();
        self.spec.inputs = inputs.iter().map(|s| s.to_string()).collect();
        self.validate()?;
        Ok(self)
    }

    /// Completes the record from the implementation: canonical parameters, fingerprint.
    fn build(mut spec: CustomSpec, imp: Arc<dyn ErasedPlant>) -> Result<Self, CustomPlantError> {
        spec.parameters = imp
            .parameters()
            .map_err(|e| CustomPlantError::record(&spec.name, e))?;
        spec.fingerprint = Some(fingerprint(imp.as_ref()));
        let p = CustomPlant { spec, imp };
        p.validate()?;
        Ok(p)
    }

    fn err(&self, key: &str, reason: impl Into<String>) -> CustomPlantError {
        CustomPlantError {
            plant: self.spec.name.clone(),
            key: key.to_string(),
            reason: reason.into(),
            source: None,
        }
    }

    /// Checks name, version, sizes and names.
    pub fn validate(&self) -> Result<(), CustomPlantError> {
        let (nx, nu) = (self.nx(), self.nu());
        if self.spec.name.trim().is_empty() {
            return Err(self.err("system.name", "a custom plant needs a name"));
        }
        if self.spec.version.trim().is_empty() {
            return Err(self.err("system.version", "a custom plant needs a version"));
        }
        if nx == 0 || nu == 0 {
            return Err(self.err(
                "system",
                format!("{nx} states and {nu} inputs: a plant needs at least one of each"),
            ));
        }
        if nx + nu > MAX_NZ {
            return Err(self.err(
                "system",
                format!("{nx} states and {nu} inputs: at most {MAX_NZ} states and inputs together"),
            ));
        }
        for (key, names, n) in [
            ("system.states", &self.spec.states, nx),
            ("system.inputs", &self.spec.inputs, nu),
        ] {
            if !names.is_empty() && names.len() != n {
                return Err(self.err(key, format!("{} names for {n} entries", names.len())));
            }
        }
        Ok(())
    }

    /// The plant's name.
    pub fn name(&self) -> &str {
        &self.spec.name
    }
    /// Its declared version.
    pub fn version(&self) -> &str {
        &self.spec.version
    }
    /// The record that files store and the problem hash covers.
    pub fn spec(&self) -> &CustomSpec {
        &self.spec
    }
    /// The implementation.
    pub fn plant(&self) -> &dyn ErasedPlant {
        self.imp.as_ref()
    }
    /// State dimension.
    pub fn nx(&self) -> usize {
        self.imp.nx()
    }
    /// Input dimension.
    pub fn nu(&self) -> usize {
        self.imp.nu()
    }
    /// State names (`x1`, `x2`, … unless given).
    pub fn state_names(&self) -> Vec<String> {
        names(&self.spec.states, "x", self.nx())
    }
    /// Input names (`u1`, … unless given).
    pub fn input_names(&self) -> Vec<String> {
        names(&self.spec.inputs, "u", self.nu())
    }

    /// The plant rebuilt with its parameter record changed by `edit` (names kept).
    pub fn with_parameters(
        &self,
        edit: impl FnOnce(&mut toml::Table),
    ) -> Result<Self, CustomPlantError> {
        let mut t = self.spec.parameters.clone();
        edit(&mut t);
        let imp = self
            .imp
            .rebuild(&t)
            .map_err(|e| CustomPlantError::record(&self.spec.name, e))?;
        Self::build(self.spec.clone(), imp)
    }

    /// The names of the plant's numeric parameters (those a mismatch scenario can scale).
    pub fn numeric_parameter_names(&self) -> Vec<String> {
        self.spec
            .parameters
            .iter()
            .filter(|(_, v)| v.as_float().is_some())
            .map(|(k, _)| k.clone())
            .collect()
    }

    /// The plant with its numeric parameter `name` scaled by `factor`; `None` without it.
    pub fn with_parameter_scaled(&self, name: &str, factor: f64) -> Option<Self> {
        self.spec.parameters.get(name)?.as_float()?;
        self.with_parameters(|t| {
            let v = t[name].as_float().unwrap_or(f64::NAN);
            t.insert(name.to_string(), toml::Value::Float(v * factor));
        })
        .ok()
    }

    /// The plant with its parameter `mass`, else `m`, scaled by `factor` (model mismatch
    /// in closed-loop studies); `None` without such a number.
    pub fn with_mass_scaled(&self, factor: f64) -> Option<Self> {
        let key = ["mass", "m"].into_iter().find(|k| {
            self.spec
                .parameters
                .get(*k)
                .is_some_and(|v| v.as_float().is_some())
        })?;
        self.with_parameters(|t| {
            let v = t[key].as_float().unwrap_or(f64::NAN);
            t.insert(key.to_string(), toml::Value::Float(v * factor));
        })
        .ok()
    }

    /// The plant of a file's record, rebuilt from the prototype of the same name among
    /// `plants` (see the module doc): errors name the plant and the key.
    fn resolve(spec: CustomSpec, plants: &[CustomPlant]) -> Result<Self, CustomPlantError> {
        let err = |key: &str, reason: String| CustomPlantError {
            plant: spec.name.clone(),
            key: key.to_string(),
            reason,
            source: None,
        };
        let Some(proto) = plants.iter().find(|p| p.name() == spec.name) else {
            let known = if plants.is_empty() {
                "it has no custom plants".to_string()
            } else {
                let names: Vec<String> = plants.iter().map(|p| format!("`{}`", p.name())).collect();
                format!("its custom plants are {}", names.join(", "))
            };
            return Err(err(
                "system.kind",
                format!(
                    "version {} is implemented in Rust by the program that wrote this problem, \
                     and this program cannot rebuild it ({known}): read the file with that \
                     program (ProblemConfig::from_toml_str_with and the plant)",
                    spec.version
                ),
            ));
        };
        if proto.version() != spec.version {
            return Err(err(
                "system.version",
                format!(
                    "the file has version {}, this program's plant is version {}",
                    spec.version,
                    proto.version()
                ),
            ));
        }
        let mut params = proto.spec.parameters.clone();
        for (k, v) in &spec.parameters {
            if !params.contains_key(k) {
                let have: Vec<&str> = params.keys().map(String::as_str).collect();
                return Err(err(
                    &format!("system.parameters.{k}"),
                    format!(
                        "not a parameter of this plant (its parameters: {})",
                        have.join(", ")
                    ),
                ));
            }
            params.insert(k.clone(), v.clone());
        }
        let imp = proto
            .imp
            .rebuild(&params)
            .map_err(|e| CustomPlantError::record(&spec.name, e))?;
        let mut named = proto.spec.clone();
        for (key, file, own) in [
            ("system.states", &spec.states, &mut named.states),
            ("system.inputs", &spec.inputs, &mut named.inputs),
        ] {
            if !file.is_empty() && !own.is_empty() && file != own {
                return Err(err(
                    key,
                    format!("the file has {file:?}, the plant {own:?}"),
                ));
            }
            if own.is_empty() {
                own.clone_from(file);
            }
        }
        let p = Self::build(named, imp)?;
        if let (Some(file), Some(own)) = (&spec.fingerprint, &p.spec.fingerprint) {
            if file != own {
                return Err(err(
                    "system.fingerprint",
                    format!(
                        "the file's plant computed f(x, u) = {file} at the probe points, this \
                         program's computes {own}: the equations changed without a new version"
                    ),
                ));
            }
        }
        Ok(p)
    }
}

fn names(given: &[String], prefix: &str, n: usize) -> Vec<String> {
    if given.is_empty() {
        (1..=n).map(|i| format!("{prefix}{i}")).collect()
    } else {
        given.to_vec()
    }
}

/// f(x, u) at three fixed probe points (entries in (−0.45, 0.55), none zero), each value
/// with 9 significant digits, hashed: SHA-256, the first 16 hex digits.
fn fingerprint(p: &dyn ErasedPlant) -> String {
    let (nx, nu) = (p.nx(), p.nu());
    let mut text = String::new();
    let mut dx = vec![0.0; nx];
    for k in 0..3 {
        let z: Vec<f64> = (0..nx + nu)
            .map(|i| ((7 * i + 3 * k + 1) % 11) as f64 / 11.0 - 0.45)
            .collect();
        p.rhs_f64(&z[..nx], &z[nx..], &mut dx);
        for v in &dx {
            text += &format!("{v:.8e};");
        }
    }
    crate::io::hex(&Sha256::digest(text.as_bytes()))[..16].to_string()
}

impl From<CustomPlant> for CustomSpec {
    fn from(p: CustomPlant) -> CustomSpec {
        p.spec
    }
}

impl TryFrom<CustomSpec> for CustomPlant {
    type Error = CustomPlantError;
    fn try_from(spec: CustomSpec) -> Result<Self, CustomPlantError> {
        PLANTS.with(|p| Self::resolve(spec, &p.borrow()))
    }
}

impl PartialEq for CustomPlant {
    fn eq(&self, other: &Self) -> bool {
        self.spec == other.spec
    }
}

impl fmt::Debug for CustomPlant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CustomPlant")
            .field("spec", &self.spec)
            .finish()
    }
}

thread_local! {
    /// The plants a problem file being read on this thread may name (see the module doc).
    static PLANTS: RefCell<Vec<CustomPlant>> = const { RefCell::new(Vec::new()) };
}

/// Runs `read` with `plants` as the custom plants a problem file may name (restored after,
/// also on a panic).
pub(crate) fn reading_with<R>(plants: &[CustomPlant], read: impl FnOnce() -> R) -> R {
    struct Restore(Vec<CustomPlant>);
    impl Drop for Restore {
        fn drop(&mut self) {
            PLANTS.with(|p| *p.borrow_mut() = std::mem::take(&mut self.0));
        }
    }
    let _restore = Restore(PLANTS.with(|p| p.replace(plants.to_vec())));
    read()
}

#[cfg(test)]
#[path = "custom_tests.rs"]
mod tests;
