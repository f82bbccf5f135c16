//! The backward on hard scenes against central differences of the forward's f64 twin
//! (issue #70): every parameter of every Gaussian of seeded scenes that hold needles of
//! condition 10⁸–10⁹, Gaussians of scale 1e-8, quaternions of norm 1e-20, opacity logits
//! ±30 (α at the clamp), large half-transparent Gaussians and Gaussians centred on the first
//! and last pixel, among ordinary ones (the `hard` family of `unseen.testing.scene`, drawn
//! here by the crate's own generator so that no test needs Python).
use super::twin::{LocalLoss, flatten};
use glam::DVec3;
use unseen::camera::Camera;
use unseen::gaussian::Gaussians;
use unseen::math::sh::num_coeffs;
use unseen::raster::backward::{GradGroups, ImageGrads, backward, render_for_backward};
use unseen::raster::decisions::{
    GAUSSIAN_DEPTH_CULL, GAUSSIAN_JACOBIAN_CLAMP, GAUSSIAN_OPACITY_CULL, Margins,
    PIXEL_BACKWARD_FLAGS, PIXEL_ILL_CONDITIONED, decisions,
};
use unseen::raster::{Outputs, RenderOptions};
use unseen::rng::Uniform;

/// A seeded hard scene and its camera (at the origin looking along +z, `fx = 0.9·W`, the
/// principal point off the centre by (0.37, −0.21) px): `n` Gaussians 2–8 units deep whose
/// centres project uniformly over the image widened by 0.6 of it on each side, scales
/// e^−4.5 … e^−2, opacity logits −3 … 4; then eight disjoint groups of `max(n/50, 8)`:
/// near depth ties (camera z 4.0), logits ±30, every scale 1e-8, needles (first scale 1e3),
/// quaternions times 1e-20, the identity quaternion, centred on the first or last pixel, large
/// half-transparent (scales e^−1 … 1).
pub fn hard_scene(
    seed: u64,
    n: usize,
    width: u32,
    height: u32,
    degree: u32,
) -> (Gaussians, Camera) {
    let mut u = Uniform::new(seed);
    let fov = 2.0 * (0.5f64 / 0.9).atan();
    let mut cam = Camera::look_at(
        "hard",
        width,
        height,
        fov,
        DVec3::ZERO,
        DVec3::Z,
        DVec3::NEG_Y,
    )
    .unwrap();
    cam.cx = f64::from(width) / 2.0 + 0.37;
    cam.cy = f64::from(height) / 2.0 - 0.21;
    let r_wc = cam.world_from_camera_rotation;
    let world = |px: f64, py: f64, z: f64| {
        let pc = DVec3::new((px - cam.cx) / cam.fx * z, (py - cam.cy) / cam.fy * z, z);
        let p = r_wc * pc + cam.center;
        [p.x as f32, p.y as f32, p.z as f32]
    };
    let (w, h) = (f64::from(width), f64::from(height));
    let k1 = num_coeffs(degree) - 1;
    let mut g = Gaussians::new(degree).unwrap();
    for _ in 0..n {
        let z = f64::from(u.range(2.0, 8.0));
        let (px, py) = (
            f64::from(u.range(-0.6, 1.6)) * w,
            f64::from(u.range(-0.6, 1.6)) * h,
        );
        let ls = [0; 3].map(|_| u.range(-4.5, -2.0));
        let q = [0; 4].map(|_| u.normal());
        let logit = u.range(-3.0, 4.0);
        let dc = [0; 3].map(|_| 0.3 * u.normal() + u.range(-1.0, 1.0));
        let rest: Vec<f32> = (0..3 * k1).map(|_| 0.3 * u.normal()).collect();
        g.push(world(px, py, z), ls, q, logit, dc, &rest);
    }
    // Eight disjoint groups: a partial Fisher–Yates shuffle.
    let m = (n / 50).max(8).min(n / 8);
    let mut idx: Vec<usize> = (0..n).collect();
    for k in 0..8 * m {
        let j = k + u.below((n - k) as u32) as usize;
        idx.swap(k, j);
    }
    for (grp, ids) in idx[..8 * m].chunks(m).enumerate() {
        for &i in ids {
            match grp {
                0 => {
                    let c = cam.camera_from_world_point(DVec3::from(g.means[i].map(f64::from)));
                    g.means[i] = world(
                        c.x / c.z * cam.fx + cam.cx,
                        c.y / c.z * cam.fy + cam.cy,
                        4.0,
                    );
                }
                1 => g.opacity_logits[i] = if u.unit() < 0.5 { 30.0 } else { -30.0 },
                2 => g.log_scales[i] = [1e-8f32.ln(); 3],
                3 => g.log_scales[i][0] = 1e3f32.ln(),
                4 => g.quats[i] = g.quats[i].map(|v| v * 1e-20),
                5 => g.quats[i] = [1.0, 0.0, 0.0, 0.0],
                6 => {
                    let first = u.unit() < 0.5;
                    let (px, py) = if first {
                        (0.5, 0.5)
                    } else {
                        (w - 0.5, h - 0.5)
                    };
                    g.means[i] = world(px, py, f64::from(u.range(3.0, 6.0)));
                }
                _ => g.log_scales[i] = [0; 3].map(|_| u.range(-1.0, 0.0)),
            }
        }
    }
    (g, cam)
}

