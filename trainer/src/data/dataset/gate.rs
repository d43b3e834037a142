//! Whether a dataset's labels can carry a certificate, and why a state has no label.
//!
//! ```text
//! certifiable(D)  ⇔  #{labelled records} ≥ 1  ∧  no record is `numerical_failure`
//!                    ∧  every labelled record's u, ∂κ/∂x and cost are finite
//!                       (∂κ/∂x and the cost may be absent — NaN — in imported labels)
//! ```
//! A `numerical_failure` means that the MPC law could not be evaluated at that state — most
//! often because the plant's arithmetic is not finite there (`log` or `sqrt` of a negative
//! number, a division by zero; the label gate of [`crate::mpc::finite`]). Theorem 1 bounds
//! κ − κ_NN over X from labels and a Lipschitz constant of κ on X; where κ is not even
//! defined no such bound exists, so the whole dataset is refused rather than certified on the
//! states that happened to work. (`max_iterations` and `infeasible` states stay allowed: the
//! covering radius is then computed over the labelled states only.) A labelled record with a
//! non-finite value can only come from a file written before the gate existed.
//!
//! [`Dataset::check_labels_for`] refines the refusal with the problem at hand: a
//! `numerical_failure` state is refused only where the plant's own arithmetic fails —
//! F(x, u) not finite for u at U's lower corner, upper corner or centre. Where F is finite
//! at the state, the breakdown happened along the solver's iterates (as in a region where
//! the plant runs away and the OCP has no solution): κ is as undefined there as at an
//! `infeasible` state, and the state is treated like one — unlabelled, left out, reported.

use super::{Dataset, Record};
use crate::mpc::finite::Failure;
use crate::mpc::law::MpcLaw;
use crate::mpc::sqp::SqpStatus;
use crate::problem::ProblemConfig;

/// Why a dataset's labels cannot carry a certificate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LabelsError {
    /// No record has a label.
    #[error(
        "the dataset holds no labelled state ({failed} numerical_failure, {unlabelled} other \
         unlabelled, of {total}): there is nothing to certify"
    )]
    NoLabels {
        /// All records.
        total: usize,
        /// Of which `numerical_failure`.
        failed: usize,
        /// Of which otherwise unlabelled (`infeasible`, `max_iterations`).
        unlabelled: usize,
    },
    /// Some records are `numerical_failure`.
    #[error(
        "{count} of {total} states are numerical_failure (the first: record {index}, \
         x = {x}): the MPC law could not be evaluated there (non-finite arithmetic in the \
         plant's equations, or a solver breakdown), so no bound over X rests on this dataset; \
         fix the model (or the domain X) and relabel"
    )]
    NumericalFailures {
        /// Number of `numerical_failure` records.
        count: usize,
        /// All records.
        total: usize,
        /// The plan index of the first.
        index: u64,
        /// Its state.
        x: String,
    },
    /// A labelled record holds a non-finite value.
    #[error("record {index} (x = {x}) is labelled `{status}` but its {what} is not finite")]
    NonFiniteLabel {
        /// Its plan index.
        index: u64,
        /// Its state.
        x: String,
        /// Its status.
        status: String,
        /// `u`, `du_dx` or `cost`.
        what: String,
    },
}

fn state(r: &Record) -> String {
    format!("{:?}", r.x)
}

impl Dataset {
    /// The gate of the module doc; returns the number of labelled records.
    pub fn check_labels(&self) -> Result<usize, LabelsError> {
        let total = self.records.len();
        let failed: Vec<&Record> = self
            .records
            .iter()
            .filter(|r| r.status == SqpStatus::NumericalFailure)
            .collect();
        let labelled = self.records.iter().filter(|r| r.is_labelled()).count();
        if labelled == 0 {
            return Err(LabelsError::NoLabels {
                total,
                failed: failed.len(),
                unlabelled: total - failed.len(),
            });
        }
        if let Some(first) = failed.first() {
            return Err(LabelsError::NumericalFailures {
                count: failed.len(),
                total,
                index: first.index,
                x: state(first),
            });
        }
        // Labels imported without Jacobian columns store ∂κ/∂x as NaN ("absent": training
        // drops the Jacobian term there), and imported labels may lack a cost (NaN: no
        // bound uses it); u must always be finite.
        let jacobian_absent = self.labels.as_ref().is_some_and(|l| !l.jacobian);
        let imported = self.labels.is_some();
        for r in self.records.iter().filter(|r| r.is_labelled()) {
            let what = if r.u.iter().any(|v| !v.is_finite()) {
                "u"
            } else if !jacobian_absent && r.du_dx.iter().any(|v| !v.is_finite()) {
                "du_dx"
            } else if !imported && !r.cost.is_finite() {
                "cost"
            } else {
                continue;
            };
            return Err(LabelsError::NonFiniteLabel {
                index: r.index,
                x: state(r),
                status: r.status.as_str().into(),
                what: what.into(),
            });
        }
        Ok(labelled)
    }

