/*
 * C measurement firmware of the safety-augmented step (ampc_safe.h) on the Cortex-M4 (QEMU
 * mps2-an386): ampc_safe_init, then SAFE_CALLS steps of ampc_safe_step over four states
 * near the upright pendulum (pendulum_ode: theta = 0 upright), the controller's memory kept
 * between steps. Prints "calls=<n> flags_sum=<sum of flags> u_sum_bits=<sum of the bits of
 * u>" and exits 0. Build it twice, -DSAFE_CALLS=1 and -DSAFE_CALLS=1001, and count
 * instructions with firmware-example/tools/insn_count.c: per step = (c(1001) - c(1))/1000
 * (tests/c_api.rs).
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

int main(void) {
    static const float states[4][AMPC_SAFE_NX] = {
        {0.1f, -0.1f}, {0.05f, 0.1f}, {-0.1f, 0.05f}, {0.02f, -0.02f}};
    struct ampc_safe s;
    float u[AMPC_SAFE_NU];
    uint32_t flags_sum = 0u, u_sum = 0u;
    unsigned i;
    char line[96];
    size_t n = 0;
    ampc_safe_init(&s);
    for (i = 0; i < SAFE_CALLS; i++) {
        flags_sum += ampc_safe_step(&s, states[i % 4u], u);
        u_sum += bits_of(u[0]);
    }
    memcpy(line + n, "calls=", 6);
    n += 6;
    n += dec(line + n, (uint32_t)SAFE_CALLS);
    memcpy(line + n, " flags_sum=", 11);
    n += 11;
    n += dec(line + n, flags_sum);
    memcpy(line + n, " u_sum_bits=", 12);
    n += 12;
    n += dec(line + n, u_sum);
    line[n++] = '\n';
    return put(line, n) ? 0 : 1;
}
