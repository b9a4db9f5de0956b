//! Time and heap figures for the symbolic core (`mpc-dsl`), printed as a table.
//!
//! A counting global allocator (a thin wrapper over [`System`]) tracks live and peak heap
//! bytes and the number of allocation calls, independently of the graph's own
//! [`Graph::heap_bytes`] estimate. Two workloads:
//!
//! - the reverse-mode gradient of a random 100,000-node DAG (the generator of
//!   `benches/common/random_dag.rs`, also used by the `symbolic` criterion bench): median time
//!   over 5 runs, each on a fresh graph; heap of the graph after building; peak heap during the
//!   gradient. Memory per node is the peak heap of the whole process during the gradient
//!   (arena, hash index, symbol table, the gradient's own work arrays, the benchmark's few
//!   vectors) divided by the number of nodes the graph holds once the gradient is built: the
//!   cost of a node, wherever it came from. The peak divided by the 100,000 original nodes is
//!   printed too; it is larger because the gradient adds about 3.3 nodes per node (one product
//!   per edge, one sum per extra parent, the local derivative factors);
//! - the quadrotor RK4 Jacobian pipeline (build + RK4 + Jacobian + CSE/SSA lowering) with 1
//!   and 4 substeps: median time over 50 runs from an empty graph, with a per-phase breakdown.
//!
//! Run with `cargo bench --bench symbolic_memory`. `realloc` is counted as the change in size
//! (what the program holds), not as a transient old + new copy.

#![allow(unsafe_code)] // the counting global allocator below

use std::alloc::{GlobalAlloc, Layout, System};
use std::hint::black_box;
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::time::{Duration, Instant};

use mpc_dsl::models::{quadrotor_rates, quadrotor_rates_rhs, rk4};
use mpc_dsl::{Expr, ExprKind, Graph};

#[path = "common/random_dag.rs"]
mod random_dag;

// ---------------------------------------------------------------------------------------------
// Counting allocator

static CURRENT: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
static CALLS: AtomicUsize = AtomicUsize::new(0);

/// [`System`] plus three counters: live bytes, peak live bytes, allocation calls.
struct Counting;

fn grew(bytes: usize) {
    let now = CURRENT.fetch_add(bytes, Relaxed) + bytes;
    PEAK.fetch_max(now, Relaxed);
}

fn shrank(bytes: usize) {
    CURRENT.fetch_sub(bytes, Relaxed);
}

// SAFETY: every method forwards to `System` with the caller's arguments unchanged and only
// updates counters afterwards; no pointer is touched.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: same contract as the caller's.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            CALLS.fetch_add(1, Relaxed);
            grew(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: same contract as the caller's.
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            CALLS.fetch_add(1, Relaxed);
            grew(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) };
        shrank(layout.size());
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: same contract as the caller's.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            CALLS.fetch_add(1, Relaxed);
            if new_size >= layout.size() {
                grew(new_size - layout.size());
            } else {
                shrank(layout.size() - new_size);
            }
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Live heap bytes now.
fn live() -> usize {
    CURRENT.load(Relaxed)
}

/// Starts a new peak window at the current live size.
fn reset_peak() {
    PEAK.store(CURRENT.load(Relaxed), Relaxed);
}

fn peak() -> usize {
    PEAK.load(Relaxed)
}

fn calls() -> usize {
    CALLS.load(Relaxed)
}

// ---------------------------------------------------------------------------------------------
// Helpers

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort_unstable();
    v[v.len() / 2]
}

fn ms(d: Duration) -> String {
    format!("{:.3} ms", d.as_secs_f64() * 1e3)
}

fn mib(bytes: usize) -> String {
    format!("{:.2} MiB", bytes as f64 / (1024.0 * 1024.0))
}