    /// The gate with the problem (module doc): a `numerical_failure` record is refused only
    /// where the plant step F(x, u) of `cfg` is not finite at its state for u at U's
    /// corners or centre; the others count as unlabelled. Returns the labelled count.
    pub fn check_labels_for(&self, cfg: &ProblemConfig) -> Result<usize, LabelsError> {
        let model = crate::problem::model::Discrete::new(
            cfg.system.clone(),
            cfg.ocp.ts,
            cfg.ocp.rk4_substeps,
        );
        let (lo, hi) = (&cfg.ocp.u_lo, &cfg.ocp.u_hi);
        let mid: Vec<f64> = lo.iter().zip(hi).map(|(a, b)| 0.5 * (a + b)).collect();
        let nx = cfg.system.nx();
        let mut next = vec![0.0; nx];
        let mut plant_fails = |x: &[f64]| {
            [lo.as_slice(), hi.as_slice(), mid.as_slice()]
                .iter()
                .filter(|u| u.iter().all(|v| v.is_finite()))
                .any(|u| {
                    model.step(x, u, &mut next);
                    next.iter().any(|v| !v.is_finite())
                })
        };
        let mut refused = self.clone();
        refused.records.retain(|r| {
            r.status != SqpStatus::NumericalFailure || r.x.len() != nx || plant_fails(&r.x)
        });
        let dropped = self.records.len() - refused.records.len();
        match refused.check_labels() {
            Err(LabelsError::NumericalFailures {
                count, index, x, ..
            }) => Err(LabelsError::NumericalFailures {
                count,
                total: self.records.len(),
                index,
                x,
            }),
            Err(LabelsError::NoLabels {
                total,
                failed,
                unlabelled,
            }) => Err(LabelsError::NoLabels {
                total: total + dropped,
                failed: failed + dropped,
                unlabelled,
            }),
            other => other,
        }
    }

    /// The first `numerical_failure` record and why it has no label: the failure of a cold
    /// solve at its state (one solve; the record itself does not store the reason, so the
    /// file format stays as it is). `None` if there is no such record.
    pub fn first_failure(&self, cfg: &ProblemConfig) -> Option<(u64, Vec<f64>, Option<Failure>)> {
        let r = self
            .records
            .iter()
            .find(|r| r.status == SqpStatus::NumericalFailure)?;
        let label = MpcLaw::new(cfg).solve(&r.x, None).0;
        Some((r.index, r.x.clone(), label.failure()))
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Header, CHUNK, FORMAT_VERSION, MAGIC};
    use super::*;
    use crate::problem::SamplingSettings;

    fn data(statuses: &[SqpStatus]) -> Dataset {
        Dataset {
            magic: MAGIC,
            version: FORMAT_VERSION,
            header: Header {
                problem: "p".into(),
                problem_hash: "h".into(),
                config_toml: String::new(),
                nx: 2,
                nu: 1,
                sampling: SamplingSettings::default(),
                total: statuses.len() as u64,
                shard: None,
                chunk: CHUNK as u32,
            },
            records: statuses
                .iter()
                .enumerate()
                .map(|(i, &status)| {
                    let v = if status.is_labelled() { 1.0 } else { f64::NAN };
                    Record {
                        index: i as u64,
                        x: vec![0.5, i as f64],
                        u: vec![v],
                        du_dx: vec![v, v],
                        cost: v,
                        status,
                        iterations: 3,
                        kkt: 1e-9,
                        degeneracy: None,
                        max_slack: 0.0,
                        seq: Vec::new(),
                    }
                })
                .collect(),
            labels: None,
            disagree: Vec::new(),
        }
    }

    #[test]
    fn no_labels_numerical_failures_and_non_finite_labels_are_refused() {
        use SqpStatus::*;
        assert_eq!(
            data(&[Converged, Soft, MaxIterations]).check_labels(),
            Ok(2)
        );
        assert!(matches!(
            data(&[NumericalFailure, NumericalFailure]).check_labels(),
            Err(LabelsError::NoLabels {
                total: 2,
                failed: 2,
                ..
            })
        ));
        let e = data(&[Converged, NumericalFailure, Converged, NumericalFailure])
            .check_labels()
            .unwrap_err();
        assert!(matches!(
            e,
            LabelsError::NumericalFailures {
                count: 2,
                index: 1,
                ..
            }
        ));
        assert!(e.to_string().contains("x = [0.5, 1.0]"), "{e}");
        let mut d = data(&[Converged, Converged]);
        d.records[1].du_dx[0] = f64::NAN;
        assert!(matches!(
            d.check_labels(),
            Err(LabelsError::NonFiniteLabel { index: 1, ref what, .. }) if what == "du_dx"
        ));
    }
}
