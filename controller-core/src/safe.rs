//! `safe`: the safety-augmented controller [`SafeController`] (Hose, Köhler, Zeilinger,
//! Trimpe, IEEE TCST 2025): a network proposes the MPC's whole input sequence, the device
//! checks it online with the nominal model and applies it only when it is feasible and no
//! worse than a safe candidate.
//!
//! ```text
//! state: ū = (ū_0 … ū_{N−1})  the sequence applied at the previous step (the "safe" one),
//!        or none yet
//! step(x):
//!   c  = Π_U(network(x)) = (Π_U(c_0) … Π_U(c_{N−1}))      candidate, each input clamped to
//!        its box (a candidate with a NaN or ±inf component is left as is: it fails)
//!   s  = (ū_1 … ū_{N−1}, κ_f(x̂_{N−1}))                    safe candidate: ū shifted by one,
//!        x̂_{N−1} = F^{N−1}(x; ū_1 … ū_{N−1})              completed by the terminal controller
//!   check(x, v): x_0 = x, x_{k+1} = F(x_k, v_k)           forward simulation (the plant's f32 RK4)
//!        feasible ⇔ Π_U(v_k) = v_k         (k = 0 … N−1)   input box, exact (no margin)
//!                  ∧ g_k(x_k, v_k) + m_s ≤ 0 (k = 0 … N−1)  the OCP's stage-k constraints, margin m_s
//!                  ∧ g_N(x_N) + m_f ≤ 0                   x_N: state box, terminal constraints and
//!                                                         the terminal set (x−x_ref)ᵀP(x−x_ref) ≤ α
//!                  ∧ J(x, v) finite
//!        J(x, v) = Σ_k ℓ(x_k, v_k) + V_f(x_N)
//!   apply c if c feasible ∧ (s infeasible ∨ J(x, c) ≤ J(x, s) ∨ J(x, c) ≤ β)   flag CANDIDATE
//!   else s                                                          flag FALLBACK
//!   u = Π_U(v_0); ū ← v  (shifted at the next step)
//!   β ← J(x, v) − σ·ℓ(x, v_0) if v passed its check and σ is set, else −∞
//! ```
//!
//! **The relaxed decrease** ([`SafeController::with_decrease`], σ ∈ (0, 1]; off by default:
//! β = −∞, the strict rule J(c) ≤ J(s)). In the nominal case the safe candidate satisfies
//! J(s) ≤ J_prev − ℓ(x_prev, u_prev) (the terminal decrease), so a fresh candidate rarely
//! beats a shifted optimal plan — it only has to match it within its own errors. Accepting
//! a feasible candidate whenever J(c) ≤ J_prev − σ·ℓ(x_prev, u_prev) keeps every step's
//! cost decrease at least σ·ℓ (each branch gives V_{t+1} ≤ V_t − σℓ_t with V_t the cost of
//! the sequence applied at t), hence Σ_t σ·ℓ(x_t, u_t) ≤ V_0 and convergence, with the
//! closed-loop cost at most V_0/σ (relaxed dynamic programming). Constraint satisfaction is
//! unaffected: the candidate still passes the full check. β is part of the controller's
//! state (the C API's `struct ampc_safe` carries it).
//!
//! **The feedback form of the candidate** ([`CandidateForm::Feedback`], the trainer's default
//! for sequence nets, `[training] sequence_form`): the network's entries c_1 … c_{N−1} are
//! offsets from the terminal controller along the simulated trajectory, not inputs:
//!
//! ```text
//!   v_0 = Π_U(c_0),   v_k = Π_U(κ_f(x̂_k) + c_k)  (k = 1 … N−1),   x̂_0 = x, x̂_{k+1} = F(x̂_k, v_k)
//! ```
//!
//! computed inside the check's forward simulation (one pass). The network's errors then
//! pass through the stabilised loop x⁺ = F(x, κ_f(x) + c) instead of the open-loop plant, so
//! an unstable plant's candidate still ends near x_ref (on the planar quadrotor, the
//! candidates of the training states that pass the check went from 9 of 6,000 in the open
//! form to 4,934). It changes no guarantee: the realised sequence v is what is checked,
//! applied and stored, exactly as an open candidate; κ_f only shapes the proposal (a gain
//! that differs from the trainer's makes worse candidates, never unsafe ones). With
//! [`CandidateForm::Open`] (the default of [`SafeController::new`]) v = Π_U(c).
//!
//! **The projection of the candidate.** A network fitted to MPC sequences that sit on an
//! input bound puts entries slightly beyond it; unprojected, such a candidate fails
//! `Π_U(v) = v` however good it is. The candidate is therefore clamped to U entry by entry
//! before the check. This does not weaken the check: the clamped sequence is what is
//! simulated, checked and (if chosen) applied and stored, so every guarantee below is about
//! the sequence actually used. A candidate with a non-finite component is not projected (Π_U
//! would turn NaN into u_ref): it fails the check, flag `NON_FINITE_CANDIDATE`.
//!
//! κ_f(x) = u_ref + K(x − x_ref) is projected onto the input box by [`Plant::project_input`]
//! (the identity inside the terminal set, where κ_f is admissible), so the stored sequence
//! stays finite whatever the state.
//!
//! **Initialisation.** Before a safe sequence exists, [`SafeController::init_with`] adopts a
//! sequence passed in (an MPC solution computed at the current state), if it passes the same
//! check. Otherwise the first feasible candidate becomes the safe sequence (flags
//! `CANDIDATE | INITIALISED`). Until then each step applies `Π_U(c_0)`, the candidate's first
//! input projected onto the input box (a non-finite component → the plant's reference input),
//! with the flag `NO_SAFE`: **nothing is guaranteed before a safe sequence exists** beyond an
//! input inside the box.
//!
//! **What it guarantees**, once a safe sequence exists: *deterministic for the nominal model:
//! constraint satisfaction and convergence*. If the plant evolves exactly as
//! [`Plant::step`] predicts (model match, including the f32 arithmetic of the simulation),
//! the state reached is the one the last check predicted, so the shifted sequence is feasible
//! again (its last step is the terminal controller inside a positively invariant terminal set
//! whose terminal cost decreases by at least the stage cost), and the applied sequence's cost
//! decreases by at least ℓ(x, u) per step: constraints hold at every step and Σ ℓ is bounded,
//! so the state converges to x_ref. This rests on
//! - **model match**: the plant on the device is the trainer's model (generated code, tested
//!   against its f64 model), and the real system follows it; under mismatch or disturbances
//!   the check still runs, but nothing is claimed (the flag `SAFE_INFEASIBLE` says when the
//!   fallback itself failed the check; it is applied all the same);
//! - **the terminal ingredients' tier**: invariance of {xᵀPx ≤ α} under κ_f and the decrease
//!   of V_f are as proven (or only sampled) as the terminal design that produced P, α, K;
//! - **the f32 margin**: the online check runs in f32; the margins `m_s`, `m_f` must cover the
//!   difference between the f32 simulation and the model the guarantee is stated for (see
//!   [`Margins`]). The cost comparison is in f32 too: convergence holds up to its rounding.
//!
//! `step` never panics, never allocates, uses no `unsafe`; for every bit pattern of the state
//! and of the candidate, the applied input is [`Plant::project_input`] of a finite input
//! (finite and inside the input box for a plant whose projection is).

