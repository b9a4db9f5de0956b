/*
 * The irk test's C program (tests/irk_c.rs): a closed loop through the C ABI of the solver
 * generated from models/stiff_actuator.mpc (implicit Gauss-Legendre dynamics).
 *
 * 60 real-time iterations from rest, target s_ref = 1 m (the model's default). The plant is
 * this file's own integration of the model's ODE: classical RK4 with 100 substeps per 0.05 s
 * interval (h = 0.5 ms, h / tau = 0.125, well inside RK4's stability interval), the control
 * held. stdout: the final state "s v F" (%.17g) and the number of steps whose status was OK;
 * the exit status is 1 if a call failed.
 */
#include "stiff_actuator.h"
#include <stddef.h>
#include <stdio.h>

#define NX STIFF_ACTUATOR_NX
#define STEPS 60
#define DT 0.05
#define SUB 100

static union {
    max_align_t align;
    unsigned char bytes[1 << 17];
} memory;

static void rhs(const double *x, double u, double *d) {
    d[0] = x[1];
    d[1] = x[2] - 4.0 * x[0] - 2.0 * x[0] * x[0] * x[0] - 0.4 * x[1];
    d[2] = (u - x[2]) / 0.004;
}

static void plant(double *x, double u) {
    const double h = DT / SUB;
    int i, j;
    for (i = 0; i < SUB; i++) {
        double k1[NX], k2[NX], k3[NX], k4[NX], y[NX];
        rhs(x, u, k1);
        for (j = 0; j < NX; j++) y[j] = x[j] + 0.5 * h * k1[j];
        rhs(y, u, k2);
        for (j = 0; j < NX; j++) y[j] = x[j] + 0.5 * h * k2[j];
        rhs(y, u, k3);
        for (j = 0; j < NX; j++) y[j] = x[j] + h * k3[j];
        rhs(y, u, k4);
        for (j = 0; j < NX; j++) x[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
    }
}

int main(void) {
    stiff_actuator_solver *s = NULL;
    double x[NX] = {0.0, 0.0, 0.0};
    double u[STIFF_ACTUATOR_NU];
    int k, ok = 0;
    if (stiff_actuator_memsize() > sizeof memory.bytes ||
        stiff_actuator_memalign() > _Alignof(max_align_t)) {
        fprintf(stderr, "static buffer too small: %zu bytes\n", stiff_actuator_memsize());
        return 1;
    }
    if (stiff_actuator_create(memory.bytes, sizeof memory.bytes, &s) != 0) {
        fprintf(stderr, "create failed\n");
        return 1;
    }
    for (k = 0; k < STEPS; k++) {
        if (stiff_actuator_prepare(s) != 0 || stiff_actuator_set_x0(s, x) != 0) {
            fprintf(stderr, "step %d: prepare or set_x0 failed\n", k);
            return 1;
        }
        ok += stiff_actuator_feedback(s) == STIFF_ACTUATOR_STATUS_OK;
        if (stiff_actuator_get_u0(s, u) != 0) {
            fprintf(stderr, "step %d: get_u0 failed\n", k);
            return 1;
        }
        plant(x, u[0]);
    }
    printf("%.17g %.17g %.17g %d\n", x[0], x[1], x[2], ok);
    return 0;
}
