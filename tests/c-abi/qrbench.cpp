// The C header of the generated `quadrotor_rates` solver from C++17: it must compile with
// `g++ -std=c++17 -Wall -Wextra -Werror -pedantic`, and its `extern "C"` declarations must
// link against the Rust static library. Runs one real-time iteration from the QR-bench x0.
#include "quadrotor_rates.h"

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <new>

namespace {

struct AlignedFree {
    std::size_t align;
    void operator()(void *p) const { ::operator delete(p, std::align_val_t(align)); }
};

int fail(const char *what, int rc) {
    std::fprintf(stderr, "qrbench.cpp: %s returned %d\n", what, rc);
    return 1;
}

}  // namespace

int main() {
    const std::size_t align = quadrotor_rates_memalign();
    const std::size_t size = (quadrotor_rates_memsize() + align - 1) / align * align;
    std::unique_ptr<void, AlignedFree> mem(::operator new(size, std::align_val_t(align)),
                                           AlignedFree{align});

    quadrotor_rates_solver *s = nullptr;
    int rc = quadrotor_rates_create(mem.get(), size, &s);
    if (rc != 0 || s == nullptr) return fail("quadrotor_rates_create", rc);

    const std::array<quadrotor_rates_real, QUADROTOR_RATES_NX> x0{0.0, 0.0, 2.0, 1.0, 0.0,
                                                                   0.0, 0.0, 0.0, 0.0, 0.0};
    std::array<quadrotor_rates_real, QUADROTOR_RATES_NU> u{};
    if ((rc = quadrotor_rates_set_guess(s, x0.data(), u.data())) != 0)
        return fail("quadrotor_rates_set_guess", rc);
    if ((rc = quadrotor_rates_prepare(s)) != 0) return fail("quadrotor_rates_prepare", rc);
    if ((rc = quadrotor_rates_set_x0(s, x0.data())) != 0)
        return fail("quadrotor_rates_set_x0", rc);
    if ((rc = quadrotor_rates_feedback(s)) != QUADROTOR_RATES_STATUS_OK)
        return fail("quadrotor_rates_feedback", rc);
    if ((rc = quadrotor_rates_get_u0(s, u.data())) != 0)
        return fail("quadrotor_rates_get_u0", rc);
    quadrotor_rates_stats st{};
    if ((rc = quadrotor_rates_get_stats(s, &st)) != 0)
        return fail("quadrotor_rates_get_stats", rc);
    // The QP solved (from the empty active set: no interior-point iteration on QR-bench).
    if (st.qp_status != 0 || st.sqp_iterations != 1) {
        std::fprintf(stderr, "qrbench.cpp: stats: QP status %d, %u SQP iterations\n",
                     static_cast<int>(st.qp_status), st.sqp_iterations);
        return 1;
    }
    if (quadrotor_rates_set_x0(nullptr, x0.data()) != QUADROTOR_RATES_ERR_NULL)
        return fail("quadrotor_rates_set_x0(nullptr)", -1);
    for (quadrotor_rates_real e : u) {
        if (!std::isfinite(e)) return fail("quadrotor_rates_get_u0 (non-finite control)", 0);
    }
    // Thrust within its bounds [0, 20] m/s^2.
    const quadrotor_rates_real c = u[QUADROTOR_RATES_CONTROL_C];
    if (!(c >= 0.0 && c <= 20.0)) return fail("quadrotor_rates_get_u0 (thrust out of bounds)", 0);
    std::printf("u0 = %.17g %.17g %.17g %.17g\n", u[0], u[1], u[2], u[3]);
    return 0;
}
