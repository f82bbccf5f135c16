//! Seeded procedural scenes for tests and benchmarks (the bundled demo scene is a file made
//! by `reference_data/generate/`, not this).

use crate::camera::Camera;
use crate::gaussian::Gaussians;
use crate::math::sh::num_coeffs;
use glam::DVec3;
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

/// `n` random Gaussians in a box `[-1,1]×[-0.75,0.75]×[2,6]` in front of [`default_camera`],
/// log-scales in `[ln(lo), ln(hi)]`, random rotations, opacities in (0.05, 0.95), colours
/// and SH rest coefficients (small) at `sh_degree`.
pub fn random_scene(
    n: usize,
    sh_degree: u32,
    seed: u64,
    scale_lo: f32,
    scale_hi: f32,
) -> Gaussians {
    let mut u = Uniform::new(seed);
    let mut g = Gaussians::new(sh_degree).expect("degree <= 5");
    let k1 = num_coeffs(sh_degree) - 1;
    let mut rest = vec![0f32; k1 * 3];
    for _ in 0..n {
        let mean = [u.range(-1.0, 1.0), u.range(-0.75, 0.75), u.range(2.0, 6.0)];
        let ls = [0; 3].map(|_| u.range(scale_lo.ln(), scale_hi.ln()));
        let q = [
            u.range(-1.0, 1.0),
            u.range(-1.0, 1.0),
            u.range(-1.0, 1.0),
            u.range(-1.0, 1.0),
        ];
        let op = u.range(-3.0, 3.0);
        let dc = [0; 3].map(|_| u.range(-1.5, 1.5));
        for v in rest.iter_mut() {
            *v = u.range(-0.3, 0.3);
        }
        g.push(mean, ls, q, op, dc, &rest);
    }
    g
}

/// A camera at the origin looking down +z (world = camera frame), 60° horizontal FOV.
pub fn default_camera(width: u32, height: u32) -> Camera {
    Camera::look_at(
        "default",
        width,
        height,
        60f64.to_radians(),
        DVec3::ZERO,
        DVec3::Z,
        DVec3::NEG_Y,
    )
    .expect("valid camera")
}
