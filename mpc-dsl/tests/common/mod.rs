//! Helpers shared by mpc-dsl's integration tests.

/// Small deterministic generator (xorshift64*), uniform in [lo, hi).
pub struct Rng(pub u64);

impl Rng {
    /// The next draw, uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let r = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d);
        lo + (hi - lo) * ((r >> 11) as f64 / (1u64 << 53) as f64)
    }
}