use crate::mlp::Network;

/// The nominal model and the OCP's ingredients, in f32, as the online check needs them.
///
/// The generated plants implement it from the problem file; tests implement it by hand.
/// Every method must be total (no panic for any bit pattern); NaN results are treated as
/// "infeasible".
pub trait Plant<const NX: usize, const NU: usize> {
    /// x⁺ = F(x, u): one sampling period of the nominal model (RK4 with the OCP's sub-steps).
    fn step(&self, x: &[f32; NX], u: &[f32; NU]) -> [f32; NX];
    /// g_k(x, u) = max_i g_i(x, u) over the constraints the OCP imposes at stage `k` on
    /// (x_k, u_k) (normalised; `≤ 0` means admissible): the state box and state constraints
    /// from k = 1 on (x_0 is the measured state, which the OCP does not constrain), path
    /// constraints per the OCP's rule. The input box is not part of it: it is checked exactly
    /// through [`Plant::project_input`] (`Π_U(u) = u`), without a margin, since an input is
    /// applied as computed and a saturated input sits exactly on its bound.
    fn stage_violation(&self, k: usize, x: &[f32; NX], u: &[f32; NU]) -> f32;
    /// g_N(x): the constraints on the last state (normalised; `≤ 0` means admissible): the
    /// state box, the terminal constraints, and the terminal set
    /// (x − x_ref)ᵀ P (x − x_ref) ≤ α.
    fn terminal_violation(&self, x: &[f32; NX]) -> f32;
    /// κ_f(x) = u_ref + K (x − x_ref): the terminal controller.
    fn terminal_input(&self, x: &[f32; NX]) -> [f32; NU];
    /// Π_U(u): the projection onto the input box; a NaN component maps to the reference
    /// input's. Must return finite inputs for every `u`, and `u` itself exactly when `u` is
    /// inside the box.
    fn project_input(&self, u: &[f32; NU]) -> [f32; NU];
    /// ℓ(x, u): the OCP's stage cost.
    fn stage_cost(&self, x: &[f32; NX], u: &[f32; NU]) -> f32;
    /// V_f(x): the OCP's terminal cost.
    fn terminal_cost(&self, x: &[f32; NX]) -> f32;
}

