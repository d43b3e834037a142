/*
 * ampc_stdin: evaluates the controller of libampc_capi.a on states read from stdin.
 *
 * Input: one state per line, AMPC_NX numbers separated by blanks; a number is a decimal
 * (strtof) or, written 0xXXXXXXXX, the bits of an IEEE-754 single.
 * Output: one line per state: "flags u_1 ... u_NU # bits(u_1) ... bits(u_NU)" (u with 9
 * significant digits, which read back to the same float).
 * First line: "certificate <ok|MISMATCH> eps=<eps> tier=<tier> hash=<hash>": whether the
 * header's AMPC_CERTIFICATE equals the library's ampc_linked_certificate field by field.
 *
 * Build: cargo build --release -p ampc-capi, then (see README, "From C")
 *   cc -std=c99 -Wall -Wextra -Werror -pedantic -Icontroller-core/capi/include \
 *      controller-core/capi/c/ampc_stdin.c target/release/libampc_capi.a -lm -lpthread -ldl
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ampc.h"

static uint32_t bits_of(float v) {
    uint32_t b;
    memcpy(&b, &v, sizeof b);
    return b;
}

static float float_of(uint32_t b) {
    float v;
    memcpy(&v, &b, sizeof v);
    return v;
}

/* Field-by-field equality, floats compared by their bits. */
static int same_certificate(const struct ampc_certificate *a, const struct ampc_certificate *b) {
    int i;
    if (memcmp(&a->eps, &b->eps, sizeof a->eps) != 0 || a->guarantee != b->guarantee ||
        a->placeholder != b->placeholder || a->fast_tanh != b->fast_tanh ||
        strcmp(a->hash, b->hash) != 0) {
        return 0;
    }
    for (i = 0; i < AMPC_NX; i++) {
        if (memcmp(&a->domain_lo[i], &b->domain_lo[i], sizeof(double)) != 0 ||
            memcmp(&a->domain_hi[i], &b->domain_hi[i], sizeof(double)) != 0) {
            return 0;
        }
    }
    for (i = 0; i < AMPC_NU; i++) {
        if (bits_of(a->clamp_lo[i]) != bits_of(b->clamp_lo[i]) ||
            bits_of(a->clamp_hi[i]) != bits_of(b->clamp_hi[i])) {
            return 0;
        }
    }
    return 1;
}

int main(void) {
    static const char *const tiers[] = {"sound", "statistical", "estimated"};
    char line[1024];
    int i;
    printf("certificate %s eps=%.17g tier=%s hash=%s\n",
           same_certificate(&AMPC_CERTIFICATE, &ampc_linked_certificate) ? "ok" : "MISMATCH",
           AMPC_CERTIFICATE.eps,
           AMPC_CERTIFICATE.guarantee < 3 ? tiers[AMPC_CERTIFICATE.guarantee] : "?",
           AMPC_CERTIFICATE.hash);
    while (fgets(line, sizeof line, stdin) != NULL) {
        float x[AMPC_NX];
        float u[AMPC_NU];
        char *p = line;
        uint8_t flags;
        for (i = 0; i < AMPC_NX; i++) {
            char *end;
            while (*p == ' ' || *p == '\t') {
                p++;
            }
            if (p[0] == '0' && (p[1] == 'x' || p[1] == 'X')) {
                x[i] = float_of((uint32_t)strtoul(p, &end, 16));
            } else {
                x[i] = strtof(p, &end);
            }
            if (end == p) {
                fprintf(stderr, "ampc_stdin: expected %d numbers per line: %s", AMPC_NX, line);
                return 2;
            }
            p = end;
        }
        flags = ampc_evaluate(x, u);
        printf("%u", (unsigned)flags);
        for (i = 0; i < AMPC_NU; i++) {
            printf(" %.9g", (double)u[i]);
        }
        printf(" #");
        for (i = 0; i < AMPC_NU; i++) {
            printf(" %08lx", (unsigned long)bits_of(u[i]));
        }
        printf("\n");
    }
    return 0;
}