/// What one seed's comparison found.
struct Outcome {
    failures: Vec<String>,
    compared: usize,
    set_aside: usize,
    worst: f64,
}

/// The oracle's gradients of `Σ w·(rgb, alpha, D)` (weights zeroed on pixels whose
/// decisions a float32 evaluation may take the other way: `PIXEL_BACKWARD_FLAGS` but the
/// ill-conditioned flag, whose pixels stay: that is what this test is about) against central
/// differences of the f64 twin, every parameter of every Gaussian. Set aside: parameters
/// whose ±h steps change a decision of the twin (a jump or kink: no derivative), and
/// Gaussians flagged at a cull or the Jacobian clamp's kink.
fn compare(seed: u64, n: usize, width: u32, height: u32, degree: u32) -> Outcome {
    let (g, cam) = hard_scene(seed, n, width, height, degree);
    let bg = [0.8, 0.45, 0.15];
    let opts = RenderOptions {
        background: bg,
        outputs: Outputs::ALL,
        ..Default::default()
    };
    let dec = decisions(&g, &cam, &opts, &Margins::default()).unwrap();
    let npix = (width * height) as usize;
    let mut u = Uniform::new(1000 + seed);
    let scale = 1.0 / npix as f32;
    let keep =
        |pi: usize| dec.pixel_flags[pi] & (PIXEL_BACKWARD_FLAGS & !PIXEL_ILL_CONDITIONED) == 0;
    let mut w_rgb: Vec<f32> = (0..npix * 3).map(|_| u.range(-1.0, 1.0) * scale).collect();
    let mut w_alpha: Vec<f32> = (0..npix).map(|_| u.range(-1.0, 1.0) * scale).collect();
    let mut w_depth: Vec<f32> = (0..npix).map(|_| u.range(-0.1, 0.1) * scale).collect();
    for pi in (0..npix).filter(|&pi| !keep(pi)) {
        w_rgb[3 * pi..3 * pi + 3].fill(0.0);
        w_alpha[pi] = 0.0;
        w_depth[pi] = 0.0;
    }
    let fwd = render_for_backward(&g, &cam, &opts).unwrap();
    let v = ImageGrads {
        rgb: Some(w_rgb.clone()),
        alpha: Some(w_alpha.clone()),
        depth: Some(w_depth.clone()),
        expected_depth: None,
    };
    let (gr, _) = backward(&g, &cam, &opts, &fwd, &v, &GradGroups::ALL).unwrap();
    let p0 = flatten(&g);
    let bg64 = bg.map(f64::from);
    let twin = LocalLoss::new(&g, &p0, &cam, bg64, &w_rgb, &w_alpha, &w_depth);
    let stride = twin.stride();
    let k = g.rest_per_channel() * 3;
    let kinks = GAUSSIAN_OPACITY_CULL | GAUSSIAN_DEPTH_CULL | GAUSSIAN_JACOBIAN_CLAMP;
    let mut out = Outcome {
        failures: Vec::new(),
        compared: 0,
        set_aside: 0,
        worst: 0.0,
    };
    for i in 0..g.len() {
        if dec.gaussian_flags[i] & kinks != 0 {
            out.set_aside += stride;
            continue;
        }
        let mut an = Vec::with_capacity(stride);
        an.extend(gr.means[i]);
        an.extend(gr.log_scales[i]);
        an.extend(gr.quats[i]);
        an.push(gr.opacity_logits[i]);
        an.extend(gr.sh_dc[i]);
        an.extend(&gr.sh_rest[i * k..(i + 1) * k]);
        let row = &p0[i * stride..(i + 1) * stride];
        let qn = row[6..10].iter().map(|v| v * v).sum::<f64>().sqrt();
        for (j, &a) in an.iter().enumerate() {
            // Quaternion entries step by their norm's share (a quaternion of norm 1e-20
            // is a rotation: a step of 1e-5 would replace it).
            let h = if (6..10).contains(&j) {
                1e-5 * qn
            } else {
                1e-5 * row[j].abs().max(1.0)
            };
            let (mut qp, mut qm) = (row.to_vec(), row.to_vec());
            qp[j] += h;
            qm[j] -= h;
            let (cp, cm) = (twin.change(i, &qp), twin.change(i, &qm));
            if !(cp.same_decisions && cm.same_decisions) {
                out.set_aside += 1;
                continue;
            }
            let fd = (cp.delta - cm.delta) / (2.0 * h);
            // Scale-free for the quaternion: its gradient scales with 1/|q|.
            let unit = if (6..10).contains(&j) { 1.0 / qn } else { 1.0 };
            let err = (f64::from(a) - fd).abs() / unit;
            let tol = FD_ATOL + FD_RTOL * fd.abs() / unit;
            out.compared += 1;
            out.worst = out.worst.max(err / tol);
            if err > tol {
                out.failures.push(format!(
                    "seed {seed} gaussian {i} param {j}: oracle {a:.6e}, twin fd {fd:.6e}"
                ));
            }
        }
    }
    out
}