/// Where the candidate sequence comes from: `x ↦ (c_0 … c_{N−1})`.
pub trait SequenceSource<const NX: usize, const NU: usize, const N: usize> {
    /// The candidate input sequence for state `x`.
    fn sequence(&self, x: &[f32; NX]) -> [[f32; NU]; N];
}

/// A network whose `M = N·nu` outputs are the input sequence, step-major
/// (`c_0[0], …, c_0[nu−1], c_1[0], …`).
///
/// If `M ≠ N·nu`, missing entries are NaN (so the candidate never passes the check) and
/// surplus outputs are ignored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SequenceNet<Net>(pub Net);

impl<const NX: usize, const NU: usize, const N: usize, const M: usize, Net>
    SequenceSource<NX, NU, N> for SequenceNet<Net>
where
    Net: Network<NX, Output = [f32; M]>,
{
    fn sequence(&self, x: &[f32; NX]) -> [[f32; NU]; N] {
        let y = self.0.forward(x);
        let mut s = [[f32::NAN; NU]; N];
        for (d, v) in s.as_flattened_mut().iter_mut().zip(y.iter()) {
            *d = *v;
        }
        s
    }
}

/// How a candidate's entries become the input sequence that is checked (module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CandidateForm {
    /// The entries are the inputs: v_k = Π_U(c_k).
    #[default]
    Open,
    /// c_0 is the first input, c_1 … c_{N−1} offsets from the terminal controller along the
    /// simulated trajectory: v_0 = Π_U(c_0), v_k = Π_U(κ_f(x̂_k) + c_k).
    Feedback,
}

/// Bit set of what one [`SafeController::step`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SafeFlags(pub u8);

impl SafeFlags {
    /// Nothing to report (not returned by `step`: it always sets one of `CANDIDATE`,
    /// `FALLBACK`, `NO_SAFE`).
    pub const EMPTY: SafeFlags = SafeFlags(0);
    /// The network's candidate passed the check and was applied.
    pub const CANDIDATE: SafeFlags = SafeFlags(1);
    /// The safe candidate (last sequence shifted, completed by κ_f) was applied.
    pub const FALLBACK: SafeFlags = SafeFlags(2);
    /// No safe sequence exists yet and the candidate failed the check: the applied input is
    /// the candidate's first, projected onto the input box; nothing is guaranteed.
    pub const NO_SAFE: SafeFlags = SafeFlags(4);
    /// This step adopted its first safe sequence (the candidate, with `CANDIDATE`).
    pub const INITIALISED: SafeFlags = SafeFlags(8);
    /// The safe candidate failed the check (model mismatch, a disturbance, or a margin too
    /// small): applied all the same if the network's candidate failed too; no guarantee.
    pub const SAFE_INFEASIBLE: SafeFlags = SafeFlags(16);
    /// A state component was NaN or ±inf (every check then fails).
    pub const NON_FINITE_STATE: SafeFlags = SafeFlags(32);
    /// A candidate component was NaN or ±inf (the candidate is then not projected onto U
    /// and fails the check).
    pub const NON_FINITE_CANDIDATE: SafeFlags = SafeFlags(64);

    /// Whether every flag in `other` is set.
    ///
    /// ```
    /// use controller_core::safe::SafeFlags;
    /// assert!(SafeFlags(3).contains(SafeFlags::FALLBACK));
    /// ```
    pub const fn contains(self, other: SafeFlags) -> bool {
        self.0 & other.0 == other.0
    }

    /// The union of both sets.
    pub const fn union(self, other: SafeFlags) -> SafeFlags {
        SafeFlags(self.0 | other.0)
    }
}

