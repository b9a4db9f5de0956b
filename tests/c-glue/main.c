/*
 * The build-glue test's C program (tests/c_glue.rs): a double-integrator closed loop through
 * the C ABI of the solver generated from glue_di.mpc, built only with what `mpcc build
 * --staticlib` writes for C projects (glue_di.mk for make, glue_di.pc for pkg-config).
 *
 * 50 real-time iterations from rest at p = 1; the plant is the exact discretization of the
 * double integrator over dt with the control held. stdout: the final state as "p v" (%.17g)
 * and the number of steps whose status was OK; the exit status is 1 if a call failed.
 */
#include "glue_di.h"
#include <stddef.h>
#include <stdio.h>

#define NX GLUE_DI_NX
#define STEPS 50
#define DT 0.1

/* The solver's memory: static, aligned for any scalar type (checked against memalign()). */
static union {
    max_align_t align;
    unsigned char bytes[1 << 16];
} memory;

int main(void) {
    glue_di_solver *s = NULL;
    double x[NX] = {1.0, 0.0};
    double u[GLUE_DI_NU];
    int k, ok = 0;
    if (glue_di_memsize() > sizeof memory.bytes || glue_di_memalign() > _Alignof(max_align_t)) {
        fprintf(stderr, "static buffer too small: %zu bytes aligned to %zu\n", glue_di_memsize(),
                glue_di_memalign());
        return 1;
    }
    if (glue_di_create(memory.bytes, sizeof memory.bytes, &s) != 0) {
        fprintf(stderr, "create failed\n");
        return 1;
    }
    for (k = 0; k < STEPS; k++) {
        if (glue_di_prepare(s) != 0 || glue_di_set_x0(s, x) != 0) {
            fprintf(stderr, "step %d: prepare or set_x0 failed\n", k);
            return 1;
        }
        ok += glue_di_feedback(s) == GLUE_DI_STATUS_OK;
        if (glue_di_get_u0(s, u) != 0) {
            fprintf(stderr, "step %d: get_u0 failed\n", k);
            return 1;
        }
        x[0] += DT * x[1] + 0.5 * DT * DT * u[0];
        x[1] += DT * u[0];
    }
    printf("%.17g %.17g %d\n", x[0], x[1], ok);
    return 0;
}
