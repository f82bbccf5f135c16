//! Backward pass: central finite differences of an f64 twin of the forward (used only by
//! these tests), determinism, frozen groups and hard cases.
use super::twin::{flatten, forward64, smooth_scene};
use crate::support::{bits, with_threads};
use unseen::camera::Camera;
use unseen::gaussian::Gaussians;
use unseen::raster::backward::{GradGroups, Gradients, ImageGrads, backward, render_for_backward};
use unseen::raster::{Outputs, RenderOptions};
use unseen::rng::Uniform;
use unseen::scene::{default_camera, random_scene};

fn grads_flat(gr: &Gradients, g: &Gaussians) -> Vec<f32> {
    let mut p = Vec::new();
    let k = g.rest_per_channel() * 3;
    for i in 0..g.len() {
        p.extend(gr.means[i]);
        p.extend(gr.log_scales[i]);
        p.extend(gr.quats[i]);
        p.push(gr.opacity_logits[i]);
        p.extend(gr.sh_dc[i]);
        p.extend(&gr.sh_rest[i * k..(i + 1) * k]);
    }
    p
}

const PARAM_NAMES: [&str; 14] = [
    "mean.x",
    "mean.y",
    "mean.z",
    "log_scale.0",
    "log_scale.1",
    "log_scale.2",
    "quat.w",
    "quat.x",
    "quat.y",
    "quat.z",
    "opacity_logit",
    "dc.r",
    "dc.g",
    "dc.b",
];

/// Finite-difference tolerance: 5e-5 absolute + 1% relative (the issue's bound).
const FD_ATOL: f64 = 5e-5;
const FD_RTOL: f64 = 0.01;

struct Weights {
    rgb: Vec<f32>,
    alpha: Vec<f32>,
    depth: Vec<f32>,
    ed: Vec<f32>,
}

fn loss64(out: &[Vec<f64>; 4], w: &Weights) -> f64 {
    let dot = |a: &[f64], b: &[f32]| a.iter().zip(b).map(|(x, y)| x * *y as f64).sum::<f64>();
    dot(&out[0], &w.rgb) + dot(&out[1], &w.alpha) + dot(&out[2], &w.depth) + dot(&out[3], &w.ed)
}

/// Analytic gradients vs central differences of the f64 twin, every parameter.
/// All-zero SH bands: a forward-only render may skip them, the backward must not (their
/// coefficients' gradients are not zero; a skipped band would never start to train).
#[test]
fn gradients_of_all_zero_sh_bands_are_computed() {
    let cam = default_camera(24, 18);
    let mut g = smooth_scene(3, 6);
    g.sh_rest.fill(0.0);
    check_fd(&g, &cam, [0.1, 0.2, 0.3], false, 6);
    let fwd = render_for_backward(&g, &cam, &RenderOptions::default()).unwrap();
    let v = ImageGrads {
        rgb: Some(vec![1.0; (cam.width * cam.height * 3) as usize]),
        ..Default::default()
    };
    let (gr, _) = backward(
        &g,
        &cam,
        &RenderOptions::default(),
        &fwd,
        &v,
        &GradGroups::ALL,
    )
    .unwrap();
    assert!(
        gr.sh_rest.iter().any(|&x| x != 0.0),
        "zero bands got no gradient"
    );
}

