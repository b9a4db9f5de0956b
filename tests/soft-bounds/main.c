/*
 * The soft-bounds test's C program (tests/soft_bounds.rs): the soft bounds' penalties of
 * soft_box.mpc's solver through the C ABI, set, read back and refused, then a solve with
 * the state's bound holding exactly (L1 above its multiplier). stdout: "x1 <x_1>"; the exit
 * status is 1 if a check failed.
 */
#include "soft_box.h"
#include <math.h>
#include <stddef.h>
#include <stdio.h>

static union {
    max_align_t align;
    unsigned char bytes[1 << 16];
} memory;

static int failed = 0;

static void check(int ok, const char *what) {
    if (!ok) {
        fprintf(stderr, "check failed: %s\n", what);
        failed = 1;
    }
}

int main(void) {
    soft_box_solver *s = NULL;
    double l1[SOFT_BOX_NSBX], l2[SOFT_BOX_NSBX], x[SOFT_BOX_NX] = {0.0}, lb[1], ub[1];
    const double nan_ = NAN, one = 1.0, neg = -1.0, zero = 0.0, big = 10.0;
    if (soft_box_create(memory.bytes, sizeof memory.bytes, &s) != 0) {
        fprintf(stderr, "create failed\n");
        return 1;
    }
    check(SOFT_BOX_NSBX == 1 && SOFT_BOX_NSBU == 1 && SOFT_BOX_NG == 0, "sizes");
    check(soft_box_get_state_bound_penalties(s, l1, l2) == 0, "get");
    check(l1[0] == 0.0 && l2[0] == 10.0, "the model's penalties");
    check(soft_box_get_control_bound_penalties(s, l1, l2) == 0, "get control");
    check(l1[0] == 5.0 && l2[0] == 0.0, "the model's control penalties");
    check(soft_box_set_state_bound_penalties(s, &nan_, &one) == SOFT_BOX_ERR_NONFINITE, "NaN");
    check(soft_box_set_state_bound_penalties(s, &neg, &one) == SOFT_BOX_ERR_INPUT, "negative");
    check(soft_box_set_state_bound_penalties(s, &zero, &zero) == SOFT_BOX_ERR_INPUT, "zeros");
    check(soft_box_set_state_bound_penalties(s, NULL, &one) == SOFT_BOX_ERR_NULL, "NULL");
    check(soft_box_set_control_bound_penalties(s, &neg, &one) == SOFT_BOX_ERR_INPUT, "u neg");
    check(soft_box_get_state_bound_penalties(s, l1, l2) == 0, "get again");
    check(l1[0] == 0.0 && l2[0] == 10.0, "refusals changed nothing");
    check(soft_box_set_state_bound_penalties(s, &big, &zero) == 0, "set");
    check(soft_box_get_state_bound_penalties(s, l1, l2) == 0, "get after set");
    check(l1[0] == 10.0 && l2[0] == 0.0, "read back");
    /* The state's bound through the bound setter, as a hard one's. */
    lb[0] = -INFINITY;
    ub[0] = 0.5;
    check(soft_box_set_state_bounds(s, lb, ub) == 0, "set_state_bounds");
    lb[0] = ub[0] = 0.0;
    check(soft_box_get_state_bounds(s, lb, ub) == 0 && ub[0] == 0.5, "get_state_bounds");
    check(soft_box_set_x0(s, x) == 0, "set_x0");
    check(soft_box_solve_sqp(s) == SOFT_BOX_STATUS_OK, "solve_sqp");
    check(soft_box_get_state(s, 3, x) == 0, "get_state");
    printf("x3 %.17g\n", x[0]);
    return failed;
}
