//! Bare-metal proof: flies the f32 QR-bench closed loop (100 steps of 0.04 s, from (0, 0, 2)
//! to hover at (4, 0, 2)) with the generated solver `generated/quadrotor_rates_f32` on a
//! Cortex-M4F (qemu `mps2-an386`; the same binary runs on the Cortex-M7 `mps2-an500`) and
//! prints, over semihosting, the per-step status, QP iterations and SysTick counts of
//! `prepare` and `set_x0` + `feedback`, then a summary, the final state and the stack
//! high-water mark. The loop mirrors `examples/build-rs/src/main.rs` exactly;
//! `host_check.rs` flies it on the host and compares.
//!
//! Counter: qemu does not implement the DWT cycle counter; its SysTick runs from the
//! board's 25 MHz system clock in *virtual* time, and under `-icount shift=0` one
//! instruction is 1 ns of virtual time, so one SysTick tick is 40 instructions. The firmware
//! checks that scale at start against `cortex_m::asm::delay` (a loop of known length).
#![no_std]
#![no_main]
#![deny(unsafe_op_in_unsafe_fn)]

use core::sync::atomic::{Ordering, compiler_fence};

use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_rt::{ExceptionFrame, entry, exception};
use cortex_m_semihosting::{debug, hprintln};
use panic_semihosting as _;
use quadrotor_rates_f32::{DT, NX_MODEL, Real, RtiStatus, Solver};

mod plant;
use plant::plant;

/// Instructions per SysTick tick: 1 ns per instruction (icount shift=0) at 25 MHz.
const INSNS_PER_TICK: u32 = 40;
/// Control steps flown.
const STEPS: usize = 100;
/// Stack paint pattern.
const PAINT: u32 = 0xDEAD_BEEF;
/// Words left unpainted below the painting function's stack pointer.
const PAINT_MARGIN: usize = 256;

/// SysTick ticks elapsed since `start` (the counter counts down, 24 bits).
fn ticks_since(start: u32) -> u32 {
    start.wrapping_sub(SYST::get_current()) & 0x00FF_FFFF
}

/// Reads SysTick with compiler fences, so the measured code is not moved across it.
fn now() -> u32 {
    compiler_fence(Ordering::SeqCst);
    let t = SYST::get_current();
    compiler_fence(Ordering::SeqCst);
    t
}

// The stack region from cortex-m-rt's linker script: `_stack_end` (lowest address, after
// .bss/.uninit) to `_stack_start` (initial SP, top of RAM). Only their addresses are used.
unsafe extern "C" {
    static _stack_start: u32;
    static _stack_end: u32;
    // The zero-filled section (.bss): cortex-m-rt's reset handler zeroes it, nothing is
    // copied from flash.
    static __sbss: u32;
    static __ebss: u32;
    // The start of .data, the first section in RAM.
    static __sdata: u32;
}

fn stack_bounds() -> (usize, usize) {
    (
        (&raw const _stack_end) as usize,
        (&raw const _stack_start) as usize,
    )
}

/// Fills the unused stack (from its bottom to a margin below the current SP) with `PAINT`.
#[inline(never)]
fn paint_stack() {
    let (bottom, _) = stack_bounds();
    let sp = cortex_m::register::msp::read() as usize;
    let mut p = bottom;
    while p + PAINT_MARGIN < sp {
        // SAFETY: `p` is word-aligned, in RAM, and below the live stack (no interrupts are
        // enabled, so nothing else uses the stack below SP meanwhile).
        unsafe { (p as *mut u32).write_volatile(PAINT) };
        p += 4;
    }
}

/// Bytes of stack used since the last `paint_stack`: from the top down to the lowest word
/// that no longer holds the pattern.
fn stack_high_water() -> usize {
    let (bottom, top) = stack_bounds();
    let mut p = bottom;
    // SAFETY: reads word-aligned RAM inside the stack region.
    while p < top && unsafe { (p as *const u32).read_volatile() } == PAINT {
        p += 4;
    }
    top - p
}