/// The margins of the online check: a sequence passes only if every state or path
/// constraint holds with `stage` to spare and the terminal state is inside the terminal set with `terminal`
/// to spare (in the units of [`Plant::stage_violation`] and [`Plant::terminal_violation`]).
///
/// They cover the difference between the f32 simulation on the device and the model the
/// guarantee is stated for; the exporter derives them from the measured difference between
/// the generated f32 plant and the trainer's f64 model (and says how).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Margins {
    /// m_s ≥ 0, subtracted from every stage constraint.
    pub stage: f32,
    /// m_f ≥ 0, subtracted from the terminal set's level α.
    pub terminal: f32,
}

/// The result of checking one sequence from one state (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Check {
    /// Whether every constraint (with its margin), the terminal set and a finite cost hold.
    pub feasible: bool,
    /// J(x, v) = Σ ℓ + V_f (+∞ when infeasible).
    pub cost: f32,
}

impl Check {
    const INFEASIBLE: Check = Check {
        feasible: false,
        cost: f32::INFINITY,
    };
}

/// Result of [`SafeController::step`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SafeOutput<const NU: usize> {
    /// The input to apply (`Plant::project_input` of the chosen sequence's first input).
    pub u: [f32; NU],
    /// What happened.
    pub flags: SafeFlags,
    /// J of the network's candidate (+∞ if it failed the check).
    pub candidate_cost: f32,
    /// J of the safe candidate (+∞ if it failed or no safe sequence existed).
    pub safe_cost: f32,
}

/// Why [`SafeController::init_with`] did not adopt a sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InitRejected {
    /// The sequence fails the online check from the given state (a constraint with its
    /// margin, the terminal set, or a non-finite cost).
    Infeasible,
}

/// Why a set of margins is not usable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InvalidMargins {
    /// A margin is NaN, infinite or negative.
    NotFiniteNonNegative,
    /// The relaxed decrease σ is not in (0, 1].
    Decrease,
}

/// The safety-augmented controller: plant, candidate source, margins and the last safe
/// sequence (fixed-size, no heap). See the module doc for the algorithm and its guarantee.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SafeController<P, S, const NX: usize, const NU: usize, const N: usize> {
    /// The nominal model and the OCP's ingredients.
    pub plant: P,
    /// The candidate source (the sequence network).
    pub source: S,
    /// The margins of the online check.
    pub margins: Margins,
    /// How the candidate's entries become inputs (default [`CandidateForm::Open`]).
    pub form: CandidateForm,
    /// σ of the relaxed decrease (module doc); `None`: the strict rule J(c) ≤ J(s).
    pub decrease: Option<f32>,
    /// β = J_prev − σ·ℓ(x_prev, u_prev), −∞ when not applicable.
    bound: f32,
    /// The sequence applied at the last step (shifted at the next), if any.
    safe: Option<[[f32; NU]; N]>,
}

