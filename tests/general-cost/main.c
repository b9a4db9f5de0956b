/* The generated C ABI of tests/data/pendulum_cost.mpc (general cost terms, exact Hessian):
 * solve_sqp from x0 = (1, 0) with tight tolerances, then print the cost read-out, the
 * iterations and the trajectory (one line per stage: th om [tau]). tests/general_cost.rs
 * compares them with IPOPT's solution. */
#include <stdio.h>
#include <stdlib.h>

#include "pendulum_cost.h"

int main(void) {
    void *mem = aligned_alloc(pendulum_cost_memalign(),
                              (pendulum_cost_memsize() + pendulum_cost_memalign() - 1) /
                                  pendulum_cost_memalign() * pendulum_cost_memalign());
    pendulum_cost_solver *s = NULL;
    if (mem == NULL || pendulum_cost_create(mem, pendulum_cost_memsize(), &s) != 0) {
        return 2;
    }
    pendulum_cost_settings settings;
    if (pendulum_cost_get_settings(s, &settings) != 0) {
        return 3;
    }
    settings.sqp_max_iter = 200;
    settings.sqp_tol = 1e-11;
    settings.sqp_kkt_tol = 1e-10;
    if (pendulum_cost_set_settings(s, &settings) != 0) {
        return 4;
    }
    const double x0[2] = {1.0, 0.0};
    if (pendulum_cost_set_x0(s, x0) != 0) {
        return 5;
    }
    if (pendulum_cost_solve_sqp(s) != 0) {
        return 6;
    }
    double cost = 0.0;
    pendulum_cost_stats stats;
    if (pendulum_cost_get_cost(s, &cost) != 0 || pendulum_cost_get_stats(s, &stats) != 0) {
        return 7;
    }
    printf("cost %.17g iterations %u\n", cost, stats.sqp_iterations);
    for (int k = 0; k <= 30; k++) {
        double x[2], u[1];
        if (pendulum_cost_get_state(s, k, x) != 0) {
            return 8;
        }
        if (k < 30) {
            if (pendulum_cost_get_control(s, k, u) != 0) {
                return 9;
            }
            printf("%.17g %.17g %.17g\n", x[0], x[1], u[0]);
        } else {
            printf("%.17g %.17g\n", x[0], x[1]);
        }
    }
    free(mem);
    return 0;
}