#[entry]
fn main() -> ! {
    // The solver in a `static`, initialized from the `const` `Solver::unconfigured()`, whose
    // bits are all zero: it is in .bss (zeroed at reset, no image in flash), and no
    // solver-sized temporary ever lives on the stack. cortex-m-rt hands `static mut`s of the
    // entry function out as `&'static mut`.
    static mut SOLVER: Solver = Solver::unconfigured();
    paint_stack();
    let mut cp = cortex_m::Peripherals::take().unwrap();

    // FPU: cortex-m-rt's reset handler grants CP10/CP11 full access on eabihf targets.
    let cpacr = cp.SCB.cpacr.read();
    let fpu_on = (cpacr >> 20) & 0xF == 0xF;
    hprintln!("fpu: CPACR={:#010x} enabled={}", cpacr, fpu_on);
    hprintln!("cpuid: {:#010x}", cp.CPUID.base.read());

    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(0x00FF_FFFF);
    cp.SYST.clear_current();
    cp.SYST.enable_counter();

    // DWT cycle counter probe (qemu: not implemented, reads 0).
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();
    let c0 = cortex_m::peripheral::DWT::cycle_count();

    // Calibration: cortex-m 0.7.10's delay(n) runs n + 1 iterations of `subs; bne`,
    // 2n + 2 instructions.
    let n = 2_000_000u32;
    let t = now();
    cortex_m::asm::delay(n);
    let calib = ticks_since(t);
    let dwt = cortex_m::peripheral::DWT::cycle_count().wrapping_sub(c0);
    hprintln!(
        "calib: {} instructions = {} ticks (expected {}); DWT CYCCNT delta {}",
        2 * n + 2,
        calib,
        (2 * n + 2) / INSNS_PER_TICK,
        dwt
    );

    let solver: &'static mut Solver = SOLVER;
    if solver.configure().is_err() {
        hprintln!("configure failed");
        debug::exit(debug::EXIT_FAILURE);
    }
    hprintln!(
        "main: stack pointer {} B below the top",
        stack_bounds().1 - cortex_m::register::msp::read() as usize
    );
    let at = (&raw const *solver) as usize;
    let bss = ((&raw const __sbss) as usize, (&raw const __ebss) as usize);
    let size = core::mem::size_of::<Solver>();
    hprintln!(
        "solver: {} bytes (static) in {}",
        size,
        if bss.0 <= at && at + size <= bss.1 {
            ".bss"
        } else {
            "not .bss"
        }
    );
    let stack_setup = stack_high_water();
    paint_stack();

    let mut x: [Real; NX_MODEL] = [0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let mut iterations = 0u32;
    let mut all_ok = true;
    // Ticks, not instructions, and u32 throughout: u64 arithmetic and printing would add 1 KB
    // of flash (this closed loop sums to some 25 M ticks; the products below saturate).
    let (mut prep_sum, mut prep_max, mut fb_sum, mut fb_max) = (0u32, 0u32, 0u32, 0u32);
    let (mut rti_max, mut rti_min) = (0u32, u32::MAX);
    let (mut stack_prepare, mut stack_feedback) = (0, 0);
    for k in 0..STEPS {
        // Step 0 also measures the stack of prepare and of set_x0 + feedback alone
        // (outside the timed sections).
        if k == 0 {
            paint_stack();
        }
        let t0 = now();
        solver.prepare();
        let prep = ticks_since(t0);
        if k == 0 {
            stack_prepare = stack_high_water();
            paint_stack();
        }
        let t1 = now();
        let set = solver.set_x0(&x);
        let info = solver.feedback();
        let fb = ticks_since(t1);
        if k == 0 {
            stack_feedback = stack_high_water();
        }
        if set.is_err() {
            hprintln!("step {}: non-finite state", k);
            debug::exit(debug::EXIT_FAILURE);
        }
        all_ok &= info.status == RtiStatus::Ok;
        iterations += info.qp.iterations;
        prep_sum = prep_sum.saturating_add(prep);
        fb_sum = fb_sum.saturating_add(fb);
        prep_max = prep_max.max(prep);
        fb_max = fb_max.max(fb);
        rti_max = rti_max.max(prep + fb);
        rti_min = rti_min.min(prep + fb);
        hprintln!(
            "step {} status={:?} iters={} prepare_ticks={} feedback_ticks={}",
            k,
            info.status,
            info.qp.iterations,
            prep,
            fb
        );
        x = plant(&x, &solver.u0(), DT);
    }
    let stack_loop = stack_high_water();

    let d = [x[0] - 4.0, x[1], x[2] - 2.0];
    let err = libm::sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    let ipt = INSNS_PER_TICK;
    let steps = STEPS as u32;
    // No float formatting (core::fmt's is large; README.md here has its size): the mean as
    // hundredths, the error in micrometres, the final state as the bits of each f32 (exact).
    hprintln!(
        "steps={} all_ok={} qp_iters={} (mean x100: {})",
        STEPS,
        all_ok,
        iterations,
        iterations * 100 / STEPS as u32
    );
    hprintln!("pos_err_um={}", (err * 1e6 + 0.5) as u32);
    hprintln!("x_final_bits={:08x?}", x.map(Real::to_bits));
    hprintln!(
        "insns/RTI step: mean={} min={} max={}",
        prep_sum.saturating_add(fb_sum).saturating_mul(ipt) / steps,
        rti_min.saturating_mul(ipt),
        rti_max.saturating_mul(ipt)
    );
    hprintln!(
        "insns prepare: mean={} max={}; feedback (set_x0+feedback): mean={} max={}",
        prep_sum.saturating_mul(ipt) / steps,
        prep_max.saturating_mul(ipt),
        fb_sum.saturating_mul(ipt) / steps,
        fb_max.saturating_mul(ipt)
    );
    let (bottom, top) = stack_bounds();
    hprintln!(
        "stack high-water: setup={} B, loop={} B (prepare {} B, set_x0+feedback {} B; region {} B)",
        stack_setup,
        stack_loop,
        stack_prepare,
        stack_feedback,
        top - bottom
    );
    // RAM in use: the static sections (.data, .bss) and the deepest stack mark. The loop's
    // mark starts after step 0's prepare (repainted there to measure set_x0 + feedback
    // alone), so that prepare's own mark counts too: it is the deepest where a later
    // prepare never goes as deep.
    let statics = (&raw const __ebss) as usize - (&raw const __sdata) as usize;
    let stack = stack_setup
        .max(stack_loop)
        .max(stack_prepare)
        .max(stack_feedback);
    hprintln!(
        "ram: static={} B (.data+.bss), stack={} B, total={} B",
        statics,
        stack,
        statics + stack
    );
    hprintln!("DONE");
    debug::exit(if all_ok && fpu_on {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    loop {
        cortex_m::asm::wfi();
    }
}

#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    hprintln!("HardFault: {:?}", ef);
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}