impl<P, S, const NX: usize, const NU: usize, const N: usize> SafeController<P, S, NX, NU, N>
where
    P: Plant<NX, NU>,
{
    /// A controller without a safe sequence yet (see the module doc's initialisation).
    pub const fn new(plant: P, source: S, margins: Margins) -> Self {
        Self {
            plant,
            source,
            margins,
            form: CandidateForm::Open,
            decrease: None,
            bound: f32::NEG_INFINITY,
            safe: None,
        }
    }

    /// The same controller with the relaxed decrease σ (module doc; σ ∈ (0, 1], checked by
    /// [`Self::validate`]).
    pub const fn with_decrease(mut self, sigma: f32) -> Self {
        self.decrease = Some(sigma);
        self
    }

    /// β, the cost bound a candidate may meet instead of the safe candidate's cost (−∞ when
    /// none: no safe sequence, a failed check, or the strict rule).
    pub const fn bound(&self) -> f32 {
        self.bound
    }

    /// The same controller with candidates of form `form` (module doc).
    pub const fn with_form(mut self, form: CandidateForm) -> Self {
        self.form = form;
        self
    }

    /// Checks that both margins are finite and ≥ 0.
    pub const fn validate(&self) -> Result<(), InvalidMargins> {
        let (s, t) = (self.margins.stage, self.margins.terminal);
        if !(s.is_finite() && t.is_finite() && s >= 0.0 && t >= 0.0) {
            return Err(InvalidMargins::NotFiniteNonNegative);
        }
        match self.decrease {
            Some(sigma) if !(sigma > 0.0 && sigma <= 1.0) => Err(InvalidMargins::Decrease),
            _ => Ok(()),
        }
    }

    /// The sequence applied at the last step (unshifted), if a safe sequence exists.
    pub const fn safe_sequence(&self) -> Option<&[[f32; NU]; N]> {
        self.safe.as_ref()
    }

    /// Forgets the safe sequence (e.g. after a reset of the plant).
    pub fn reset(&mut self) {
        self.safe = None;
        self.bound = f32::NEG_INFINITY;
    }

    /// Puts back a safe sequence kept elsewhere (what [`Self::safe_sequence`] returned after
    /// the last step, e.g. across the C API, whose caller holds the controller's memory).
    /// Not checked here: the next `step` checks the shifted sequence from the state it is
    /// given like any other, and flags [`SafeFlags::SAFE_INFEASIBLE`] when it fails — so a
    /// sequence that is not the one last returned voids the guarantee but is never applied
    /// unflagged.
    /// β is unknown afterwards (−∞: the strict rule for the next step); see
    /// [`Self::restore_with_bound`].
    pub fn restore(&mut self, sequence: Option<[[f32; NU]; N]>) {
        self.restore_with_bound(sequence, f32::NEG_INFINITY);
    }

    /// [`Self::restore`] with the bound β that [`Self::bound`] returned after the last step.
    /// A β that is not the one returned changes which candidates are accepted (a larger one
    /// voids the convergence argument, never the constraint check); NaN acts as −∞.
    pub fn restore_with_bound(&mut self, sequence: Option<[[f32; NU]; N]>, bound: f32) {
        self.safe = sequence;
        self.bound = if sequence.is_some() {
            bound
        } else {
            f32::NEG_INFINITY
        };
    }

    /// β after applying the feasible sequence `v` (cost `cost`) at `x`.
    fn next_bound(&self, x: &[f32; NX], v: &[[f32; NU]; N], cost: f32) -> f32 {
        match (self.decrease, v.first()) {
            (Some(sigma), Some(v0)) => cost - sigma * self.plant.stage_cost(x, v0),
            _ => f32::NEG_INFINITY,
        }
    }

    /// Adopts `sequence` (an MPC solution at state `x`) as the safe sequence, as if it had
    /// been applied at `x`, if it passes the online check from `x`; its first input is what
    /// the caller applies at `x`. Returns its cost. Nothing changes on rejection.
    pub fn init_with(
        &mut self,
        x: &[f32; NX],
        sequence: &[[f32; NU]; N],
    ) -> Result<f32, InitRejected> {
        let mut v = *sequence;
        let c = self.check(x, &mut v, false);
        if c.feasible {
            self.safe = Some(v);
            self.bound = self.next_bound(x, &v, c.cost);
            Ok(c.cost)
        } else {
            Err(InitRejected::Infeasible)
        }
    }

    /// Checks the sequence `v` from `x` (module doc). With `complete`, its last input is
    /// first set to `Π_U(κ_f(x_{N−1}))`. Always simulates all N steps (the same work whether
    /// or not a constraint fails, and the completed entry is always written).
    pub fn check(&self, x: &[f32; NX], v: &mut [[f32; NU]; N], complete: bool) -> Check {
        self.check_as(x, v, complete, false)
    }

    /// [`Self::check`]; with `feedback`, entries 1 … N−1 of `v` are first realised as
    /// `Π_U(κ_f(x̂_k) + v_k)` along the simulation (a non-finite entry is left unprojected, so
    /// it fails), and `v` holds the realised sequence on return.
    fn check_as(
        &self,
        x: &[f32; NX],
        v: &mut [[f32; NU]; N],
        complete: bool,
        feedback: bool,
    ) -> Check {
        let mut xk = *x;
        let mut cost = 0.0f32;
        let mut ok = true;
        let last = N.wrapping_sub(1);
        for (k, u) in v.iter_mut().enumerate() {
            if complete && k == last {
                *u = self.plant.project_input(&self.plant.terminal_input(&xk));
            } else if feedback && k >= 1 {
                *u = realise(&self.plant, &xk, u);
            }
            // The input box, exactly (a NaN input is projected elsewhere, so it fails).
            ok &= self.plant.project_input(u) == *u;
            // NaN compares false: a NaN constraint value fails.
            ok &= self.plant.stage_violation(k, &xk, u) + self.margins.stage <= 0.0;
            cost += self.plant.stage_cost(&xk, u);
            xk = self.plant.step(&xk, u);
        }
        ok &= self.plant.terminal_violation(&xk) + self.margins.terminal <= 0.0;
        cost += self.plant.terminal_cost(&xk);
        if ok && cost.is_finite() {
            Check {
                feasible: true,
                cost,
            }
        } else {
            Check::INFEASIBLE
        }
    }

    /// One control step with the candidate from the controller's source.
    pub fn step(&mut self, x: &[f32; NX]) -> SafeOutput<NU>
    where
        S: SequenceSource<NX, NU, N>,
    {
        let candidate = self.source.sequence(x);
        self.step_with(x, candidate)
    }

    /// One control step with a candidate given by the caller (module doc). Never panics
    /// (checked with `#[no_panic]` under the `no-panic` feature, for the plants it is
    /// instantiated with in a release build: `tests/safe_closed_loop.rs`).
    #[cfg_attr(feature = "no-panic", no_panic::no_panic)]
    pub fn step_with(&mut self, x: &[f32; NX], mut candidate: [[f32; NU]; N]) -> SafeOutput<NU> {
        let mut flags = SafeFlags::EMPTY;
        if !x.iter().all(|v| v.is_finite()) {
            flags = flags.union(SafeFlags::NON_FINITE_STATE);
        }
        if candidate.as_flattened().iter().all(|v| v.is_finite()) {
            // Π_U on each input: a finite candidate is clamped to the input box before the
            // check (which then simulates the clamped sequence like any other).
            // (In the feedback form only c_0 is an input; the offsets are projected after
            // κ_f is added, in `check_as`.)
            let inputs = if self.form == CandidateForm::Feedback {
                1
            } else {
                N
            };
            for u in candidate.iter_mut().take(inputs) {
                *u = self.plant.project_input(u);
            }
        } else {
            flags = flags.union(SafeFlags::NON_FINITE_CANDIDATE);
        }
        let feedback = self.form == CandidateForm::Feedback;
        let c = self.check_as(x, &mut candidate, false, feedback);
        let Some(previous) = self.safe else {
            if c.feasible {
                self.safe = Some(candidate);
                self.bound = self.next_bound(x, &candidate, c.cost);
                return self.output(
                    &candidate,
                    flags
                        .union(SafeFlags::CANDIDATE)
                        .union(SafeFlags::INITIALISED),
                    c.cost,
                    f32::INFINITY,
                );
            }
            return self.output(
                &candidate,
                flags.union(SafeFlags::NO_SAFE),
                c.cost,
                f32::INFINITY,
            );
        };
        // ū shifted by one; its last entry is completed inside `check`.
        let mut shifted: [[f32; NU]; N] =
            core::array::from_fn(|k| previous.get(k + 1).copied().unwrap_or([0.0; NU]));
        let s = self.check(x, &mut shifted, true);
        if !s.feasible {
            flags = flags.union(SafeFlags::SAFE_INFEASIBLE);
        }
        let (chosen, flag, cost) =
            if c.feasible && (!s.feasible || c.cost <= s.cost || c.cost <= self.bound) {
                (candidate, SafeFlags::CANDIDATE, c.cost)
            } else {
                (shifted, SafeFlags::FALLBACK, s.cost)
            };
        // β only after a sequence that passed its check (an infeasible fallback has cost +∞).
        self.bound = if cost.is_finite() {
            self.next_bound(x, &chosen, cost)
        } else {
            f32::NEG_INFINITY
        };
        self.safe = Some(chosen);
        self.output(&chosen, flags.union(flag), c.cost, s.cost)
    }

    fn output(&self, v: &[[f32; NU]; N], flags: SafeFlags, cand: f32, safe: f32) -> SafeOutput<NU> {
        let first = v.first().copied().unwrap_or([f32::NAN; NU]);
        SafeOutput {
            u: self.plant.project_input(&first),
            flags,
            candidate_cost: cand,
            safe_cost: safe,
        }
    }
}

/// v = Π_U(κ_f(x) + c) for a finite result; the unprojected sum otherwise (a NaN or ±inf
/// entry, or a non-finite κ_f, must fail the box check rather than be mapped into U).
fn realise<P: Plant<NX, NU>, const NX: usize, const NU: usize>(
    plant: &P,
    x: &[f32; NX],
    c: &[f32; NU],
) -> [f32; NU] {
    let kf = plant.terminal_input(x);
    let mut w = *c;
    for (w, k) in w.iter_mut().zip(kf.iter()) {
        *w += *k;
    }
    if w.iter().all(|v| v.is_finite()) {
        plant.project_input(&w)
    } else {
        w
    }
}

pub mod example;
pub mod fmath;

#[cfg(test)]
mod tests;
