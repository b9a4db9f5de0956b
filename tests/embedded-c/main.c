/*
 * Bare-metal C firmware: flies the f32 QR-bench closed loop (100 steps of 0.04 s, from
 * (0, 0, 2) to hover at (4, 0, 2)) through the C ABI of the generated solver
 * `quadrotor_rates_f32`, linked as a static library built for thumbv7em-none-eabihf, on an
 * emulated Cortex-M4F (qemu mps2-an386). It mirrors the Rust firmware tests/embedded/src/main.rs
 * line for line: the same loop and plant (tests/embedded/src/plant.rs, the f32 operations in
 * the same order), the same SysTick instruction count (qemu -icount shift=0: 40 instructions
 * per tick), stack painting and output lines, so tests/embedded_c.rs compares the two.
 */
#include <stddef.h>
#include <stdint.h>

#include "quadrotor_rates_f32.h"
#include "semihosting.h"

#define NX QUADROTOR_RATES_F32_NX
#define NU QUADROTOR_RATES_F32_NU
/* The solver's interval (the header states it in its comment; the crate's `DT`). */
#define DT 0.04f
/* Instructions per SysTick tick: 1 ns per instruction (icount shift=0) at 25 MHz. */
#define INSNS_PER_TICK 40u
#define STEPS 100
#define PAINT 0xDEADBEEFu
#define PAINT_MARGIN 256u
/* Bytes of the solver's static memory: at least memsize() (checked at start; the test sets
   it to the Rust firmware's size_of::<Solver>()). */
#ifndef SOLVER_BYTES
#define SOLVER_BYTES 32768
#endif

#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)
#define CPUID (*(volatile uint32_t *)0xE000ED00u)
#define CPACR (*(volatile uint32_t *)0xE000ED88u)
#define DEMCR (*(volatile uint32_t *)0xE000EDFCu)
#define DWT_CTRL (*(volatile uint32_t *)0xE0001000u)
#define DWT_CYCCNT (*(volatile uint32_t *)0xE0001004u)

extern uint32_t _stack_start, _stack_end, __sbss, __ebss, __sdata;

/* The solver's memory: zero-filled .bss, like the Rust firmware's static. */
static unsigned char solver_memory[SOLVER_BYTES] __attribute__((aligned(8)));

/* ---- output: one line at a time over semihosting, no printf ---- */

static char line[256];
static size_t len;

static void put(const char *s) {
    while (*s && len < sizeof line - 2) line[len++] = *s++;
}

static void put_u(uint32_t v) {
    char d[10];
    int n = 0;
    do {
        d[n++] = (char)('0' + v % 10);
        v /= 10;
    } while (v);
    while (n && len < sizeof line - 2) line[len++] = d[--n];
}

static void put_hex(uint32_t v, int width) {
    int i;
    for (i = width - 1; i >= 0; i--) {
        uint32_t nib = (v >> (4 * i)) & 0xF;
        if (len < sizeof line - 2) line[len++] = (char)(nib < 10 ? '0' + nib : 'a' + nib - 10);
    }
}

static void end_line(void) {
    line[len++] = '\n';
    line[len] = 0;
    sh_write(line);
    len = 0;
}

/* ---- counters and the stack ---- */

static uint32_t now(void) {
    uint32_t t;
    __asm__ volatile("" ::: "memory");
    t = SYST_CVR;
    __asm__ volatile("" ::: "memory");
    return t;
}

/* SysTick ticks elapsed since `start` (the counter counts down, 24 bits). */
static uint32_t ticks_since(uint32_t start) { return (start - SYST_CVR) & 0x00FFFFFFu; }

static uintptr_t stack_pointer(void) {
    uintptr_t sp;
    __asm__ volatile("mov %0, sp" : "=r"(sp));
    return sp;
}

/* Fills the unused stack (from its bottom to a margin below the current SP) with PAINT. */
__attribute__((noinline)) static void paint_stack(void) {
    uintptr_t p = (uintptr_t)&_stack_end;
    uintptr_t sp = stack_pointer();
    while (p + PAINT_MARGIN < sp) {
        *(volatile uint32_t *)p = PAINT;
        p += 4;
    }
}

/* Bytes of stack used since the last paint_stack. */
static uint32_t stack_high_water(void) {
    uintptr_t p = (uintptr_t)&_stack_end, top = (uintptr_t)&_stack_start;
    while (p < top && *(volatile uint32_t *)p == PAINT) p += 4;
    return (uint32_t)(top - p);
}

/* n + 1 iterations of `subs; bne`: 2n + 2 instructions (as cortex-m's asm::delay(n)). */
static void delay(uint32_t n) {
    uint32_t r = n + 1;
    __asm__ volatile("1:\n\tsubs %0, #1\n\tbne 1b" : "+r"(r)::"cc");
}

/* ---- the plant: tests/embedded/src/plant.rs in C ---- */

