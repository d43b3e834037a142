/*
 * C firmware: the paper's pendulum upswing on the Cortex-M4 (QEMU mps2-an386), the
 * controller called through the C API (libampc_capi.a for thumbv7em-none-eabihf).
 *
 * The same loop as the Rust firmware (firmware-example/src/lib.rs, `run`): x_0 = (-pi, 0)
 * in f32, rows k = 0..=90: u_k = controller(x_k), x_{k+1} = rk4_step(x_k, u_k). The plant
 * is firmware-example's own f32 code, exported by the library built with the
 * `pendulum-plant` feature (so that the trajectories can agree bit for bit). Prints
 * "k,x1,x2,u,flags" rows over semihosting (newlib's rdimon), floats as the hex bits of the
 * IEEE-754 single, and exits with status 0 (1 on a write error).
 */
#include <stdint.h>
#include <string.h>
#include <unistd.h>

#include "ampc.h"

/* Exported by libampc_capi.a with the `pendulum-plant` feature (not part of ampc.h). */
void ampc_example_pendulum_step(float x[2], float u);

enum { STEPS = 90 };

static int put(const char *s, size_t n) {
    return write(1, s, n) == (ssize_t)n;
}

static size_t hex32(char *out, uint32_t v) {
    static const char digits[] = "0123456789abcdef";
    int i;
    for (i = 0; i < 8; i++) {
        out[i] = digits[(v >> (28 - 4 * i)) & 0xFu];
    }
    return 8;
}

static size_t dec(char *out, unsigned v) {
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
    /* -pi rounded to f32 (Rust: -core::f32::consts::PI). */
    float x[AMPC_NX] = {-0x1.921fb6p+1f, 0.0f};
    float u[AMPC_NU];
    int ok = put("k,x1,x2,u,flags\n", 16);
    unsigned k;
    for (k = 0; k <= STEPS; k++) {
        char row[64];
        size_t n = 0;
        uint8_t flags = ampc_evaluate(x, u);
        n += dec(row + n, k);
        row[n++] = ',';
        n += hex32(row + n, bits_of(x[0]));
        row[n++] = ',';
        n += hex32(row + n, bits_of(x[1]));
        row[n++] = ',';
        n += hex32(row + n, bits_of(u[0]));
        row[n++] = ',';
        n += dec(row + n, flags);
        row[n++] = '\n';
        ok &= put(row, n);
        ampc_example_pendulum_step(x, u[0]);
    }
    return ok ? 0 : 1;
}
