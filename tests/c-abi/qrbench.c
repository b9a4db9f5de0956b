/*
 * QR-bench closed loop through the C ABI of the generated `quadrotor_rates` solver.
 *
 * The solver lives in memory this program allocates (memsize() bytes aligned to memalign());
 * 100 real-time iterations (prepare, set_x0, feedback, get_u0) drive a plant written here in
 * C: the quadrotor ODE of runtime/tests/support/quadrotor.rs, 10 RK4 substeps per 0.05 s,
 * with the operations in the same order as the Rust plant so both loops agree to rounding.
 * Also exercises the error paths (NULL, size, alignment, non-finite input, stage range) and
 * the run-time bounds (a thrust limit set through the ABI bounds the control returned).
 *
 * stdout: one line, the final state as 10 numbers printed with %.17g.
 * stderr: a message for every failed check; the exit status is then 1.
 *
 * Build (see tests/c_program.rs):
 *   gcc -std=c99 -Wall -Wextra -Werror -pedantic -I generated/quadrotor_rates/include \
 *       qrbench.c libc_abi_test.a -lpthread -ldl -lm
 */
#define _POSIX_C_SOURCE 200112L /* posix_memalign */

#include "quadrotor_rates.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define NX QUADROTOR_RATES_NX
#define NU QUADROTOR_RATES_NU
#define NP QUADROTOR_RATES_NP
#define HORIZON QUADROTOR_RATES_N
#define STEPS 100
#define DT 0.05
#define SUBSTEPS 10
#define GRAVITY 9.81

static int failures = 0;

