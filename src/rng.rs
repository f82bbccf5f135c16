//! The crate's one random-number family: a seeded uniform source (rand_pcg's PCG-64 MCG)
//! and the hash that derives each stage's seed from the run's seed, so every stochastic
//! stage draws from its own reproducible stream.

use rand_core::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

/// A seeded uniform source (rand_pcg), the crate's one RNG family.
#[derive(Clone)]
pub struct Uniform(Pcg64Mcg);

impl Uniform {
    pub fn new(seed: u64) -> Self {
        Uniform(Pcg64Mcg::seed_from_u64(seed))
    }
    /// The generator's whole state (a training checkpoint saves it).
    pub fn state(&self) -> u128 {
        self.0.state()
    }
    /// The generator with a state from [`Uniform::state`]: it continues the same stream.
    pub fn from_state(state: u128) -> Self {
        Uniform(Pcg64Mcg::new(state))
    }
    /// Uniform in `[0, 1)` with 24 random bits.
    pub fn unit(&mut self) -> f32 {
        (self.0.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }
    /// Uniform in `[0, 1)` with 53 random bits.
    pub fn unit_f64(&mut self) -> f64 {
        (self.0.next_u64() >> 11) as f64 * (1.0 / 9_007_199_254_740_992.0)
    }
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }
    /// A standard normal sample (Marsaglia's polar method in f32 with the crate's own `ln`,
    /// so the value does not depend on the platform's libm; the second sample of each
    /// accepted pair is discarded to keep one draw per call).
    pub fn normal(&mut self) -> f32 {
        loop {
            let u = 2.0 * self.unit() - 1.0;
            let v = 2.0 * self.unit() - 1.0;
            let s = u * u + v * v;
            if s > 0.0 && s < 1.0 {
                return u * (-2.0 * crate::math::fastexp::ln(s) / s).sqrt();
            }
        }
    }
    /// Uniform integer in `0..n` (`n > 0`), by rejection, without modulo bias.
    pub fn below(&mut self, n: u32) -> u32 {
        assert!(n > 0);
        let zone = u32::MAX - (u32::MAX - n + 1) % n;
        loop {
            let x = self.0.next_u32();
            if x <= zone {
                return x % n;
            }
        }
    }
}

/// Seed of a stage's generator: the run seed mixed with the stage name (FNV-1a), so
/// stages draw independent streams (SPEC.md §6).
pub fn stage_seed(seed: u64, stage: &str) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64 ^ seed;
    for b in stage.bytes() {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}
