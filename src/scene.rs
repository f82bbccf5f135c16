//! Seeded procedural scenes for tests and benchmarks (the bundled demo scene is a file made
//! by `reference_data/generate/`, not this).

use crate::camera::Camera;
use crate::gaussian::Gaussians;
use crate::math::sh::num_coeffs;
use crate::rng::Uniform;
use glam::DVec3;

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