/// Finite-difference tolerance: as `gradients.rs` (5e-5 + 1 %).
const FD_ATOL: f64 = 5e-5;
const FD_RTOL: f64 = 0.01;

#[test]
fn hard_scene_gradients_match_the_f64_twin() {
    let mut failures = Vec::new();
    for seed in 0..10 {
        let o = compare(seed, 300, 48, 40, 1);
        eprintln!(
            "seed {seed}: {} compared, {} set aside, worst err/tol {:.3}, {} fail",
            o.compared,
            o.set_aside,
            o.worst,
            o.failures.len()
        );
        failures.extend(o.failures);
    }
    assert!(
        failures.is_empty(),
        "{} off:\n{}",
        failures.len(),
        failures[..failures.len().min(40)].join("\n")
    );
}

/// The f64 chain runs for lanes the f32 lanes select: every kernel form gives the scalar
/// reference's bits on hard scenes (needles, subnormal quaternions, α at the clamp), on 1
/// and 2 threads.
#[test]
fn hard_scene_gradients_are_the_same_bits_in_every_kernel_and_thread_count() {
    use crate::support::with_threads;
    use unseen::raster::Kernel;
    let (g, cam) = hard_scene(3, 2000, 96, 80, 3);
    let npix = (cam.width * cam.height) as usize;
    let mut u = Uniform::new(11);
    let v = ImageGrads {
        rgb: Some((0..npix * 3).map(|_| u.range(-1.0, 1.0)).collect()),
        alpha: Some((0..npix).map(|_| u.range(-1.0, 1.0)).collect()),
        depth: Some((0..npix).map(|_| u.range(-1.0, 1.0)).collect()),
        expected_depth: None,
    };
    let run = |kernel, threads| {
        with_threads(threads, || {
            let opts = RenderOptions {
                background: [0.8, 0.45, 0.15],
                kernel,
                outputs: Outputs::ALL,
                ..Default::default()
            };
            let fwd = render_for_backward(&g, &cam, &opts).unwrap();
            let (gr, _) = backward(&g, &cam, &opts, &fwd, &v, &GradGroups::ALL).unwrap();
            let mut bits: Vec<u32> = Vec::new();
            for a in [
                gr.means.as_flattened(),
                gr.log_scales.as_flattened(),
                gr.quats.as_flattened(),
                &gr.opacity_logits,
                gr.sh_dc.as_flattened(),
                &gr.sh_rest,
            ] {
                bits.extend(a.iter().map(|x| x.to_bits()));
            }
            bits
        })
    };
    let want = run(Kernel::Scalar, 1);
    for (kernel, threads) in [(Kernel::Auto, 1), (Kernel::Avx2, 2), (Kernel::Auto, 2)] {
        assert!(
            run(kernel, threads) == want,
            "{kernel:?} on {threads} threads"
        );
    }
}
