//! A deterministic random expression DAG with heavy sharing, shared by the `symbolic` and
//! `symbolic_memory` benchmarks (included in each with `#[path = "common/random_dag.rs"]`).
//!
//! The generator starts from [`INPUTS`] symbols and grows a pool of expressions: each step
//! picks an operation from `+ - * / sin cos exp tanh sqrt powi(2) atan2 min max` and operands
//! drawn mostly from the most recent [`WINDOW`] pool entries (so the graph is deep) and
//! sometimes from anywhere in the pool (so old nodes are shared by many parents). The first
//! operand prefers a recent entry that nothing uses yet, so that almost the whole graph is
//! reachable from the output (with uniform picks only ~58 % of it is; with the preference ~97 %)
//! and the gradient really walks ~100k nodes. It stops once the graph holds the requested
//! number of nodes; the scalar output is the sum of the last [`TAIL`] pool entries. The
//! sequence only depends on the seed, so every run (and every benchmark iteration) builds
//! exactly the same graph.

use mpc_dsl::{Expr, Graph};

/// Number of input symbols.
pub const INPUTS: usize = 50;
/// How many of the most recent pool entries most operands are drawn from.
const WINDOW: usize = 64;
/// How many of the last pool entries are summed into the output.
const TAIL: usize = 32;
/// Draws from the window when looking for an unused first operand.
const TRIES: usize = 8;
/// Fixed seed used by both benchmarks.
pub const SEED: u64 = 0x9E37_79B9_7F4A_7C15;

/// xorshift64* (Vigna 2016): tiny, fast and good enough to pick operations and operands.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Rng {
        Rng(if seed == 0 {
            0x2545_F491_4F6C_DD1D
        } else {
            seed
        })
    }

    fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in `0..n` (`n > 0`); the modulo bias is irrelevant here.
    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() >> 11) as usize % n
    }
}

/// An operand: 85 % of the time one of the last `WINDOW` pool entries, otherwise any entry.
fn pick(rng: &mut Rng, n: usize) -> usize {
    if rng.below(100) < 85 {
        n - 1 - rng.below(WINDOW.min(n))
    } else {
        rng.below(n)
    }
}

/// The first operand: a recent entry, preferring one no node uses yet (up to `TRIES` draws
/// from the window), so that few nodes end up unreachable from the output.
fn pick_first(rng: &mut Rng, used: &[bool]) -> usize {
    let n = used.len();
    let mut k = n - 1 - rng.below(WINDOW.min(n));
    for _ in 1..TRIES {
        if !used[k] {
            break;
        }
        k = n - 1 - rng.below(WINDOW.min(n));
    }
    k
}

/// Builds the random DAG in `g` until it holds at least `min_nodes` nodes. Returns the scalar
/// output and the input symbols (the variables to differentiate with respect to).
///
/// The pool of intermediate expressions is dropped before returning, so after the call the
/// heap holds the graph and the two returned values only.
pub fn random_dag(g: &Graph, min_nodes: usize, seed: u64) -> (Expr<'_>, Vec<Expr<'_>>) {
    let mut rng = Rng::new(seed);
    let inputs: Vec<Expr<'_>> = (0..INPUTS).map(|i| g.symbol(&format!("x{i}"))).collect();
    let mut pool: Vec<Expr<'_>> = Vec::with_capacity(min_nodes);
    pool.extend_from_slice(&inputs);
    let mut used = vec![false; pool.len()];
    while g.len() < min_nodes {
        let ia = pick_first(&mut rng, &used);
        let a = pool[ia];
        let second = |rng: &mut Rng, used: &mut [bool]| {
            let ib = pick(rng, pool.len());
            used[ib] = true;
            pool[ib]
        };
        let e = match rng.below(13) {
            0 => a + second(&mut rng, &mut used),
            1 => a - second(&mut rng, &mut used),
            2 => a * second(&mut rng, &mut used),
            3 => a / second(&mut rng, &mut used),
            4 => a.sin(),
            5 => a.cos(),
            6 => a.exp(),
            7 => a.tanh(),
            8 => a.sqrt(),
            9 => a.powi(2),
            10 => a.atan2(second(&mut rng, &mut used)),
            11 => a.min(second(&mut rng, &mut used)),
            _ => a.max(second(&mut rng, &mut used)),
        };
        // `x - x` and friends simplify to constants; keep those out of the pool so the DAG
        // stays a function of the inputs everywhere.
        if e.as_constant().is_none() {
            used[ia] = true;
            pool.push(e);
            used.push(false);
        }
    }
    let tail = &pool[pool.len().saturating_sub(TAIL)..];
    let f = tail[1..].iter().fold(tail[0], |s, &t| s + t);
    (f, inputs)
}