static void f(const float x[NX], const float u[NU], float out[NX]) {
    const float qw = x[3], qx = x[4], qy = x[5], qz = x[6];
    const float c = u[0], wx = u[1], wy = u[2], wz = u[3];
    out[0] = x[7];
    out[1] = x[8];
    out[2] = x[9];
    out[3] = 0.5f * (-qx * wx - qy * wy - qz * wz);
    out[4] = 0.5f * (qw * wx + qy * wz - qz * wy);
    out[5] = 0.5f * (qw * wy - qx * wz + qz * wx);
    out[6] = 0.5f * (qw * wz + qx * wy - qy * wx);
    out[7] = 2.0f * (qw * qy + qx * qz) * c;
    out[8] = 2.0f * (qy * qz - qw * qx) * c;
    out[9] = (1.0f - 2.0f * (qx * qx + qy * qy)) * c - 9.81f;
}

/* 10 RK4 substeps over dt, in place. */
static void plant(float x[NX], const float u[NU], float dt) {
    const float h = dt / 10.0f;
    float k1[NX], k2[NX], k3[NX], k4[NX], t[NX];
    int s, i;
    for (s = 0; s < 10; s++) {
        f(x, u, k1);
        for (i = 0; i < NX; i++) t[i] = x[i] + h / 2.0f * k1[i];
        f(t, u, k2);
        for (i = 0; i < NX; i++) t[i] = x[i] + h / 2.0f * k2[i];
        f(t, u, k3);
        for (i = 0; i < NX; i++) t[i] = x[i] + h * k3[i];
        f(t, u, k4);
        for (i = 0; i < NX; i++)
            x[i] = x[i] + h / 6.0f * (k1[i] + 2.0f * k2[i] + 2.0f * k3[i] + k4[i]);
    }
}

static uint32_t sat_add(uint32_t a, uint32_t b) { return a + b < a ? UINT32_MAX : a + b; }

static uint32_t sat_mul(uint32_t a, uint32_t b) {
    return b != 0 && a > UINT32_MAX / b ? UINT32_MAX : a * b;
}

static uint32_t max_u(uint32_t a, uint32_t b) { return a > b ? a : b; }

static uint32_t float_bits(float v) {
    union {
        float f;
        uint32_t u;
    } b;
    b.f = v;
    return b.u;
}