/// Number of nodes reachable from `roots` (the part of the graph a sweep walks).
fn reachable(g: &Graph, roots: &[Expr<'_>]) -> usize {
    let mut seen = vec![false; g.len()];
    let mut stack: Vec<Expr<'_>> = Vec::new();
    let mut count = 0;
    for &r in roots {
        if !std::mem::replace(&mut seen[r.index()], true) {
            stack.push(r);
        }
        while let Some(e) = stack.pop() {
            count += 1;
            let kids = match e.kind() {
                ExprKind::Constant(_) | ExprKind::Symbol(_) => [None, None],
                ExprKind::Unary(_, a) | ExprKind::PowI(a, _) => [Some(a), None],
                ExprKind::Binary(_, a, b) => [Some(a), Some(b)],
            };
            for c in kids.into_iter().flatten() {
                if !std::mem::replace(&mut seen[c.index()], true) {
                    stack.push(c);
                }
            }
        }
    }
    count
}

/// A two-column table: label, value.
struct Table {
    title: String,
    rows: Vec<(String, String)>,
}

impl Table {
    fn new(title: impl Into<String>) -> Table {
        Table {
            title: title.into(),
            rows: Vec::new(),
        }
    }

    fn row(&mut self, label: impl Into<String>, value: impl Into<String>) {
        self.rows.push((label.into(), value.into()));
    }

    fn print(&self) {
        let lw = self.rows.iter().map(|r| r.0.len()).max().unwrap_or(0);
        let vw = self.rows.iter().map(|r| r.1.len()).max().unwrap_or(0);
        let width = (lw + vw + 7).max(self.title.len() + 4);
        let vw = width - lw - 7;
        let rule = format!("+{}+{}+", "-".repeat(lw + 2), "-".repeat(vw + 2));
        println!("+{}+", "-".repeat(width - 2));
        println!("| {:<w$} |", self.title, w = width - 4);
        println!("{rule}");
        for (l, v) in &self.rows {
            println!("| {l:<lw$} | {v:>vw$} |");
        }
        println!("{rule}");
        println!();
    }
}

fn check(ok: bool) -> &'static str {
    if ok { "PASS" } else { "FAIL" }
}

// ---------------------------------------------------------------------------------------------
// Workloads

const DAG_NODES: usize = 100_000;
const DAG_RUNS: usize = 5;
const QR_RUNS: usize = 50;

/// Figures of one gradient run.
struct GradRun {
    time: Duration,
    nodes_before: usize,
    nodes_after: usize,
    reachable: usize,
    build_live: usize,
    heap_bytes_before: usize,
    heap_bytes_after: usize,
    grad_peak_extra: usize,
    total_peak: usize,
    live_after: usize,
    grad_calls: usize,
    nonzero_entries: usize,
}

fn gradient_run() -> GradRun {
    let base = live();
    let g = Graph::new();
    let (f, inputs) = random_dag::random_dag(&g, DAG_NODES, random_dag::SEED);
    let nodes_before = g.len();
    let reachable = reachable(&g, &[f]);
    let build_live = live() - base;
    let heap_bytes_before = g.heap_bytes();
    reset_peak();
    let calls0 = calls();
    let start = Instant::now();
    let grad = g.gradient(f, &inputs).expect("gradient");
    let time = start.elapsed();
    let grad_calls = calls() - calls0;
    let grad_peak_extra = peak() - (base + build_live);
    let total_peak = peak() - base;
    let live_after = live() - base;
    let grad = black_box(grad);
    GradRun {
        time,
        nodes_before,
        nodes_after: g.len(),
        reachable,
        build_live,
        heap_bytes_before,
        heap_bytes_after: g.heap_bytes(),
        grad_peak_extra,
        total_peak,
        live_after,
        grad_calls,
        nonzero_entries: grad.iter().filter(|e| !e.is_zero()).count(),
    }
}

fn gradient_table() -> (Duration, f64) {
    let runs: Vec<GradRun> = (0..DAG_RUNS).map(|_| gradient_run()).collect();
    let time = median(runs.iter().map(|r| r.time).collect());
    let r = &runs[0];
    for other in &runs[1..] {
        assert_eq!(other.nodes_after, r.nodes_after, "the DAG is deterministic");
    }
    let per_node = r.total_peak as f64 / r.nodes_after as f64;
    let per_original = r.total_peak as f64 / r.nodes_before as f64;
    let mut t = Table::new(format!(
        "gradient of a random {DAG_NODES}-node DAG ({} inputs, median of {DAG_RUNS} fresh graphs)",
        random_dag::INPUTS
    ));
    t.row("nodes before gradient", r.nodes_before.to_string());
    t.row("  of which reachable from f", r.reachable.to_string());
    t.row("nodes after gradient", r.nodes_after.to_string());
    t.row(
        "  new nodes per reachable node",
        format!(
            "{:.2}",
            (r.nodes_after - r.nodes_before) as f64 / r.reachable as f64
        ),
    );
    t.row(
        "nonzero gradient entries",
        format!("{} / {}", r.nonzero_entries, random_dag::INPUTS),
    );
    t.row("gradient time (median)", ms(time));
    t.row(
        "  all runs",
        runs.iter()
            .map(|r| format!("{:.1}", r.time.as_secs_f64() * 1e3))
            .collect::<Vec<_>>()
            .join(" / "),
    );
    t.row("heap after build (allocator)", mib(r.build_live));
    t.row(
        "  Graph::heap_bytes() after build",
        mib(r.heap_bytes_before),
    );
    t.row("peak extra heap during gradient", mib(r.grad_peak_extra));
    t.row("total peak (graph + gradient)", mib(r.total_peak));
    t.row("heap after gradient (allocator)", mib(r.live_after));
    t.row(
        "  Graph::heap_bytes() after gradient",
        mib(r.heap_bytes_after),
    );
    t.row("allocation calls during gradient", r.grad_calls.to_string());
    t.row(
        "total peak / nodes after gradient",
        format!("{per_node:.1} B/node"),
    );
    t.row(
        "  total peak / original node count",
        format!("{per_original:.1} B/node"),
    );
    t.row(
        "target: gradient < 1 s",
        check(time < Duration::from_secs(1)),
    );
    t.row("target: < 64 B/node", check(per_node < 64.0));
    t.print();
    (time, per_node)
}

