/*
 * ampc_safe_stdin: runs the safe controller of libampc_capi.a (ampc_safe.h) on a sequence
 * of states read from stdin, one controller memory for the whole run.
 *
 * Input: one state per line, AMPC_SAFE_NX numbers 0xXXXXXXXX (the bits of IEEE-754
 * singles); a line "reset" calls ampc_safe_init.
 * Output: first "sizeof=<sizeof(struct ampc_safe)> n=<AMPC_SAFE_N> nx=<..> nu=<..>", then
 * "null <flags u-null> <flags s-null> <bits u> <flags x-null> <bits u> <flags init-null>"
 * (the bad-input answers), then one line per state: "flags bits(u_1) ... bits(u_NU) has_safe".
 *
 * Build (see tests/c_api.rs):
 *   cc -std=c99 -Wall -Wextra -Werror -pedantic -Icontroller-core/capi/include \
 *      controller-core/capi/c/ampc_safe_stdin.c libampc_capi.a -lm -lpthread -ldl
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ampc_safe.h"

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

int main(void) {
    struct ampc_safe s;
    char line[1024];
    float x[AMPC_SAFE_NX] = {0};
    float u[AMPC_SAFE_NU];
    unsigned f1, f2, f3, f4;
    uint32_t b2, b3;
    int i;

    printf("sizeof=%u n=%d nx=%d nu=%d\n", (unsigned)sizeof s, AMPC_SAFE_N, AMPC_SAFE_NX,
           AMPC_SAFE_NU);
    ampc_safe_init(&s);
    f1 = ampc_safe_step(&s, x, NULL);
    u[0] = 5.0f;
    f2 = ampc_safe_step(NULL, x, u);
    b2 = bits_of(u[0]);
    u[0] = 5.0f;
    f3 = ampc_safe_step(&s, NULL, u);
    b3 = bits_of(u[0]);
    f4 = ampc_safe_init(NULL);
    printf("null %u %u 0x%08lx %u 0x%08lx %u has_safe=%u\n", f1, f2, (unsigned long)b2, f3,
           (unsigned long)b3, f4, (unsigned)s.has_safe);
    while (fgets(line, sizeof line, stdin) != NULL) {
        char *p = line;
        unsigned flags;
        if (strncmp(line, "reset", 5) == 0) {
            printf("reset %u\n", (unsigned)ampc_safe_init(&s));
            continue;
        }
        for (i = 0; i < AMPC_SAFE_NX; i++) {
            char *end;
            x[i] = float_of((uint32_t)strtoul(p, &end, 16));
            p = end;
        }
        flags = ampc_safe_step(&s, x, u);
        printf("%u", flags);
        for (i = 0; i < AMPC_SAFE_NU; i++) {
            printf(" 0x%08lx", (unsigned long)bits_of(u[i]));
        }
        printf(" %u\n", (unsigned)s.has_safe);
    }
    return 0;
}
