/*
 * ampc_safe.h: C interface of the safety-augmented controller compiled into libampc_capi.a
 * (controller-core/capi, module `safe`): the safe controller written by `trainer export
 * --safe-rs` for `pendulum_ode` (default: tests/fixtures/safe-controller/pendulum_ode_safe.rs)
 * or, when the library is built with the cargo feature `safe-planar-quadrotor` and this
 * header is included with AMPC_SAFE_PLANAR_QUADROTOR defined, for the planar quadrotor
 * (planar_quadrotor_safe.rs). Its sequence network proposes the MPC's input sequence, the
 * f32 plant checks it online over AMPC_SAFE_N steps against the last safe sequence shifted by
 * one step (controller_core::safe).
 *
 * Guarantee, once a safe sequence exists (flag CANDIDATE or FALLBACK without
 * SAFE_INFEASIBLE): deterministic for the nominal model: constraint satisfaction and
 * convergence. It rests on model match (the plant follows the generated f32 model), the
 * terminal set (invariance sampled; decrease "not established" for this pendulum, sampled
 * for the quadrotor) and the f32 margins (estimated). Nothing is guaranteed while
 * NO_SAFE is returned beyond an input inside the input box.
 * Plain C99; no allocation, no global state: the caller owns struct ampc_safe.
 */
#ifndef AMPC_SAFE_H
#define AMPC_SAFE_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* State dimension, input dimension and horizon of the compiled-in safe controller (the
   library's: a mismatch with the library's feature is caught by tests/c_api.rs, not by C). */
#ifdef AMPC_SAFE_PLANAR_QUADROTOR
#define AMPC_SAFE_NX 6
#define AMPC_SAFE_NU 2
#define AMPC_SAFE_N 20
#else
#define AMPC_SAFE_NX 2
#define AMPC_SAFE_NU 1
#define AMPC_SAFE_N 20
#endif

/* Flag bits returned by ampc_safe_step (controller_core::safe::SafeFlags). */
/* The network's candidate passed the check and was applied. */
#define AMPC_SAFE_FLAG_CANDIDATE 0x01u
/* The safe candidate (last sequence shifted, completed by the terminal controller) was applied. */
#define AMPC_SAFE_FLAG_FALLBACK 0x02u
/* No safe sequence yet and the candidate failed: u is its first input projected onto the
   input box; nothing is guaranteed. */
#define AMPC_SAFE_FLAG_NO_SAFE 0x04u
/* This step adopted the first safe sequence (with CANDIDATE). */
#define AMPC_SAFE_FLAG_INITIALISED 0x08u
/* The safe candidate failed its check (model mismatch, disturbance, altered memory): no
   guarantee for this step. */
#define AMPC_SAFE_FLAG_SAFE_INFEASIBLE 0x10u
/* A state component was NaN or infinite (or x/s was NULL). */
#define AMPC_SAFE_FLAG_NON_FINITE_STATE 0x20u
/* A candidate component was NaN or infinite. */
#define AMPC_SAFE_FLAG_NON_FINITE_CANDIDATE 0x40u
/* s, x or u was NULL (see ampc_safe_step). */
#define AMPC_SAFE_FLAG_NULL_ARGUMENT 0x80u

/* The controller's memory: the sequence applied at the last step. Initialise it with
   ampc_safe_init; do not alter it between steps (an altered sequence is re-checked and
   flagged SAFE_INFEASIBLE if it fails, never applied unflagged). */
struct ampc_safe {
    float sequence[AMPC_SAFE_N][AMPC_SAFE_NU];
    /* The relaxed decrease's bound (controller_core SafeController::bound; -INFINITY when
       none). A larger value accepts costlier candidates: do not alter it. */
    float bound;
    /* 0: no safe sequence yet. */
    uint8_t has_safe;
};

/* Forget the safe sequence. Returns 0, or AMPC_SAFE_FLAG_NULL_ARGUMENT if s is NULL. */
uint8_t ampc_safe_init(struct ampc_safe *s);

/* Adopt sequence (e.g. the MPC's solution at x) as the safe sequence if it passes the
 * online check from x, as if applied at x (the caller applies sequence[0] at x).
 * Returns 0 when adopted; AMPC_SAFE_FLAG_SAFE_INFEASIBLE when rejected (NaN, outside the
 * input box, a constraint or the terminal set violated); AMPC_SAFE_FLAG_NULL_ARGUMENT if an
 * argument is NULL. s changes only when the sequence is adopted. */
uint8_t ampc_safe_init_with(struct ampc_safe *s, const float x[AMPC_SAFE_NX],
                            const float sequence[AMPC_SAFE_N][AMPC_SAFE_NU]);

/* Write the terminal controller's rollout from x (v_k = the input box's projection of
 * kappa_f(x_k), x_{k+1} = the f32 model's step): a safe sequence when x lies well inside the
 * terminal set, e.g. to initialise near the set point. Returns 0;
 * AMPC_SAFE_FLAG_NULL_ARGUMENT if x or sequence is NULL (nothing written);
 * AMPC_SAFE_FLAG_NON_FINITE_STATE for a NaN/inf state (written, inside the box, meaningless). */
uint8_t ampc_safe_terminal_sequence(const float x[AMPC_SAFE_NX],
                                    float sequence[AMPC_SAFE_N][AMPC_SAFE_NU]);

/* One control step at state x: writes the input u, updates s, returns the flag bits.
 * u NULL: nothing read or written, returns AMPC_SAFE_FLAG_NULL_ARGUMENT.
 * s or x NULL: u = the plant's reference input, s unchanged, returns
 *   AMPC_SAFE_FLAG_NULL_ARGUMENT | AMPC_SAFE_FLAG_NON_FINITE_STATE.
 * x with a NaN/inf component: flag NON_FINITE_STATE, u finite and inside the input box. */
uint8_t ampc_safe_step(struct ampc_safe *s, const float x[AMPC_SAFE_NX], float u[AMPC_SAFE_NU]);

#ifdef __cplusplus
}
#endif

#endif /* AMPC_SAFE_H */
