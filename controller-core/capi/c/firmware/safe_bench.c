/*
 * C measurement firmware of the safety-augmented step (ampc_safe.h) in QEMU, on the
 * Cortex-M4F (mps2-an386, startup.c + mps2_an386.ld) or the Cortex-M0 (microbit,
 * startup.c + microbit.ld), for the controller compiled into the library: the pendulum's, or
 * the planar quadrotor's (library feature safe-planar-quadrotor, -DAMPC_SAFE_PLANAR_QUADROTOR).
 *
 * Like the Rust firmware (firmware-example safe-bench): a safe sequence is adopted first —
 * ampc_safe_init_with the terminal controller's rollout from the first state
 * (ampc_safe_terminal_sequence) — so every measured step checks both the network's candidate
 * and the shifted safe sequence over all AMPC_SAFE_N steps. Then SAFE_CALLS steps of
 * ampc_safe_step over four states near the set point, the controller's memory kept between
 * steps. Prints "calls=<n> init=<1 if adopted> flags_sum=<sum of flags> u_sum_bits=<sum of
 * the bits of every u>" and exits 0. Build it twice, -DSAFE_CALLS=1 and -DSAFE_CALLS=<1+K>,
 * and count instructions with firmware-example/tools/insn_count.c: per step =
 * (c(1+K) - c(1))/K (tests/c_api.rs).
 */
#include <stdint.h>
#include <string.h>
#include <unistd.h>

#include "ampc_safe.h"

#ifndef SAFE_CALLS
#define SAFE_CALLS 1
#endif

static int put(const char *s, size_t n) {
    return write(1, s, n) == (ssize_t)n;
}

static size_t dec(char *out, uint32_t v) {
    char tmp[12];
    size_t n = 0, i;
    do {
        tmp[n++] = (char)('0' + v % 10u);
        v /= 10u;
    } while (v != 0u);
    for (i = 0; i < n; i++) {
        out[i] = tmp[n - 1 - i];
    }
    return n;
}

static uint32_t bits_of(float v) {
    uint32_t b;
    memcpy(&b, &v, sizeof b);
    return b;
}

static size_t field(char *out, const char *label, uint32_t v) {
    size_t n = strlen(label);
    memcpy(out, label, n);
    return n + dec(out + n, v);
}

/* The measurement states (the Rust firmware's). */
#ifdef AMPC_SAFE_PLANAR_QUADROTOR
static const float states[4][AMPC_SAFE_NX] = {{0.05f, -0.05f, 0.02f, 0.0f, 0.05f, 0.0f},
                                              {0.04f, -0.04f, 0.015f, 0.01f, 0.04f, 0.0f},
                                              {-0.05f, 0.05f, -0.02f, 0.0f, -0.05f, 0.01f},
                                              {0.02f, 0.01f, 0.0f, -0.01f, 0.0f, 0.0f}};
#else
static const float states[4][AMPC_SAFE_NX] = {
    {0.1f, -0.1f}, {0.05f, 0.1f}, {-0.1f, 0.05f}, {0.02f, -0.02f}};
#endif

int main(void) {
    struct ampc_safe s;
    float seq[AMPC_SAFE_N][AMPC_SAFE_NU];
    float u[AMPC_SAFE_NU];
    uint32_t flags_sum = 0u, u_sum = 0u, init;
    unsigned i, j;
    char line[112];
    size_t n = 0;
    ampc_safe_init(&s);
    ampc_safe_terminal_sequence(states[0], seq);
    init = ampc_safe_init_with(&s, states[0], (const float(*)[AMPC_SAFE_NU])seq) == 0u;
    for (i = 0; i < SAFE_CALLS; i++) {
        flags_sum += ampc_safe_step(&s, states[i % 4u], u);
        for (j = 0; j < AMPC_SAFE_NU; j++) {
            u_sum += bits_of(u[j]);
        }
    }
    n += field(line + n, "calls=", (uint32_t)SAFE_CALLS);
    n += field(line + n, " init=", init);
    n += field(line + n, " flags_sum=", flags_sum);
    n += field(line + n, " u_sum_bits=", u_sum);
    line[n++] = '\n';
    return put(line, n) ? 0 : 1;
}