/* Records a failed check (and keeps going, so one run reports every failure). */
#define CHECK(cond)                                                                \
    do {                                                                           \
        if (!(cond)) {                                                             \
            fprintf(stderr, "qrbench.c:%d: check failed: %s\n", __LINE__, #cond); \
            failures++;                                                            \
        }                                                                          \
    } while (0)

/* Checks that `call` returns `expected`. */
#define EXPECT_RC(call, expected)                                                         \
    do {                                                                                  \
        int rc_ = (call);                                                                 \
        if (rc_ != (expected)) {                                                          \
            fprintf(stderr, "qrbench.c:%d: %s returned %d, expected %s (%d)\n", __LINE__, \
                    #call, rc_, #expected, (int)(expected));                              \
            failures++;                                                                   \
        }                                                                                 \
    } while (0)

/* xdot = f(x, u): the expressions of `ode` in runtime/tests/support/quadrotor.rs. */
static void ode(const double x[NX], const double u[NU], double f[NX]) {
    const double h = 0.5;
    const double two = 2.0;
    const double qw = x[3], qx = x[4], qy = x[5], qz = x[6];
    const double c = u[0], wx = u[1], wy = u[2], wz = u[3];
    f[0] = x[7];
    f[1] = x[8];
    f[2] = x[9];
    f[3] = h * (-qx * wx - qy * wy - qz * wz);
    f[4] = h * (qw * wx + qy * wz - qz * wy);
    f[5] = h * (qw * wy - qx * wz + qz * wx);
    f[6] = h * (qw * wz + qx * wy - qy * wx);
    f[7] = two * (qw * qy + qx * qz) * c;
    f[8] = two * (qy * qz - qw * qx) * c;
    f[9] = (1.0 - two * (qx * qx + qy * qy)) * c - GRAVITY;
}

/* One classical RK4 step of length dt, in place (the state part of `rk4`). */
static void rk4(double x[NX], const double u[NU], double dt) {
    double k1[NX], k2[NX], k3[NX], k4[NX], xt[NX];
    const double half = dt * 0.5;
    const double sixth = dt / 6.0;
    int i;
    ode(x, u, k1);
    for (i = 0; i < NX; i++) xt[i] = x[i] + k1[i] * half;
    ode(xt, u, k2);
    for (i = 0; i < NX; i++) xt[i] = x[i] + k2[i] * half;
    ode(xt, u, k3);
    for (i = 0; i < NX; i++) xt[i] = x[i] + k3[i] * dt;
    ode(xt, u, k4);
    for (i = 0; i < NX; i++) x[i] = x[i] + (k1[i] + k2[i] * 2.0 + k3[i] * 2.0 + k4[i]) * sixth;
}

/* The plant: RK4 with `substeps` steps over dt (the quaternion is not renormalized). */
static void plant(double x[NX], const double u[NU], double dt, int substeps) {
    int k;
    for (k = 0; k < substeps; k++) rk4(x, u, dt / (double)substeps);
}

/* `size` rounded up to a multiple of `align` (a power of two). */
static size_t round_up(size_t size, size_t align) { return (size + align - 1) & ~(align - 1); }

/* Memory for one solver: memsize() bytes (rounded up) aligned to memalign(). */
static void *alloc_solver_memory(size_t *size_out) {
    size_t align = quadrotor_rates_memalign();
    size_t size;
    void *mem = NULL;
    if (align < sizeof(void *)) align = sizeof(void *); /* posix_memalign's minimum */
    size = round_up(quadrotor_rates_memsize(), align);
    if (posix_memalign(&mem, align, size) != 0) return NULL;
    *size_out = size;
    return mem;
}

static int all_zero_stats(const quadrotor_rates_stats *st) {
    return st->status == 0 && st->qp_status == 0 && st->qp_iterations == 0 &&
           st->sqp_iterations == 0 && st->res_stat == 0.0 && st->res_eq == 0.0 &&
           st->res_ineq == 0.0 && st->mu == 0.0;
}

/* Every pointer argument of every function refuses NULL with ERR_NULL. */
static void check_null_pointers(quadrotor_rates_solver *s) {
    double x[NX] = {0}, u[NU] = {0}, p[NP] = {0};
    quadrotor_rates_stats st;
    EXPECT_RC(quadrotor_rates_set_x0(NULL, x), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_x0(s, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_param(NULL, 0, p), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_param(s, 0, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_param_all(NULL, p), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_param_all(s, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_xref(NULL, 0, x), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_xref(s, 0, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_uref(NULL, 0, u), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_uref(s, 0, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_guess(NULL, x, u), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_guess(s, NULL, u), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_guess(s, x, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_qp_max_iter(NULL, 10), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_prepare(NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_feedback(NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_solve_sqp(NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_u0(NULL, u), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_u0(s, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_control(NULL, 0, u), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_control(s, 0, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_state(NULL, 0, x), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_state(s, 0, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_stats(NULL, &st), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_stats(s, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_control_bounds(NULL, u, u), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_control_bounds(s, NULL, u), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_control_bounds(s, u, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_control_bounds(NULL, u, u), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_control_bounds(s, NULL, u), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_control_bounds(s, u, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_state_bounds(NULL, x, x), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_state_bounds(s, NULL, x), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_state_bounds(s, x, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_state_bounds(NULL, x, x), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_state_bounds(s, NULL, x), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_state_bounds(s, x, NULL), QUADROTOR_RATES_ERR_NULL);
    /* No general constraints (NG = NGN = 0): their bounds have no entries, NULL is fine. */
    CHECK(QUADROTOR_RATES_NG == 0 && QUADROTOR_RATES_NGN == 0);
    EXPECT_RC(quadrotor_rates_set_constraint_bounds(NULL, NULL, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_constraint_bounds(NULL, NULL, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_terminal_constraint_bounds(NULL, NULL, NULL),
              QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_terminal_constraint_bounds(NULL, NULL, NULL),
              QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_constraint_bounds(s, NULL, NULL), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_constraint_bounds(s, NULL, NULL), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_set_terminal_constraint_bounds(s, NULL, NULL),
              QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_terminal_constraint_bounds(s, NULL, NULL),
              QUADROTOR_RATES_STATUS_OK);
}

/* create refuses NULL, too-small and misaligned memory and leaves *out untouched. */
static void check_create_errors(void) {
    const size_t need = quadrotor_rates_memsize();
    const size_t align = quadrotor_rates_memalign();
    size_t size = 0;
    void *mem;
    quadrotor_rates_solver *s = NULL;

    CHECK(need > 0);
    CHECK(align > 0 && (align & (align - 1)) == 0);

    mem = alloc_solver_memory(&size);
    if (mem == NULL) {
        fprintf(stderr, "qrbench.c: out of memory\n");
        failures++;
        return;
    }
    EXPECT_RC(quadrotor_rates_create(NULL, size, &s), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_create(mem, size, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_create(mem, need - 1, &s), QUADROTOR_RATES_ERR_SIZE);
    EXPECT_RC(quadrotor_rates_create(mem, 0, &s), QUADROTOR_RATES_ERR_SIZE);
    CHECK(s == NULL);
    free(mem);

    if (align > 1) {
        /* One byte past an aligned block: misaligned, with enough room behind it. */
        void *big = NULL;
        size_t big_align = align < sizeof(void *) ? sizeof(void *) : align;
        if (posix_memalign(&big, big_align, round_up(need, big_align) + big_align) != 0) {
            fprintf(stderr, "qrbench.c: out of memory\n");
            failures++;
            return;
        }
        EXPECT_RC(quadrotor_rates_create((char *)big + 1, need, &s), QUADROTOR_RATES_ERR_ALIGN);
        CHECK(s == NULL);
        free(big);
    }
}

/* Stage indices outside 0..N (states, parameters) or 0..N-1 (controls) give ERR_STAGE. */
static void check_stage_errors(quadrotor_rates_solver *s) {
    double x[NX], u[NU], p[NP];
    /* The generated default reference (4, 0, 2, identity, 0): re-setting it changes nothing. */
    static const double xref[NX] = {4.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    static const double uref[NU] = {GRAVITY, 0.0, 0.0, 0.0};
    memset(p, 0, sizeof p);
    EXPECT_RC(quadrotor_rates_get_control(s, HORIZON, u), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_get_control(s, -1, u), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_get_control(s, HORIZON - 1, u), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_control(s, 0, u), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_state(s, HORIZON + 1, x), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_get_state(s, -1, x), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_get_state(s, HORIZON, x), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_set_xref(s, HORIZON + 1, xref), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_set_xref(s, -1, xref), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_set_xref(s, HORIZON, xref), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_set_uref(s, HORIZON + 1, uref), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_set_uref(s, -1, uref), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_set_param(s, HORIZON + 1, p), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_set_param(s, -1, p), QUADROTOR_RATES_ERR_STAGE);
}

/* Non-finite values are refused with ERR_NONFINITE (and change nothing). */
static void check_nonfinite_setters(quadrotor_rates_solver *s) {
    double x[NX] = {0}, u[NU] = {0}, p[NP] = {0};
    x[3] = 1.0;
    x[5] = NAN;
    EXPECT_RC(quadrotor_rates_set_xref(s, 3, x), QUADROTOR_RATES_ERR_NONFINITE);
    EXPECT_RC(quadrotor_rates_set_guess(s, x, u), QUADROTOR_RATES_ERR_NONFINITE);
    u[2] = INFINITY;
    EXPECT_RC(quadrotor_rates_set_uref(s, 0, u), QUADROTOR_RATES_ERR_NONFINITE);
    p[13] = -INFINITY;
    EXPECT_RC(quadrotor_rates_set_param(s, 0, p), QUADROTOR_RATES_ERR_NONFINITE);
    EXPECT_RC(quadrotor_rates_set_param_all(s, p), QUADROTOR_RATES_ERR_NONFINITE);
}

/* A second, independent solver: feedback without prepare is reported, not run. */
static void check_not_prepared(const double x0[NX]) {
    size_t size = 0;
    void *mem = alloc_solver_memory(&size);
    quadrotor_rates_solver *s = NULL;
    quadrotor_rates_stats st;
    double u[NU], u_ok[NU];
    if (mem == NULL) {
        fprintf(stderr, "qrbench.c: out of memory\n");
        failures++;
        return;
    }
    EXPECT_RC(quadrotor_rates_create(mem, size, &s), QUADROTOR_RATES_STATUS_OK);
    CHECK(s != NULL);
    if (s != NULL) {
        EXPECT_RC(quadrotor_rates_set_x0(s, x0), QUADROTOR_RATES_STATUS_OK);
        EXPECT_RC(quadrotor_rates_prepare(s), QUADROTOR_RATES_STATUS_OK);
        EXPECT_RC(quadrotor_rates_feedback(s), QUADROTOR_RATES_STATUS_OK);
        EXPECT_RC(quadrotor_rates_get_u0(s, u_ok), QUADROTOR_RATES_STATUS_OK);
        EXPECT_RC(quadrotor_rates_feedback(s), QUADROTOR_RATES_STATUS_NOT_PREPARED);
        EXPECT_RC(quadrotor_rates_get_stats(s, &st), QUADROTOR_RATES_STATUS_OK);
        CHECK(st.status == QUADROTOR_RATES_STATUS_NOT_PREPARED);
        CHECK(st.qp_iterations == 0 && st.sqp_iterations == 0);
        /* The control stays the one of the last solved QP (the plan's first). */
        EXPECT_RC(quadrotor_rates_get_u0(s, u), QUADROTOR_RATES_STATUS_OK);
        CHECK(memcmp(u, u_ok, sizeof u) == 0);
    }
    free(mem);
}

/* Whether the control bounds in use are `lb`, `ub`. */
static int control_bounds_are(quadrotor_rates_solver *s, const double lb[NU], const double ub[NU]) {
    double l[NU], u[NU];
    return quadrotor_rates_get_control_bounds(s, l, u) == 0 && memcmp(l, lb, sizeof l) == 0 &&
           memcmp(u, ub, sizeof u) == 0;
}

/* Sets the reference 5 m above the hover at x0 for every stage and solves to convergence
   from the hover; returns the thrust of the first control. */
static double climb_thrust(quadrotor_rates_solver *s, const double x0[NX]) {
    static const double hover[NU] = {GRAVITY, 0.0, 0.0, 0.0};
    double xref[NX], u[NU] = {0};
    int k;
    memcpy(xref, x0, sizeof xref);
    xref[2] += 5.0;
    for (k = 0; k <= HORIZON; k++) {
        EXPECT_RC(quadrotor_rates_set_xref(s, k, xref), QUADROTOR_RATES_STATUS_OK);
    }
    EXPECT_RC(quadrotor_rates_set_guess(s, x0, hover), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_set_x0(s, x0), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_solve_sqp(s), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_u0(s, u), QUADROTOR_RATES_STATUS_OK);
    return u[0];
}

/* A second solver: a thrust limit of 12 set at run time bounds the climb's first control
   (20 without it), from the next prepare or solve_sqp on; bad bounds are refused with
   their codes and change nothing. */
static void check_run_time_bounds(const double x0[NX]) {
    static const double lb[NU] = {0.0, -20.0, -20.0, -6.0};
    static const double ub_model[NU] = {20.0, 20.0, 20.0, 6.0};
    static const double ub[NU] = {12.0, 20.0, 20.0, 6.0};
    double bad[NU], xl[NX], xu[NX], u[NU];
    size_t size = 0;
    void *mem = alloc_solver_memory(&size);
    quadrotor_rates_solver *s = NULL;
    int k;
    if (mem == NULL) {
        fprintf(stderr, "qrbench.c: out of memory\n");
        failures++;
        return;
    }
    EXPECT_RC(quadrotor_rates_create(mem, size, &s), QUADROTOR_RATES_STATUS_OK);
    if (s == NULL) {
        free(mem);
        return;
    }
    CHECK(control_bounds_are(s, lb, ub_model));
    CHECK(climb_thrust(s, x0) > 12.0);

    /* Set after the preparation: the feedback solves the QP prepared with the old bounds. */
    EXPECT_RC(quadrotor_rates_prepare(s), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_set_control_bounds(s, lb, ub), QUADROTOR_RATES_STATUS_OK);
    CHECK(control_bounds_are(s, lb, ub));
    EXPECT_RC(quadrotor_rates_feedback(s), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_u0(s, u), QUADROTOR_RATES_STATUS_OK);
    CHECK(u[0] > 12.0);
    /* The next preparation applies them. */
    EXPECT_RC(quadrotor_rates_prepare(s), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_feedback(s), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_u0(s, u), QUADROTOR_RATES_STATUS_OK);
    CHECK(u[0] <= 12.0 + 1e-6);
    CHECK(fabs(climb_thrust(s, x0) - 12.0) <= 1e-6);
    for (k = 0; k < HORIZON; k++) {
        EXPECT_RC(quadrotor_rates_get_control(s, k, u), QUADROTOR_RATES_STATUS_OK);
        CHECK(u[0] <= 12.0 + 1e-6);
    }

    memcpy(bad, lb, sizeof bad);
    bad[0] = 13.0;
    EXPECT_RC(quadrotor_rates_set_control_bounds(s, bad, ub), QUADROTOR_RATES_ERR_BOUNDS);
    bad[0] = NAN;
    EXPECT_RC(quadrotor_rates_set_control_bounds(s, bad, ub), QUADROTOR_RATES_ERR_NONFINITE);
    bad[0] = INFINITY;
    EXPECT_RC(quadrotor_rates_set_control_bounds(s, bad, ub), QUADROTOR_RATES_ERR_NONFINITE);
    CHECK(control_bounds_are(s, lb, ub));
    /* QR-bench bounds no state: the solver has no state-bound row for one. */
    EXPECT_RC(quadrotor_rates_get_state_bounds(s, xl, xu), QUADROTOR_RATES_STATUS_OK);
    for (k = 0; k < NX; k++) CHECK(xl[k] == -INFINITY && xu[k] == INFINITY);
    xu[2] = 4.0;
    EXPECT_RC(quadrotor_rates_set_state_bounds(s, xl, xu), QUADROTOR_RATES_ERR_INPUT);
    EXPECT_RC(quadrotor_rates_get_state_bounds(s, xl, xu), QUADROTOR_RATES_STATUS_OK);
    CHECK(xu[2] == INFINITY);
    CHECK(control_bounds_are(s, lb, ub));
    free(mem);
}

/* Creates a solver in fresh memory (*mem to free), NULL on failure (recorded). */
static quadrotor_rates_solver *fresh_solver(void **mem) {
    size_t size = 0;
    quadrotor_rates_solver *s = NULL;
    *mem = alloc_solver_memory(&size);
    if (*mem == NULL) {
        fprintf(stderr, "qrbench.c: out of memory\n");
        failures++;
        return NULL;
    }
    EXPECT_RC(quadrotor_rates_create(*mem, size, &s), QUADROTOR_RATES_STATUS_OK);
    return s;
}

/* Settings from C: read, refused (nothing changes), written back changed. */
static void check_settings(quadrotor_rates_solver *s) {
    quadrotor_rates_settings st, bad, now;
    EXPECT_RC(quadrotor_rates_get_settings(NULL, &st), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_settings(s, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_settings(NULL, &st), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_settings(s, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_settings(s, &st), QUADROTOR_RATES_STATUS_OK);
    CHECK(st.qp_max_iter > 0 && st.sqp_max_iter == 50 && st.fallback_limit > 0);
    CHECK(st.qp_tol_stat > 0.0 && st.sqp_tol > 0.0);
    bad = st;
    bad.sqp_tol = NAN;
    EXPECT_RC(quadrotor_rates_set_settings(s, &bad), QUADROTOR_RATES_ERR_NONFINITE);
    bad = st;
    bad.qp_tol_eq = -1e-9;
    EXPECT_RC(quadrotor_rates_set_settings(s, &bad), QUADROTOR_RATES_ERR_INPUT);
    bad = st;
    bad.sqp_max_iter = 0;
    EXPECT_RC(quadrotor_rates_set_settings(s, &bad), QUADROTOR_RATES_ERR_INPUT);
    bad = st;
    bad.shift = 2;
    EXPECT_RC(quadrotor_rates_set_settings(s, &bad), QUADROTOR_RATES_ERR_INPUT);
    bad = st;
    bad.qp_method = 3;
    EXPECT_RC(quadrotor_rates_set_settings(s, &bad), QUADROTOR_RATES_ERR_INPUT);
    EXPECT_RC(quadrotor_rates_get_settings(s, &now), QUADROTOR_RATES_STATUS_OK);
    CHECK(memcmp(&now, &st, sizeof st) == 0);
    bad = st;
    bad.shift = !st.shift;
    bad.sqp_max_iter = 7;
    bad.sqp_kkt_tol = 1e-7;
    bad.fallback_limit = 2;
    EXPECT_RC(quadrotor_rates_set_settings(s, &bad), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_settings(s, &now), QUADROTOR_RATES_STATUS_OK);
    CHECK(memcmp(&now, &bad, sizeof bad) == 0);
    EXPECT_RC(quadrotor_rates_set_settings(s, &st), QUADROTOR_RATES_STATUS_OK);
}

/* Per-stage guesses, the whole-trajectory guess and read-back. */
static void check_guesses(quadrotor_rates_solver *s) {
    static double x[(HORIZON + 1) * NX], u[HORIZON * NU], xb[(HORIZON + 1) * NX], ub[HORIZON * NU];
    double one[NX + 1];
    int i;
    for (i = 0; i < (HORIZON + 1) * NX; i++) x[i] = 0.01 * i;
    for (i = 0; i < HORIZON * NU; i++) u[i] = 9.0 + 0.001 * i;
    EXPECT_RC(quadrotor_rates_set_trajectory_guess(s, NULL, u), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_trajectory_guess(s, x, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_set_trajectory_guess(s, (const double *)((const char *)x + 1), u),
              QUADROTOR_RATES_ERR_ALIGN);
    EXPECT_RC(quadrotor_rates_set_trajectory_guess(s, x, u), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_trajectory(s, NULL, ub), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_trajectory(s, xb, ub), QUADROTOR_RATES_STATUS_OK);
    CHECK(memcmp(x, xb, sizeof x) == 0 && memcmp(u, ub, sizeof u) == 0);
    /* A NaN anywhere: refused, nothing changed. */
    x[5 * NX + 2] = NAN;
    EXPECT_RC(quadrotor_rates_set_trajectory_guess(s, x, u), QUADROTOR_RATES_ERR_NONFINITE);
    EXPECT_RC(quadrotor_rates_set_state_guess(s, 5, &x[5 * NX]), QUADROTOR_RATES_ERR_NONFINITE);
    EXPECT_RC(quadrotor_rates_get_trajectory(s, xb, ub), QUADROTOR_RATES_STATUS_OK);
    CHECK(xb[5 * NX + 2] == 0.01 * (5 * NX + 2));
    for (i = 0; i < NX; i++) one[i] = -1.0 - i;
    EXPECT_RC(quadrotor_rates_set_state_guess(s, HORIZON + 1, one), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_set_state_guess(s, -1, one), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_set_state_guess(s, HORIZON, one), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_state(s, HORIZON, xb), QUADROTOR_RATES_STATUS_OK);
    CHECK(memcmp(one, xb, NX * sizeof(double)) == 0);
    EXPECT_RC(quadrotor_rates_set_control_guess(s, HORIZON, one), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_set_control_guess(s, 3, one), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_control(s, 3, ub), QUADROTOR_RATES_STATUS_OK);
    CHECK(memcmp(one, ub, NU * sizeof(double)) == 0);
}

/* Read-outs after a converged full SQP: a KKT point, a finite cost, multipliers per stage. */
static void check_read_outs(quadrotor_rates_solver *s, const double x0[NX]) {
    double cost = -1.0, kkt = -1.0, m[NX], sl[1], su[1];
    static const double hover[NU] = {GRAVITY, 0.0, 0.0, 0.0};
    static const double hx[NX] = {0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    EXPECT_RC(quadrotor_rates_set_guess(s, hx, hover), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_set_x0(s, x0), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_solve_sqp(s), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_cost(NULL, &cost), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_cost(s, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_cost(s, &cost), QUADROTOR_RATES_STATUS_OK);
    CHECK(cost > 0.0 && isfinite(cost));
    EXPECT_RC(quadrotor_rates_get_kkt_residual(s, &kkt), QUADROTOR_RATES_STATUS_OK);
    CHECK(kkt >= 0.0 && kkt <= 1e-5);
    EXPECT_RC(quadrotor_rates_get_dynamics_multipliers(s, 0, m), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_dynamics_multipliers(s, HORIZON, m), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_get_control_bound_multipliers(s, 0, m), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_control_bound_multipliers(s, 0, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_state_bound_multipliers(s, 0, m), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_get_state_bound_multipliers(s, HORIZON, m), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_constraint_multipliers(s, 0, NULL), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_terminal_constraint_multipliers(s, NULL), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_slacks(s, 0, sl, su), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_slacks(s, HORIZON, sl, su), QUADROTOR_RATES_ERR_STAGE);
    EXPECT_RC(quadrotor_rates_get_terminal_slacks(s, NULL, NULL), QUADROTOR_RATES_STATUS_OK);
    /* No general rows: the penalty functions take NULL and there is nothing to set. */
    EXPECT_RC(quadrotor_rates_set_soft_penalties(s, NULL, NULL), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_soft_penalties(s, NULL, NULL), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_set_terminal_soft_penalties(NULL, NULL, NULL), QUADROTOR_RATES_ERR_NULL);
    EXPECT_RC(quadrotor_rates_get_terminal_soft_penalties(s, NULL, NULL), QUADROTOR_RATES_STATUS_OK);
}

/* QPs that cannot converge (one iteration, no warm active set) fail step after step: the
   status escalates to PLAN_EXHAUSTED at the fallback_limit-th failure in a row. */
static void check_escalation(quadrotor_rates_solver *s, const double x0[NX]) {
    quadrotor_rates_settings st;
    quadrotor_rates_stats stats;
    int k, status;
    EXPECT_RC(quadrotor_rates_get_settings(s, &st), QUADROTOR_RATES_STATUS_OK);
    st.qp_max_iter = 1;
    st.qp_warm_active_set = 0;
    st.qp_polish = 0;
    st.fallback_limit = 3;
    EXPECT_RC(quadrotor_rates_set_settings(s, &st), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_set_x0(s, x0), QUADROTOR_RATES_STATUS_OK);
    for (k = 1; k <= 5; k++) {
        EXPECT_RC(quadrotor_rates_prepare(s), QUADROTOR_RATES_STATUS_OK);
        status = quadrotor_rates_feedback(s);
        EXPECT_RC(quadrotor_rates_get_stats(s, &stats), QUADROTOR_RATES_STATUS_OK);
        CHECK(stats.consecutive_failures == (unsigned int)k);
        CHECK(status == (k >= 3 ? QUADROTOR_RATES_STATUS_PLAN_EXHAUSTED
                                : QUADROTOR_RATES_STATUS_USED_PREVIOUS_PLAN));
    }
    st.qp_max_iter = 50;
    EXPECT_RC(quadrotor_rates_set_settings(s, &st), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_prepare(s), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_feedback(s), QUADROTOR_RATES_STATUS_OK);
    EXPECT_RC(quadrotor_rates_get_stats(s, &stats), QUADROTOR_RATES_STATUS_OK);
    CHECK(stats.consecutive_failures == 0);
}

/* The run-time API of issue 30 on a fresh solver. */
static void check_run_time_api(const double x0[NX]) {
    void *mem = NULL;
    quadrotor_rates_solver *s = fresh_solver(&mem);
    if (s != NULL) {
        check_settings(s);
        check_guesses(s);
        check_read_outs(s, x0);
        check_escalation(s, x0);
    }
    free(mem);
}

int main(void) {
    static const double x0[NX] = {0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    const double u_zero[NU] = {0.0, 0.0, 0.0, 0.0};
    double x[NX], u[NU], bad[NX];
    quadrotor_rates_solver *s = NULL;
    quadrotor_rates_stats st;
    size_t size = 0;
    void *mem;
    int k, i;

    check_create_errors();

    mem = alloc_solver_memory(&size);
    if (mem == NULL) {
        fprintf(stderr, "qrbench.c: out of memory\n");
        return 1;
    }
    EXPECT_RC(quadrotor_rates_create(mem, size, &s), QUADROTOR_RATES_STATUS_OK);
    if (s == NULL) {
        fprintf(stderr, "qrbench.c: create gave no solver\n");
        free(mem);
        return 1;
    }
    CHECK((void *)s == mem);

    check_null_pointers(s);
    EXPECT_RC(quadrotor_rates_get_stats(s, &st), QUADROTOR_RATES_STATUS_OK);
    CHECK(all_zero_stats(&st));
    check_nonfinite_setters(s);

    EXPECT_RC(quadrotor_rates_set_guess(s, x0, u_zero), QUADROTOR_RATES_STATUS_OK);
    memcpy(x, x0, sizeof x);
    for (k = 0; k < STEPS; k++) {
        int status;
        EXPECT_RC(quadrotor_rates_prepare(s), QUADROTOR_RATES_STATUS_OK);
        EXPECT_RC(quadrotor_rates_set_x0(s, x), QUADROTOR_RATES_STATUS_OK);
        if (k % 25 == 0) {
            /* A NaN (or infinity) measurement is refused and keeps the state set above. */
            memcpy(bad, x, sizeof bad);
            bad[k % NX] = (k % 50 == 0) ? NAN : INFINITY;
            EXPECT_RC(quadrotor_rates_set_x0(s, bad), QUADROTOR_RATES_ERR_NONFINITE);
        }
        status = quadrotor_rates_feedback(s);
        if (status != QUADROTOR_RATES_STATUS_OK) {
            fprintf(stderr, "qrbench.c: step %d: feedback returned %d, expected %d\n", k, status,
                    QUADROTOR_RATES_STATUS_OK);
            failures++;
        }
        EXPECT_RC(quadrotor_rates_get_u0(s, u), QUADROTOR_RATES_STATUS_OK);
        if (k == 0) {
            double c0[NU];
            EXPECT_RC(quadrotor_rates_get_stats(s, &st), QUADROTOR_RATES_STATUS_OK);
            CHECK(st.status == QUADROTOR_RATES_STATUS_OK);
            CHECK(st.qp_status == 0);
            /* The first QP is solved from the empty active set (warm active set, on by
               default): no interior-point iteration is needed on QR-bench. */
            CHECK(st.qp_iterations == 0);
            CHECK(st.sqp_iterations == 1);
            CHECK(isfinite(st.res_stat) && isfinite(st.res_eq) && isfinite(st.res_ineq));
            /* The first control of the plan is the control returned. */
            EXPECT_RC(quadrotor_rates_get_control(s, 0, c0), QUADROTOR_RATES_STATUS_OK);
            CHECK(memcmp(c0, u, sizeof c0) == 0);
            check_stage_errors(s);
        }
        for (i = 0; i < NU; i++) CHECK(isfinite(u[i]));
        plant(x, u, DT, SUBSTEPS);
    }
    EXPECT_RC(quadrotor_rates_get_stats(s, &st), QUADROTOR_RATES_STATUS_OK);
    /* Solved; with no interior-point iteration where the last step's warm active set held. */
    CHECK(st.status == QUADROTOR_RATES_STATUS_OK && st.qp_status == 0);

    check_not_prepared(x0);
    check_run_time_bounds(x0);
    check_run_time_api(x0);
    free(mem);

    for (i = 0; i < NX; i++) printf(i == 0 ? "%.17g" : " %.17g", x[i]);
    printf("\n");

    /* The closed loop must have reached the hover reference (4, 0, 2). */
    CHECK(fabs(x[0] - 4.0) < 0.05 && fabs(x[1]) < 0.05 && fabs(x[2] - 2.0) < 0.05);

    if (failures > 0) {
        fprintf(stderr, "qrbench.c: %d check(s) failed\n", failures);
        return 1;
    }
    return 0;
}