fn check_fd(g: &Gaussians, cam: &Camera, bg: [f32; 3], with_depth: bool, seed: u64) {
    let npix = (cam.width * cam.height) as usize;
    let mut u = Uniform::new(seed);
    let scale = 1.0 / npix as f32;
    let w = Weights {
        rgb: (0..npix * 3).map(|_| u.range(-1.0, 1.0) * scale).collect(),
        alpha: (0..npix).map(|_| u.range(-1.0, 1.0) * scale).collect(),
        depth: (0..npix)
            .map(|_| {
                if with_depth {
                    u.range(-0.3, 0.3) * scale
                } else {
                    0.0
                }
            })
            .collect(),
        ed: (0..npix)
            .map(|_| {
                if with_depth {
                    u.range(-0.3, 0.3) * scale
                } else {
                    0.0
                }
            })
            .collect(),
    };
    let opts = RenderOptions {
        background: bg,
        outputs: Outputs::ALL,
        ..Default::default()
    };
    let fwd = render_for_backward(g, cam, &opts).unwrap();
    assert_eq!(
        fwd.render.report.visible as usize,
        g.len(),
        "the smooth scene must be fully visible"
    );
    let v = ImageGrads {
        rgb: Some(w.rgb.clone()),
        alpha: Some(w.alpha.clone()),
        depth: Some(w.depth.clone()),
        expected_depth: Some(w.ed.clone()),
    };
    let (gr, _) = backward(g, cam, &opts, &fwd, &v, &GradGroups::ALL).unwrap();
    let analytic = grads_flat(&gr, g);
    let p0 = flatten(g);
    let bg64 = bg.map(|v| v as f64);
    let base = forward64(g, &p0, cam, bg64);
    // The twin agrees with the f32 forward, so both compute the same function.
    let rgb32 = fwd.render.rgb.as_ref().unwrap();
    let max_fwd = base[0]
        .iter()
        .zip(rgb32)
        .map(|(a, b)| (a - *b as f64).abs())
        .fold(0.0, f64::max);
    assert!(
        max_fwd < 1e-5,
        "f64 twin and f32 forward differ by {max_fwd}"
    );
    let stride = p0.len() / g.len();
    let mut failures = Vec::new();
    for (k, &an) in analytic.iter().enumerate() {
        let hstep = 1e-5 * p0[k].abs().max(1.0);
        let (mut pp, mut pm) = (p0.clone(), p0.clone());
        pp[k] += hstep;
        pm[k] -= hstep;
        let fd = (loss64(&forward64(g, &pp, cam, bg64), &w)
            - loss64(&forward64(g, &pm, cam, bg64), &w))
            / (2.0 * hstep);
        let err = (an as f64 - fd).abs();
        if err > FD_ATOL + FD_RTOL * fd.abs() {
            let j = k % stride;
            let name = PARAM_NAMES
                .get(j)
                .map_or(format!("sh_rest[{}]", j - 14), |s| s.to_string());
            failures.push(format!(
                "gaussian {} {name}: analytic {an:.6e} fd {fd:.6e}",
                k / stride
            ));
        }
    }
    // Background: dL/dbg_k = Σ_p T_p·w_rgb.
    for k in 0..3 {
        let (mut bp, mut bm) = (bg64, bg64);
        bp[k] += 1e-5;
        bm[k] -= 1e-5;
        let fd = (loss64(&forward64(g, &p0, cam, bp), &w)
            - loss64(&forward64(g, &p0, cam, bm), &w))
            / 2e-5;
        let an = gr.background[k] as f64;
        if (an - fd).abs() > FD_ATOL + FD_RTOL * fd.abs() {
            failures.push(format!("background {k}: analytic {an:.6e} fd {fd:.6e}"));
        }
    }
    assert!(
        failures.is_empty(),
        "{} gradient(s) off:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn gradients_match_finite_differences_sh_degrees() {
    let cam = default_camera(24, 18);
    for (deg, seed) in [(0, 1), (1, 2), (3, 3), (5, 4)] {
        check_fd(&smooth_scene(deg, seed), &cam, [0.2, 0.5, 0.8], false, seed);
    }
}

#[test]
fn gradients_match_finite_differences_depth_losses() {
    let cam = default_camera(20, 16);
    check_fd(&smooth_scene(1, 9), &cam, [0.0; 3], true, 9);
}

/// A rotated, off-centre camera and Gaussians outside the Jacobian's guard band (their
/// x/z is clamped, so the Jacobian's gradient goes to z).
#[test]
fn gradients_match_finite_differences_clamped_jacobian() {
    let mut cam = Camera::look_at(
        "c",
        22,
        18,
        1.2,
        [0.2, -0.1, 0.3].into(),
        [0.0, 0.0, 3.0].into(),
        [0.1, -1.0, 0.0].into(),
    )
    .unwrap();
    cam.cx = 10.3;
    cam.cy = 8.2;
    let mut g = smooth_scene(2, 5);
    // Two wide Gaussians far to the side: x/z beyond the guard, still covering the image.
    let rest = vec![0.05; g.rest_per_channel() * 3];
    g.push(
        [4.5, 0.1, 3.0],
        [1.2, 0.6, 0.5],
        [0.9, 0.1, 0.2, 0.1],
        -0.5,
        [0.3, -0.2, 0.1],
        &rest,
    );
    g.push(
        [0.2, -3.9, 3.5],
        [0.5, 1.1, 0.5],
        [0.8, -0.2, 0.1, 0.3],
        -0.8,
        [-0.3, 0.2, 0.4],
        &rest,
    );
    check_fd(&g, &cam, [0.1, 0.1, 0.1], true, 7);
}

fn grads_all(scene: &Gaussians, cam: &Camera, groups: &GradGroups) -> Gradients {
    let opts = RenderOptions {
        background: [0.3, 0.2, 0.1],
        ..Default::default()
    };
    let fwd = render_for_backward(scene, cam, &opts).unwrap();
    let npix = (cam.width * cam.height) as usize;
    let mut u = Uniform::new(77);
    let v = ImageGrads {
        rgb: Some((0..npix * 3).map(|_| u.range(-1.0, 1.0)).collect()),
        ..Default::default()
    };
    backward(scene, cam, &opts, &fwd, &v, groups).unwrap().0
}

/// 100k Gaussians: bit-identical gradients for 1, 2 and 7 threads and across runs.
#[test]
fn gradients_are_deterministic_across_thread_counts() {
    let scene = random_scene(100_000, 3, 42, 0.002, 0.08);
    let cam = default_camera(256, 192);
    let reference = with_threads(1, || grads_all(&scene, &cam, &GradGroups::ALL));
    assert!(reference.means.iter().any(|m| m[0] != 0.0));
    for threads in [2, 7, 2] {
        let r = with_threads(threads, || grads_all(&scene, &cam, &GradGroups::ALL));
        assert!(r == reference, "{threads} threads");
    }
}

/// Frozen groups: what is computed equals the full backward bit for bit; the rest is zero.
#[test]
fn frozen_groups_are_bit_identical_to_the_full_backward() {
    let scene = random_scene(5000, 3, 8, 0.005, 0.2);
    let cam = default_camera(128, 96);
    let full = grads_all(&scene, &cam, &GradGroups::ALL);
    let sh = grads_all(&scene, &cam, &GradGroups::SH_REST);
    assert_eq!(sh.sh_rest, full.sh_rest);
    assert!(sh.means.iter().all(|m| *m == [0.0; 3]) && sh.quats.iter().all(|q| *q == [0.0; 4]));
    assert_eq!(sh.background, [0.0; 3]);
    let geo = GradGroups {
        sh_dc: false,
        sh_rest: false,
        background: false,
        ..GradGroups::ALL
    };
    let g2 = grads_all(&scene, &cam, &geo);
    assert_eq!(
        (g2.means, g2.log_scales, g2.quats, g2.opacity_logits),
        (full.means, full.log_scales, full.quats, full.opacity_logits)
    );
}

/// Degenerate scenes keep gradients finite; a Gaussian outside the image gets exactly zero;
/// a Gaussian whose α sits at the 0.99 clamp gets no opacity gradient through the clamp.
#[test]
fn gradient_hard_cases() {
    let cam = default_camera(64, 48);
    let mut g = random_scene(300, 2, 3, 0.001, 1.0);
    let rest = vec![0.0; g.rest_per_channel() * 3];
    g.push(
        [0.0, 0.0, 3.0],
        [1e-12f32.ln(); 3],
        [1.0, 0.0, 0.0, 0.0],
        2.0,
        [0.5; 3],
        &rest,
    );
    g.push(
        [0.0, 0.0, 0.02],
        [1e6f32.ln(); 3],
        [1.0, 0.0, 0.0, 0.0],
        2.0,
        [0.5; 3],
        &rest,
    );
    g.push([0.0, 0.0, 3.0], [0.0; 3], [0.0; 4], 2.0, [0.5; 3], &rest);
    g.push(
        [0.0, 0.0, 3.0],
        [f32::NAN; 3],
        [1.0, 0.0, 0.0, 0.0],
        2.0,
        [0.5; 3],
        &rest,
    );
    let outside = g.len();
    g.push(
        [50.0, 0.0, 3.0],
        [-2.0; 3],
        [1.0, 0.0, 0.0, 0.0],
        2.0,
        [0.5; 3],
        &rest,
    );
    let gr = grads_all(&g, &cam, &GradGroups::ALL);
    let flat = grads_flat(&gr, &g);
    assert!(flat.iter().all(|v| v.is_finite()), "non-finite gradient");
    assert!(
        gr.means[outside] == [0.0; 3]
            && gr.opacity_logits[outside] == 0.0
            && gr.sh_dc[outside] == [0.0; 3]
    );

    // α at the clamp: o = 0.999 and a scale so large that o·exp(−σ) > 0.99 at every pixel.
    // Its opacity gets exactly no gradient (sigmoid' is far from 0 here, so a zero proves
    // the clamp cut it), while its colour does.
    let mut g = Gaussians::new(0).unwrap();
    let logit = (0.999f32 / 0.001).ln();
    g.push(
        [0.0, 0.0, 3.0],
        [100f32.ln(); 3],
        [1.0, 0.0, 0.0, 0.0],
        logit,
        [0.3; 3],
        &[],
    );
    g.push(
        [0.0, 0.0, 5.0],
        [100f32.ln(); 3],
        [1.0, 0.0, 0.0, 0.0],
        0.0,
        [0.1; 3],
        &[],
    );
    let small = default_camera(16, 12);
    let opts = RenderOptions::default();
    let fwd = render_for_backward(&g, &small, &opts).unwrap();
    let v = ImageGrads {
        rgb: Some(vec![1.0; 16 * 12 * 3]),
        ..Default::default()
    };
    let (gr, _) = backward(&g, &small, &opts, &fwd, &v, &GradGroups::ALL).unwrap();
    assert_eq!(
        gr.opacity_logits[0], 0.0,
        "no gradient through the 0.99 clamp"
    );
    assert!(
        gr.opacity_logits[1] != 0.0,
        "the Gaussian behind is not clamped"
    );
    assert!(gr.sh_dc[0].iter().all(|v| v.is_finite() && *v > 0.0));
}

/// The AVX-512 backward (`Kernel::Auto` where the CPU has AVX-512F), the AVX2 backward and the
/// lane-by-lane reference give the same bits.
#[test]
fn backward_simd_and_scalar_are_bit_identical() {
    use unseen::raster::Kernel;
    let scene = random_scene(20_000, 3, 12, 0.003, 0.3);
    let cam = default_camera(203, 117);
    let npix = (cam.width * cam.height) as usize;
    let mut u = Uniform::new(5);
    let v = ImageGrads {
        rgb: Some((0..npix * 3).map(|_| u.range(-1.0, 1.0)).collect()),
        alpha: Some((0..npix).map(|_| u.range(-1.0, 1.0)).collect()),
        depth: Some((0..npix).map(|_| u.range(-1.0, 1.0)).collect()),
        expected_depth: Some((0..npix).map(|_| u.range(-1.0, 1.0)).collect()),
    };
    for groups in [GradGroups::ALL, GradGroups::SH_REST] {
        let run = |kernel| {
            let opts = RenderOptions {
                background: [0.2, 0.3, 0.4],
                kernel,
                outputs: Outputs::ALL,
                ..Default::default()
            };
            let fwd = render_for_backward(&scene, &cam, &opts).unwrap();
            backward(&scene, &cam, &opts, &fwd, &v, &groups).unwrap()
        };
        let (b, pb) = run(Kernel::Scalar);
        let bits = grads_bits(&b);
        assert!(b.sh_rest.iter().any(|&g| g != 0.0));
        for kernel in [Kernel::Auto, Kernel::Avx2] {
            let (a, pa) = run(kernel);
            assert!(
                grads_bits(&a) == bits && pa == pb,
                "{kernel:?} vs Scalar, {groups:?}"
            );
        }
    }
}

/// The backward projection in lanes (sixteen Gaussians per AVX-512F instruction, eight per
/// AVX2 instruction, a scalar remainder) gives the bits of the scalar reference: SH degrees
/// 0–5 (and a plan degree below the stored one), blocks that mix visible and culled
/// Gaussians (behind the camera, off screen), visible Gaussians beyond the Jacobian's clamp
/// in x and in y, Gaussians without colour gradient, Gaussians marked visible whose
/// geometry fails (SH gradients only), a count that leaves a remainder, and four group
/// sets. The scalar form is itself held to the backward of each Gaussian alone (a scene of
/// one): the backward stages the visible Gaussians of a chunk side by side, and a wrong
/// entry, a culled Gaussian's nonzero entry or a row spilling onto its neighbour's would
/// show there.
#[test]
fn projection_backward_simd_matches_scalar_bitwise() {
    use unseen::raster::backward::composite::SplatGrad;
    use unseen::raster::backward::project::project_backward;
    use unseen::raster::project::{CameraF32, Projected, project};
    use unseen::raster::{Kernel, RenderPlan, RenderReport};
    #[cfg(target_arch = "x86_64")]
    eprintln!(
        "lane forms compared with the scalar one: AVX-512F {}, AVX2 {}",
        std::is_x86_feature_detected!("avx512f"),
        std::is_x86_feature_detected!("avx2")
    );
    let cam = default_camera(97, 61);
    let groups = [
        GradGroups::ALL,
        GradGroups::SH_REST,
        GradGroups {
            means: true,
            sh_dc: false,
            sh_rest: false,
            background: false,
            ..GradGroups::ALL
        },
        GradGroups {
            log_scales: false,
            quats: false,
            ..GradGroups::ALL
        },
    ];
    for (degree, plan_degree) in [(0, 0), (1, 1), (3, 2), (3, 3), (5, 5)] {
        let mut scene = random_scene(1_037, degree, 40 + degree as u64, 0.01, 0.3);
        for i in 0..scene.len() {
            if i % 5 == 1 {
                scene.means[i][2] = -2.0; // behind the camera
            } else if i % 7 == 2 {
                scene.means[i][0] = 40.0; // off screen
            } else if i % 11 == 3 {
                // Beyond the clamp of x/z (0.75 here) or y/z (0.47), still on screen.
                let (axis, ratio) = if i % 2 == 0 { (0, 0.85) } else { (1, 0.55) };
                scene.means[i][axis] = ratio * scene.means[i][2];
                scene.log_scales[i] = [0.5f32.ln(); 3];
            }
        }
        let opts = RenderOptions {
            sh_degree: Some(plan_degree),
            ..Default::default()
        };
        let plan = RenderPlan::for_backward(&scene, &opts);
        let projected = project(&scene, &cam, &plan, &opts, &mut RenderReport::default());
        let culled = projected.radii.iter().filter(|r| **r == [0, 0]).count();
        assert!(culled > 300 && culled < 700, "{culled} culled");
        let clamped = (0..scene.len())
            .filter(|&i| i % 11 == 3 && i % 5 != 1 && i % 7 != 2)
            .filter(|&i| projected.radii[i] != [0, 0])
            .count();
        assert!(clamped > 30, "{clamped} visible beyond the clamp");
        // Every Gaussian marked visible (those behind the camera fail the geometry), with
        // colour channels closed by the clamp in a pattern.
        let mut all_visible = projected.clone();
        all_visible.radii.fill([1, 1]);
        for (i, s) in all_visible.splats.iter_mut().enumerate() {
            s.color = std::array::from_fn(|ch| if (i + ch) % 4 == 0 { 0.0 } else { 0.5 });
        }
        let mut u = Uniform::new(degree as u64);
        let splats: Vec<SplatGrad> = (0..scene.len())
            .map(|_| SplatGrad {
                mean2d: [u.range(-1.0, 1.0), u.range(-1.0, 1.0)],
                conic: [u.range(-1.0, 1.0), u.range(-1.0, 1.0), u.range(-1.0, 1.0)],
                opacity: u.range(-1.0, 1.0),
                color: [u.range(-1.0, 1.0), u.range(-1.0, 1.0), u.range(-1.0, 1.0)],
                depth: u.range(-1.0, 1.0),
            })
            .enumerate()
            .map(|(i, s)| SplatGrad {
                color: if i % 13 == 4 { [0.0; 3] } else { s.color },
                ..s
            })
            .collect();
        let camf = CameraF32::new(&cam);
        for (g, fwd) in groups
            .iter()
            .flat_map(|g| [(g, &projected), (g, &all_visible)])
        {
            let run = |k| project_backward(&scene, &camf, fwd, &plan, g, &splats, k);
            let reference = run(Kernel::Scalar);
            assert!(reference.means.iter().flatten().any(|&v| v != 0.0) == g.means);
            let rest = scene.rest_per_channel() * 3;
            for i in (0..scene.len()).step_by(3) {
                let one = scene.select(&[i]);
                let fwd_one = Projected {
                    splats: vec![fwd.splats[i]],
                    radii: vec![fwd.radii[i]],
                };
                let alone = project_backward(
                    &one,
                    &camf,
                    &fwd_one,
                    &plan,
                    g,
                    &splats[i..=i],
                    Kernel::Scalar,
                );
                let entry = |r: &Gradients, k: usize| {
                    grads_bits(&Gradients {
                        means: vec![r.means[k]],
                        log_scales: vec![r.log_scales[k]],
                        quats: vec![r.quats[k]],
                        opacity_logits: vec![r.opacity_logits[k]],
                        sh_dc: vec![r.sh_dc[k]],
                        sh_rest: r.sh_rest[k * rest..(k + 1) * rest].to_vec(),
                        ..Gradients::default()
                    })
                };
                assert!(
                    entry(&reference, i) == entry(&alone, 0),
                    "Gaussian {i} in the scene vs alone, degree {degree} (plan {plan_degree}), {g:?}"
                );
                if fwd.radii[i] == [0, 0] {
                    assert!(
                        entry(&alone, 0).iter().all(|&b| b == 0),
                        "culled {i} not +0.0"
                    );
                }
            }
            for kernel in [Kernel::Auto, Kernel::Avx2] {
                assert!(
                    grads_bits(&run(kernel)) == grads_bits(&reference),
                    "{kernel:?} vs Scalar, degree {degree} (plan {plan_degree}), {g:?}"
                );
            }
        }
    }
}

/// Every gradient of a backward, as bits (NaN and −0.0 compared exactly).
fn grads_bits(g: &Gradients) -> Vec<u32> {
    let mut v: Vec<f32> = Vec::new();
    v.extend(g.means.iter().flatten());
    v.extend(g.log_scales.iter().flatten());
    v.extend(g.quats.iter().flatten());
    v.extend(&g.opacity_logits);
    v.extend(g.sh_dc.iter().flatten());
    v.extend(&g.sh_rest);
    v.extend(g.background);
    v.extend(g.means2d.iter().flatten());
    v.extend(g.means2d_ndc.iter().flatten());
    v.into_iter().map(f32::to_bits).collect()
}

/// The backward's exact skips — row and column culling, visits past the last blended splat
/// of the reachable pixels, rows that miss the ellipse — give the same bits as walking every
/// (row, splat) of the list prefix (`cull_rows = false`), for all three kernels (AVX-512 as
/// `Kernel::Auto` where the CPU has it, AVX2, scalar), which also agree with each other.
#[test]
fn backward_skips_are_bit_identical() {
    use unseen::raster::Kernel;
    use unseen::raster::backward::composite::{PixelGrads, SplatGrad, composite_backward};
    fn grad_bits(g: &[SplatGrad]) -> Vec<u32> {
        g.iter()
            .flat_map(|s| {
                s.mean2d
                    .into_iter()
                    .chain(s.conic)
                    .chain([s.opacity])
                    .chain(s.color)
                    .chain([s.depth])
            })
            .map(f32::to_bits)
            .collect()
    }
    let cam = default_camera(203, 117);
    let npix = (cam.width * cam.height) as usize;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut u = Uniform::new(11);
    let v_rgb: Vec<f32> = (0..npix * 3).map(|_| u.range(-1.0, 1.0)).collect();
    let v1: Vec<f32> = (0..npix).map(|_| u.range(-1.0, 1.0)).collect();
    let v2: Vec<f32> = (0..npix).map(|_| u.range(-1.0, 1.0)).collect();
    let v3: Vec<f32> = (0..npix).map(|_| u.range(-1.0, 1.0)).collect();
    for (scene, min_s, max_s) in [(12, 0.003, 0.3), (13, 0.0005, 0.6)] {
        let scene = random_scene(20_000, 3, scene, min_s, max_s);
        let opts = RenderOptions {
            background: [0.2, 0.3, 0.4],
            outputs: Outputs::ALL,
            ..Default::default()
        };
        let fwd = render_for_backward(&scene, &cam, &opts).unwrap();
        let r = &fwd.render;
        let pg = PixelGrads {
            v_rgb: Some(&v_rgb),
            v_alpha: Some(&v1),
            v_depth: Some(&v2),
            v_expected_depth: Some(&v3),
            final_t: r.final_t.as_deref().unwrap(),
            n_contrib: r.n_contrib.as_deref().unwrap(),
            blend_halves: r.blend_halves.as_deref().unwrap(),
            depth: r.depth.as_deref(),
        };
        for geometry in [true, false] {
            let mut reference: Option<(Vec<u32>, [u32; 3])> = None;
            for kernel in [Kernel::Scalar, Kernel::Avx2, Kernel::Auto] {
                let run = |cull| {
                    composite_backward(
                        w,
                        h,
                        &fwd.projected,
                        &fwd.bins,
                        cull,
                        fwd.plan.conventions.max_alpha(),
                        opts.background,
                        &pg,
                        geometry,
                        kernel,
                    )
                };
                let (a, b) = (run(true), run(false));
                let bits = grad_bits(&a.splats);
                assert!(
                    bits == grad_bits(&b.splats) && a.background == b.background,
                    "{kernel:?} geometry {geometry}"
                );
                assert!(a.splats.iter().any(|g| g.color[0] != 0.0));
                // The visits walked are all the work unit's without the skips and a strict
                // part of it with them.
                assert_eq!(b.walked, b.pairs, "{kernel:?}");
                assert!(0 < a.walked && a.walked < a.pairs, "{kernel:?}");
                let bg = a.background.map(f32::to_bits);
                match &reference {
                    None => reference = Some((bits, bg)),
                    Some(r) => assert!(
                        *r == (bits, bg),
                        "{kernel:?} vs Scalar, geometry {geometry}"
                    ),
                }
            }
        }
    }
}

/// Frozen geometry: the recorded blend replays the full render and the full SH backward
/// bit for bit after the SH coefficients change.
#[test]
fn frozen_replay_matches_full_render_and_backward() {
    use unseen::gaussian::Param;
    use unseen::raster::Kernel;
    use unseen::raster::backward::frozen::{FrozenBlend, FrozenWork};
    use unseen::raster::render;
    use unseen::train::adam::{Adam, AdamConfig};
    let cam = default_camera(203, 117);
    let mut scene = random_scene(20_000, 3, 21, 0.003, 0.3);
    // Culled Gaussians among the visible ones (behind the camera, off screen), in runs and
    // alone.
    for i in 0..scene.len() {
        if i % 5 == 1 || (i / 40) % 3 == 0 {
            scene.means[i][2] = -2.0;
        } else if i % 7 == 2 {
            scene.means[i][0] = 40.0;
        }
    }
    // The replay has AVX-512F and AVX2 loops (`Kernel::Auto`) and the scalar ones; its
    // colours are evaluated in the kernel's lanes (AVX-512F, AVX2 or one at a time) for the
    // visible Gaussians only, staged side by side.
    let cases = [
        ([0.0; 3], Kernel::Auto),
        ([0.3, 0.6, 0.9], Kernel::Auto),
        ([0.3, 0.6, 0.9], Kernel::Avx2),
        ([0.3, 0.6, 0.9], Kernel::Scalar),
    ];
    for (bg, kernel) in cases {
        let opts = RenderOptions {
            background: bg,
            kernel,
            ..Default::default()
        };
        let frozen = FrozenBlend::record(&scene, &cam, &opts).unwrap();
        let culled = frozen.visible().iter().filter(|v| !**v).count();
        assert!(culled > 8000 && culled < 14_000, "{culled} culled");
        let mut u = Uniform::new(9);
        for v in scene.sh_rest.iter_mut() {
            *v += u.range(-0.1, 0.1);
        }
        for dc in scene.sh_dc.iter_mut() {
            dc[1] += u.range(-0.2, 0.2);
        }
        let full = render(&scene, &cam, &opts).unwrap().rgb.unwrap();
        assert!(
            frozen.render_rgb(&scene).unwrap() == full,
            "replayed render differs (bg {bg:?})"
        );
        let npix = (cam.width * cam.height) as usize;
        let v = ImageGrads {
            rgb: Some((0..npix * 3).map(|_| u.range(-1.0, 1.0)).collect()),
            ..Default::default()
        };
        let groups = GradGroups {
            sh_dc: true,
            background: true,
            ..GradGroups::SH_REST
        };
        let fwd = render_for_backward(&scene, &cam, &opts).unwrap();
        let (want, _) = backward(&scene, &cam, &opts, &fwd, &v, &groups).unwrap();
        let got = frozen
            .backward_sh(&scene, v.rgb.as_ref().unwrap(), &groups)
            .unwrap();
        assert!(
            got.sh_rest == want.sh_rest && got.sh_dc == want.sh_dc,
            "SH gradients differ (bg {bg:?})"
        );
        assert_eq!(got.background, want.background);
        assert!(
            frozen
                .backward_sh(&scene, v.rgb.as_ref().unwrap(), &GradGroups::ALL)
                .is_err()
        );
        // The fused path of the QA-Mask fine-tune (reused work buffers, the SH-rest
        // gradient made per chunk inside the Adam step) gives the same bits.
        let (mut ws, mut rgb) = (FrozenWork::default(), vec![7.0; 5]);
        frozen.render_rgb_with(&scene, &mut ws, &mut rgb).unwrap();
        assert!(bits(&rgb) == bits(&full), "fused render differs");
        frozen
            .color_backward(v.rgb.as_ref().unwrap(), &mut ws)
            .unwrap();
        assert_eq!(ws.background_grad(), want.background);
        let (mut a, mut b) = (scene.clone(), scene.clone());
        let mut adam_a = Adam::new(AdamConfig::default(), &a).unwrap();
        let mut adam_b = adam_a.clone();
        for _ in 0..2 {
            adam_a.step(&mut a, Param::ShRest, &want.sh_rest, 1e-3);
            adam_b.step_with(
                &mut b,
                Param::ShRest,
                1e-3,
                &|first, g| frozen.sh_rest_grad(&ws, first, g),
                None,
            );
        }
        assert!(
            bits(&a.sh_rest) == bits(&b.sh_rest),
            "fused Adam step differs"
        );
        assert!(bits(&adam_a.v.sh_rest) == bits(&adam_b.v.sh_rest));
    }
}

/// A reused gradient buffer (`backward_into`, as training uses it) gives the bits of a fresh
/// one whatever it held: here NaN everywhere, longer and shorter than needed, and with a
/// plan degree below the scene's (the coefficients above it must come back +0.0).
#[test]
fn reused_gradient_buffers_give_fresh_bits() {
    use unseen::raster::backward::backward_into;
    let cam = default_camera(40, 30);
    let scene = random_scene(700, 3, 17, 0.01, 0.3);
    let npix = 40 * 30;
    let mut u = Uniform::new(9);
    let v = ImageGrads {
        rgb: Some((0..npix * 3).map(|_| u.range(-1.0, 1.0)).collect()),
        alpha: Some((0..npix).map(|_| u.range(-1.0, 1.0)).collect()),
        ..Default::default()
    };
    let poison = |n: usize, k: usize| Gradients {
        means: vec![[f32::NAN; 3]; n],
        log_scales: vec![[f32::NAN; 3]; n],
        quats: vec![[f32::NAN; 4]; n],
        opacity_logits: vec![f32::NAN; n],
        sh_dc: vec![[f32::NAN; 3]; n],
        sh_rest: vec![f32::NAN; n * k],
        background: [f32::NAN; 3],
        means2d: vec![[f32::NAN; 2]; n],
        means2d_ndc: vec![[f32::NAN; 2]; n],
    };
    for degree in [3, 1] {
        let opts = RenderOptions {
            sh_degree: Some(degree),
            ..Default::default()
        };
        let fwd = render_for_backward(&scene, &cam, &opts).unwrap();
        for groups in [GradGroups::ALL, GradGroups::SH_REST] {
            let (fresh, pairs) = backward(&scene, &cam, &opts, &fwd, &v, &groups).unwrap();
            for n in [100, 700, 2000] {
                let mut g = poison(n, 45);
                let p = backward_into(&scene, &cam, &opts, &fwd, &v, &groups, &mut g).unwrap();
                assert_eq!(p, pairs);
                assert!(
                    grads_bits(&g) == grads_bits(&fresh),
                    "degree {degree}, {groups:?}, buffer of {n}"
                );
            }
        }
    }
}

/// The bare backward kernel (the roofline's bound for the blend backward) walks every row a
/// splat blends on and no other, in every form, whatever the rows' split over threads.
#[test]
fn bare_backward_walks_every_visit() {
    use unseen::raster::Kernel;
    use unseen::raster::backward::composite::bare_blend_backward;
    use unseen::raster::project::Splat;
    let mut u = Uniform::new(5);
    // Wide splats blend every pixel of a tile (σ ≤ 0.26, α ≥ 0.015): every (row, splat) is
    // a visit; one splat far off blends none and is never walked.
    let mut splats: Vec<Splat> = (0..100)
        .map(|_| Splat {
            mean: [u.range(0.0, 16.0), u.range(0.0, 16.0)],
            conic: [1e-3, 0.0, 1e-3],
            opacity: u.range(0.02, 0.06),
            color: [u.unit(), u.unit(), u.unit()],
            depth: u.range(1.0, 5.0),
        })
        .collect();
    splats.insert(
        40,
        Splat {
            mean: [1e3, 1e3],
            ..splats[0]
        },
    );
    for threads in [1, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        for kernel in [Kernel::Scalar, Kernel::Avx2, Kernel::Auto] {
            for rows in [0, 1, 37] {
                let pairs = pool.install(|| bare_blend_backward(&splats, rows, kernel));
                assert_eq!(pairs, rows as u64 * 100 * 16, "{kernel:?}, {rows} rows");
            }
        }
    }
}