int main(void) {
    quadrotor_rates_f32_solver *solver = NULL;
    quadrotor_rates_f32_stats stats;
    float x[NX] = {0.0f, 0.0f, 2.0f, 1.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f};
    float u[NU];
    uint32_t cpacr, c0, t, calib, n = 2000000u, stack_setup, stack_loop, statics, stack;
    uint32_t iterations = 0, prep_sum = 0, prep_max = 0, fb_sum = 0, fb_max = 0;
    uint32_t rti_max = 0, rti_min = UINT32_MAX, stack_prepare = 0, stack_feedback = 0;
    uintptr_t at = (uintptr_t)solver_memory;
    int all_ok = 1, fpu_on, k, i;
    float d0, d1, d2, err;

    paint_stack();
    cpacr = CPACR;
    fpu_on = ((cpacr >> 20) & 0xF) == 0xF;
    put("fpu: CPACR=0x");
    put_hex(cpacr, 8);
    put(" enabled=");
    put(fpu_on ? "true" : "false");
    end_line();
    put("cpuid: 0x");
    put_hex(CPUID, 8);
    end_line();

    SYST_RVR = 0x00FFFFFFu;
    SYST_CVR = 0;
    SYST_CSR = 0x5u; /* processor clock, enabled, no interrupt */

    DEMCR |= 1u << 24; /* TRCENA */
    DWT_CTRL |= 1u;    /* CYCCNTENA */
    c0 = DWT_CYCCNT;

    t = now();
    delay(n);
    calib = ticks_since(t);
    put("calib: ");
    put_u(2 * n + 2);
    put(" instructions = ");
    put_u(calib);
    put(" ticks (expected ");
    put_u((2 * n + 2) / INSNS_PER_TICK);
    put("); DWT CYCCNT delta ");
    put_u(DWT_CYCCNT - c0);
    end_line();

    if (quadrotor_rates_f32_memsize() > sizeof solver_memory ||
        quadrotor_rates_f32_create(solver_memory, sizeof solver_memory, &solver) != 0) {
        put("create failed: memsize ");
        put_u((uint32_t)quadrotor_rates_f32_memsize());
        put(" B, memalign ");
        put_u((uint32_t)quadrotor_rates_f32_memalign());
        put(" B, SOLVER_BYTES ");
        put_u(SOLVER_BYTES);
        end_line();
        return 1;
    }
    put("main: stack pointer ");
    put_u((uint32_t)((uintptr_t)&_stack_start - stack_pointer()));
    put(" B below the top");
    end_line();
    put("solver: ");
    put_u((uint32_t)quadrotor_rates_f32_memsize());
    put(" bytes (static, buffer ");
    put_u(SOLVER_BYTES);
    put(" B) in ");
    put((uintptr_t)&__sbss <= at && at + sizeof solver_memory <= (uintptr_t)&__ebss ? ".bss"
                                                                                    : "not .bss");
    end_line();
    stack_setup = stack_high_water();
    paint_stack();

    for (k = 0; k < STEPS; k++) {
        uint32_t t0, t1, prep, fb;
        int set, status;
        if (k == 0) paint_stack();
        t0 = now();
        quadrotor_rates_f32_prepare(solver);
        prep = ticks_since(t0);
        if (k == 0) {
            stack_prepare = stack_high_water();
            paint_stack();
        }
        t1 = now();
        set = quadrotor_rates_f32_set_x0(solver, x);
        status = quadrotor_rates_f32_feedback(solver);
        fb = ticks_since(t1);
        if (k == 0) stack_feedback = stack_high_water();
        if (set != 0) {
            put("step ");
            put_u((uint32_t)k);
            put(": non-finite state");
            end_line();
            return 1;
        }
        quadrotor_rates_f32_get_stats(solver, &stats);
        all_ok &= status == QUADROTOR_RATES_F32_STATUS_OK;
        iterations += stats.qp_iterations;
        prep_sum = sat_add(prep_sum, prep);
        fb_sum = sat_add(fb_sum, fb);
        prep_max = max_u(prep_max, prep);
        fb_max = max_u(fb_max, fb);
        rti_max = max_u(rti_max, prep + fb);
        rti_min = prep + fb < rti_min ? prep + fb : rti_min;
        put("step ");
        put_u((uint32_t)k);
        put(" status=");
        if (status == QUADROTOR_RATES_F32_STATUS_OK) {
            put("Ok");
        } else {
            put("code");
            put_u((uint32_t)status);
        }
        put(" iters=");
        put_u(stats.qp_iterations);
        put(" prepare_ticks=");
        put_u(prep);
        put(" feedback_ticks=");
        put_u(fb);
        end_line();
        quadrotor_rates_f32_get_u0(solver, u);
        plant(x, u, DT);
    }
    stack_loop = stack_high_water();

    d0 = x[0] - 4.0f;
    d1 = x[1];
    d2 = x[2] - 2.0f;
    err = __builtin_sqrtf(d0 * d0 + d1 * d1 + d2 * d2);
    put("steps=");
    put_u(STEPS);
    put(" all_ok=");
    put(all_ok ? "true" : "false");
    put(" qp_iters=");
    put_u(iterations);
    put(" (mean x100: ");
    put_u(iterations * 100 / STEPS);
    put(")");
    end_line();
    put("pos_err_um=");
    put_u((uint32_t)(err * 1e6f + 0.5f));
    end_line();
    put("x_final_bits=[");
    for (i = 0; i < NX; i++) {
        if (i) put(", ");
        put_hex(float_bits(x[i]), 8);
    }
    put("]");
    end_line();
    put("insns/RTI step: mean=");
    put_u(sat_mul(sat_add(prep_sum, fb_sum), INSNS_PER_TICK) / STEPS);
    put(" min=");
    put_u(sat_mul(rti_min, INSNS_PER_TICK));
    put(" max=");
    put_u(sat_mul(rti_max, INSNS_PER_TICK));
    end_line();
    put("insns prepare: mean=");
    put_u(sat_mul(prep_sum, INSNS_PER_TICK) / STEPS);
    put(" max=");
    put_u(sat_mul(prep_max, INSNS_PER_TICK));
    put("; feedback (set_x0+feedback): mean=");
    put_u(sat_mul(fb_sum, INSNS_PER_TICK) / STEPS);
    put(" max=");
    put_u(sat_mul(fb_max, INSNS_PER_TICK));
    end_line();
    put("stack high-water: setup=");
    put_u(stack_setup);
    put(" B, loop=");
    put_u(stack_loop);
    put(" B (prepare ");
    put_u(stack_prepare);
    put(" B, set_x0+feedback ");
    put_u(stack_feedback);
    put(" B; region ");
    put_u((uint32_t)((uintptr_t)&_stack_start - (uintptr_t)&_stack_end));
    put(" B)");
    end_line();
    statics = (uint32_t)((uintptr_t)&__ebss - (uintptr_t)&__sdata);
    stack = max_u(max_u(stack_setup, stack_loop), max_u(stack_prepare, stack_feedback));
    put("ram: static=");
    put_u(statics);
    put(" B (.data+.bss), stack=");
    put_u(stack);
    put(" B, total=");
    put_u(statics + stack);
    put(" B");
    end_line();
    put("DONE");
    end_line();
    return all_ok && fpu_on ? 0 : 1;
}
