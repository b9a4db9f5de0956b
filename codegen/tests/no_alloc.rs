//! Generated solvers never touch the heap: a counting global allocator sees zero allocations
//! during construction in place, preparation, feedback, full SQP and the parameter setters.
//! Only the test's own thread is counted: the test harness's main thread allocates while the
//! test runs (seen on a loaded machine: 4 allocations that were not the solver's).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCS: AtomicUsize = AtomicUsize::new(0);
thread_local! {
    static COUNTED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

fn counted() -> bool {
    COUNTED.try_with(std::cell::Cell::get).unwrap_or(false)
}

// SAFETY: forwards to the system allocator; only counts.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if counted() {
            ALLOCS.fetch_add(1, Ordering::SeqCst);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        if counted() {
            ALLOCS.fetch_add(1, Ordering::SeqCst);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static A: Counting = Counting;

fn count(f: impl FnOnce()) -> usize {
    let before = ALLOCS.load(Ordering::SeqCst);
    COUNTED.with(|c| c.set(true));
    f();
    COUNTED.with(|c| c.set(false));
    ALLOCS.load(Ordering::SeqCst) - before
}

#[test]
fn generated_solvers_do_not_allocate() {
    // The counter counts: a Vec allocates.
    assert!(count(|| drop(std::hint::black_box(vec![1u8; 16]))) >= 1);

    let mut qr = Box::new(quadrotor_rates::Solver::unconfigured());
    let mut pm = Box::new(paper_pointmass::Solver::unconfigured());
    let mut f32s = Box::new(quadrotor_rates_f32::Solver::unconfigured());
    let n = count(|| {
        qr.configure().unwrap();
        pm.configure().unwrap();
        f32s.configure().unwrap();
        let mut x = [0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        for _ in 0..5 {
            qr.prepare();
            qr.set_x0(&x).unwrap();
            assert_eq!(qr.feedback().status, quadrotor_rates::RtiStatus::Ok);
            x[0] += 0.01;
            f32s.prepare();
            f32s.set_x0(&x.map(|v| v as f32)).unwrap();
            assert_eq!(f32s.feedback().status, quadrotor_rates_f32::RtiStatus::Ok);
        }
        qr.set_xref_all(&[1.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
            .unwrap();
        qr.solve_sqp();
        let mut xref = [0.0; 9];
        xref[0] = 1.0;
        pm.set_xref_all(&xref).unwrap();
        pm.set_u_prev(&[0.5, 0.0, 0.0]).unwrap();
        pm.set_x0(&[0.0; 9]).unwrap();
        for _ in 0..5 {
            pm.prepare();
            assert_eq!(pm.feedback().status, paper_pointmass::RtiStatus::Ok);
        }
    });
    assert_eq!(n, 0, "{n} heap allocations in generated solver calls");
}