/// Figures of one quadrotor pipeline run.
struct QrRun {
    build: Duration,
    jacobian: Duration,
    compile: Duration,
    total: Duration,
    nodes_model: usize,
    nodes_after: usize,
    nnz: usize,
    instrs: usize,
    max_live: usize,
    peak: usize,
    calls_jacobian: usize,
    calls_compile: usize,
}

fn qr_run(substeps: usize) -> QrRun {
    let base = live();
    reset_peak();
    let t0 = Instant::now();
    let g = Graph::new();
    let model = quadrotor_rates(&g).expect("quadrotor model");
    let xnext = rk4(&model.x, 0.04, substeps, |x| {
        quadrotor_rates_rhs(x, &model.u)
    })
    .expect("rk4 discretization");
    let wrt: Vec<_> = model.x.iter().chain(model.u.iter()).copied().collect();
    let nodes_model = g.len();
    let t1 = Instant::now();
    let c1 = calls();
    let jac = g.jacobian(&xnext, &wrt).expect("jacobian");
    let t2 = Instant::now();
    let c2 = calls();
    let program = g.compile(jac.values(), &wrt).expect("lowering to SSA");
    let t3 = Instant::now();
    let c3 = calls();
    let program = black_box(program);
    QrRun {
        build: t1 - t0,
        jacobian: t2 - t1,
        compile: t3 - t2,
        total: t3 - t0,
        nodes_model,
        nodes_after: g.len(),
        nnz: jac.nnz(),
        instrs: program.instrs().len(),
        max_live: program.max_live(),
        peak: peak() - base,
        calls_jacobian: c2 - c1,
        calls_compile: c3 - c2,
    }
}

fn qr_table(substeps: usize) -> Duration {
    // One untimed warm-up run, then the measured ones.
    let _ = qr_run(substeps);
    let runs: Vec<QrRun> = (0..QR_RUNS).map(|_| qr_run(substeps)).collect();
    let med = |f: fn(&QrRun) -> Duration| median(runs.iter().map(f).collect());
    let total = med(|r| r.total);
    let r = &runs[0];
    let mut t = Table::new(format!(
        "quadrotor RK4 Jacobian -> SSA, h = 0.04 s, {substeps} substep(s) (median of {QR_RUNS})"
    ));
    t.row("total: build + jacobian + CSE/SSA", ms(total));
    t.row("  model + RK4 build", ms(med(|r| r.build)));
    t.row("  jacobian (10 x 14)", ms(med(|r| r.jacobian)));
    t.row("  compile (CSE/SSA lowering)", ms(med(|r| r.compile)));
    t.row("nodes: model + RK4", r.nodes_model.to_string());
    t.row("nodes: after jacobian", r.nodes_after.to_string());
    t.row("jacobian nnz", format!("{} / 140", r.nnz));
    t.row("SSA instructions", r.instrs.to_string());
    t.row("max live temporaries", r.max_live.to_string());
    t.row("peak heap (whole pipeline)", mib(r.peak));
    t.row("allocation calls in jacobian", r.calls_jacobian.to_string());
    t.row("allocation calls in compile", r.calls_compile.to_string());
    t.row(
        "target: total < 5 ms",
        check(total < Duration::from_millis(5)),
    );
    t.print();
    total
}

fn main() {
    // `cargo bench` passes `--bench`; nothing else is accepted.
    let qr1 = qr_table(1);
    let qr4 = qr_table(4);
    let (grad, per_node) = gradient_table();
    let mut s = Table::new("summary");
    s.row(
        "QR RK4 (1 substep) Jacobian built + CSE + SSA < 5 ms",
        format!("{} {}", ms(qr1), check(qr1 < Duration::from_millis(5))),
    );
    s.row("QR RK4 (4 substeps), for reference", ms(qr4));
    s.row(
        "100k-node gradient < 1 s",
        format!("{} {}", ms(grad), check(grad < Duration::from_secs(1))),
    );
    s.row(
        "100k-node gradient < 64 B/node (peak / graph nodes)",
        format!("{per_node:.1} B/node {}", check(per_node < 64.0)),
    );
    s.print();
}
