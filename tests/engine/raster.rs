//! Exact answers, hard cases, render-plan skips and determinism of the forward rasterizer.
use crate::support::{bits, with_threads};
use unseen::camera::Camera;
use unseen::gaussian::Gaussians;
use unseen::raster::{
    Kernel, Outputs, Render, RenderOptions, RenderPlan, render, render_with_plan,
};
use unseen::scene::{default_camera, random_scene};

const LOGIT_ONE: f32 = 100.0; // sigmoid(100) == 1.0 exactly in f32

fn one(g: &mut Gaussians, mean: [f32; 3], log_scale: f32, logit: f32, rgb: [f32; 3]) {
    let c0 = unseen::raster::project::SH_C0_F32;
    let dc = rgb.map(|c| (c - 0.5) / c0);
    let rest = vec![0.0; g.rest_per_channel() * 3];
    g.push(mean, [log_scale; 3], [1.0, 0.0, 0.0, 0.0], logit, dc, &rest);
}

fn all_outputs(bg: [f32; 3]) -> RenderOptions {
    RenderOptions {
        background: bg,
        outputs: Outputs::ALL,
        ..Default::default()
    }
}

fn assert_all_finite(r: &Render, what: &str) {
    for (name, v) in [
        ("rgb", r.rgb.as_ref()),
        ("alpha", r.alpha.as_ref()),
        ("depth", r.depth.as_ref()),
        ("expected_depth", r.expected_depth.as_ref()),
        ("final_t", r.final_t.as_ref()),
    ] {
        if let Some(v) = v {
            assert!(
                v.iter().all(|x| x.is_finite()),
                "{what}: non-finite value in {name}"
            );
        }
    }
}

#[test]
fn empty_scene_renders_background_exactly() {
    let g = Gaussians::new(3).unwrap();
    let bg = [0.25, 0.5, 0.75];
    let r = render(&g, &default_camera(37, 21), &all_outputs(bg)).unwrap();
    for px in r.rgb.unwrap().chunks_exact(3) {
        assert_eq!(bits(px), bits(&bg));
    }
    assert!(r.alpha.unwrap().iter().all(|&a| a.to_bits() == 0));
    assert!(r.depth.unwrap().iter().all(|&d| d.to_bits() == 0));
    assert!(r.expected_depth.unwrap().iter().all(|&d| d.to_bits() == 0));
    assert!(r.final_t.unwrap().iter().all(|&t| t == 1.0));
    assert!(r.n_contrib.unwrap().iter().all(|&n| n == 0));
}

/// One opaque Gaussian covering the image: α = 0.99 (the clamp) at every pixel, so the
/// output is exactly `c·0.99 + (1 − 0.99)·bg`; a second one cannot push T below 1e-4
/// because the stop is exclusive (T would become 0.01² < 1e-4).
#[test]
fn opaque_gaussian_hides_background_to_the_clamp() {
    let cam = default_camera(48, 32);
    let bg = [1.0, 0.5, 0.25];
    let mut g = Gaussians::new(0).unwrap();
    one(
        &mut g,
        [0.0, 0.0, 5.0],
        1000f32.ln(),
        LOGIT_ONE,
        [0.2, 0.4, 0.6],
    );
    let r = render(&g, &cam, &all_outputs(bg)).unwrap();
    let c = [0.2f32, 0.4, 0.6].map(|v| {
        // The colour as the renderer computes it from the DC coefficient.
        let c0 = unseen::raster::project::SH_C0_F32;
        c0 * ((v - 0.5) / c0) + 0.5
    });
    let t = 1.0f32 * (1.0 - 0.99f32);
    for (i, px) in r.rgb.as_ref().unwrap().chunks_exact(3).enumerate() {
        for k in 0..3 {
            assert_eq!(
                px[k],
                c[k] * (0.99f32 * 1.0) + t * bg[k],
                "pixel {i} channel {k}"
            );
        }
    }
    assert!(r.final_t.as_ref().unwrap().iter().all(|&v| v == t));
    assert!(r.alpha.as_ref().unwrap().iter().all(|&a| a == 1.0 - t));

    one(
        &mut g,
        [0.0, 0.0, 6.0],
        1000f32.ln(),
        LOGIT_ONE,
        [0.9, 0.9, 0.9],
    );
    let r2 = render(&g, &cam, &all_outputs(bg)).unwrap();
    assert_eq!(
        r2.rgb, r.rgb,
        "the second opaque Gaussian must be stopped before blending"
    );
    assert!(r2.n_contrib.unwrap().iter().all(|&n| n == 1));
}

#[test]
fn gaussians_behind_camera_or_near_plane_contribute_nothing() {
    let cam = default_camera(32, 32);
    let bg = [0.1, 0.2, 0.3];
    let mut g = Gaussians::new(1).unwrap();
    for z in [-1.0, 0.0, 0.005, 0.0099] {
        one(
            &mut g,
            [0.0, 0.0, z],
            0.5f32.ln(),
            LOGIT_ONE,
            [1.0, 0.0, 0.0],
        );
    }
    let r = render(&g, &cam, &all_outputs(bg)).unwrap();
    assert_eq!(r.report.behind_near_plane, 4);
    for px in r.rgb.as_ref().unwrap().chunks_exact(3) {
        assert_eq!(bits(px), bits(&bg));
    }
    // Exactly on the near plane (z = 0.01) is drawn, as in gsplat (`z < near` culls).
    let mut g = Gaussians::new(0).unwrap();
    one(
        &mut g,
        [0.0, 0.0, 0.01],
        0.001f32.ln(),
        2.0,
        [1.0, 0.0, 0.0],
    );
    let r = render(&g, &cam, &all_outputs(bg)).unwrap();
    assert_eq!(r.report.behind_near_plane, 0);
    assert_all_finite(&r, "near plane");
}

/// The colour (and so every SH coefficient) is read and checked only for Gaussians that
/// pass the geometric culls (SPEC.md §5.1): a non-finite coefficient is counted
/// `non_finite` in view, but as the cull that comes first elsewhere, in every kernel form
/// and at the ends of a block of lanes (33 Gaussians: two AVX-512F blocks and a tail).
#[test]
fn colour_is_checked_only_where_it_is_computed() {
    let cam = default_camera(64, 48);
    for kernel in [Kernel::Auto, Kernel::Avx2, Kernel::Scalar] {
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            for at in [0, 5, 15, 16, 31, 32] {
                let mut g = Gaussians::new(3).unwrap();
                let rest = vec![0.1; g.rest_per_channel() * 3];
                let q = [1.0, 0.0, 0.0, 0.0];
                let mut expect = [0u64; 4]; // visible, non_finite, near, off screen
                for i in 0..33 {
                    // In view, behind the near plane, off screen, in view, …
                    let mean = match i % 4 {
                        1 => [0.0, 0.0, -3.0],
                        2 => [50.0, 0.0, 3.0],
                        _ => [0.1 * (i as f32 - 16.0) / 16.0, 0.0, 3.0],
                    };
                    let (mut dc, mut r) = ([0.2; 3], rest.clone());
                    if i == at || i % 7 == 3 {
                        if i % 2 == 0 {
                            dc[i % 3] = bad;
                        } else {
                            r[(5 * i) % rest.len()] = bad;
                        }
                    }
                    let poisoned = !(dc.iter().chain(&r).all(|v| v.is_finite()));
                    let slot = match (i % 4, poisoned) {
                        (1, _) => 2,
                        (2, _) => 3,
                        (_, true) => 1,
                        (_, false) => 0,
                    };
                    expect[slot] += 1;
                    g.push(mean, [-3.0; 3], q, 2.0, dc, &r);
                }
                let opts = RenderOptions {
                    kernel,
                    ..all_outputs([0.0; 3])
                };
                let r = render(&g, &cam, &opts).unwrap();
                let case = format!("{kernel:?} {bad} at {at}");
                assert_all_finite(&r, &case);
                let rep = r.report;
                assert_eq!(
                    [
                        rep.visible,
                        rep.non_finite,
                        rep.behind_near_plane,
                        rep.off_screen
                    ],
                    expect,
                    "{case}: {rep:?}"
                );
            }
        }
    }
}

/// Scales 1e-12 and 1e6, zero quaternions, NaN/Inf in every parameter, opacity 0 and 1,
/// means at the image corners, 1×1 and 4096×1 images: no NaN or Inf in any output, and the
/// bad Gaussians are skipped and counted.
#[test]
fn hard_cases_produce_finite_outputs() {
    let mut g = Gaussians::new(3).unwrap();
    let rest = vec![0.1; g.rest_per_channel() * 3];
    let q = [0.9, 0.1, -0.2, 0.3];
    g.push([0.0, 0.0, 3.0], [1e-12f32.ln(); 3], q, 2.0, [0.5; 3], &rest);
    g.push([0.1, 0.0, 3.0], [1e6f32.ln(); 3], q, 2.0, [0.5; 3], &rest);
    g.push([0.0, 0.1, 0.02], [1e6f32.ln(); 3], q, 2.0, [0.5; 3], &rest);
    g.push([0.0, 0.0, 3.0], [0.0; 3], [0.0; 4], 2.0, [0.5; 3], &rest); // zero quaternion
    g.push([0.0, 0.0, 3.0], [-1.0; 3], q, -1e30, [0.5; 3], &rest); // opacity 0
    g.push([0.0, 0.0, 3.0], [-1.0; 3], q, 1e30, [0.5; 3], &rest); // opacity 1
    g.push([-1.7, -1.7, 3.0], [-2.0; 3], q, 1.0, [0.5; 3], &rest); // corners
    g.push([1.7, 1.7, 3.0], [-2.0; 3], q, 1.0, [0.5; 3], &rest);
    g.push([0.0, 0.0, 3.0], [-30.0, 5.0, 0.0], q, 3.0, [0.5; 3], &rest); // needle
    g.push([3e38, 3e38, 3e38], [0.0; 3], q, 1.0, [0.5; 3], &rest); // beyond the far plane
    let huge = vec![f32::MAX; rest.len()];
    g.push([0.0, 0.0, 3.0], [-1.0; 3], q, 1.0, [f32::MAX; 3], &huge); // colour overflows
    // Towards −∞: clamped at 0 it would look finite (it was drawn black before the sum
    // itself was checked).
    let neg = vec![-f32::MAX; rest.len()];
    g.push([0.0, 0.0, 3.0], [-1.0; 3], q, 1.0, [-f32::MAX; 3], &neg);
    let n_overflow = 2;
    let n_good = g.len() - n_overflow; // includes the far one
    let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
    let mut n_bad = 0;
    for &b in &bad {
        for field in 0..6 {
            let (mut m, mut s, mut qq, mut o, mut dc) =
                ([0.0, 0.0, 3.0], [-1.0; 3], q, 1.0, [0.5; 3]);
            let mut r = rest.clone();
            match field {
                0 => m[1] = b,
                1 => s[2] = b,
                2 => qq[0] = b,
                3 => o = b,
                4 => dc[1] = b,
                _ => r[7] = b,
            }
            g.push(m, s, qq, o, dc, &r);
            n_bad += 1;
        }
    }
    for (w, h) in [(64, 48), (1, 1), (4096, 1), (1, 300)] {
        let cam = default_camera(w, h);
        for kernel in [Kernel::Auto, Kernel::Scalar] {
            let opts = RenderOptions {
                kernel,
                ..all_outputs([0.3, 0.3, 0.3])
            };
            let r = render(&g, &cam, &opts).unwrap();
            assert_all_finite(&r, &format!("{w}x{h}"));
            assert_eq!(r.report.non_finite, (n_bad + n_overflow) as u64, "{w}x{h}");
            // The zero quaternion, plus (for wide images) the 1e6-scale Gaussian at z = 0.02
            // whose 2D covariance determinant overflows f32: both are skipped as degenerate.
            assert!(
                (1..=2).contains(&r.report.degenerate),
                "{w}x{h}: {:?}",
                r.report
            );
            let counted = r.report.visible
                + r.report.non_finite
                + r.report.degenerate
                + r.report.low_opacity
                + r.report.off_screen
                + r.report.behind_near_plane
                + r.report.beyond_far_plane;
            assert_eq!(counted as usize, n_good + n_overflow + n_bad);
        }
    }
}

/// A scene with SH degree 3 whose bands 2 and 3 are zero: the plan evaluates degree 1.
fn scene_with_zero_high_bands() -> Gaussians {
    let mut g = random_scene(3000, 3, 11, 0.01, 0.2);
    let k1 = g.rest_per_channel();
    for i in 0..g.len() {
        for j in 3..k1 {
            for c in 0..3 {
                g.sh_rest[(i * k1 + j) * 3 + c] = 0.0;
            }
        }
    }
    g
}

/// Each skip of the minimal plan gives the same bits as the full computation.
#[test]
fn plan_skips_are_bit_identical() {
    let cam = default_camera(173, 131);
    let zero_bands = scene_with_zero_high_bands();
    assert_eq!(
        RenderPlan::new(&zero_bands, &RenderOptions::default()).sh_degree,
        1
    );
    let elongated = {
        let mut g = random_scene(2000, 1, 5, 0.001, 0.5);
        for ls in g.log_scales.iter_mut() {
            ls[0] += 2.0;
            ls[2] -= 3.0;
        }
        g
    };
    let scenes = [random_scene(4000, 2, 3, 0.01, 0.3), zero_bands, elongated];
    for (si, scene) in scenes.iter().enumerate() {
        for bg in [[0.0; 3], [0.2, 0.7, 1.0]] {
            for outputs in [
                Outputs::RGB,
                Outputs {
                    alpha: true,
                    ..Outputs::RGB
                },
                Outputs::ALL,
            ] {
                let opts = RenderOptions {
                    background: bg,
                    outputs,
                    ..Default::default()
                };
                let minimal = render(scene, &cam, &opts).unwrap();
                let full =
                    render_with_plan(scene, &cam, &opts, &RenderPlan::full(scene, &opts)).unwrap();
                let what = format!("scene {si}, bg {bg:?}, {outputs:?}");
                assert_eq!(
                    bits(minimal.rgb.as_ref().unwrap()),
                    bits(full.rgb.as_ref().unwrap()),
                    "{what}"
                );
                for (a, b) in [
                    (&minimal.alpha, &full.alpha),
                    (&minimal.depth, &full.depth),
                    (&minimal.expected_depth, &full.expected_depth),
                    (&minimal.final_t, &full.final_t),
                ] {
                    if let (Some(a), Some(b)) = (a, b) {
                        assert_eq!(bits(a), bits(b), "{what}");
                    }
                }
                assert_eq!(
                    minimal.n_contrib,
                    full.n_contrib.filter(|_| outputs.backward_state)
                );
                assert!(minimal.report.pairs_evaluated <= full.report.pairs_evaluated);
            }
        }
    }
}

/// The vectorized kernel (AVX2 when the CPU has it) and the one-pixel-at-a-time reference
/// give the same bits.
#[test]
fn simd_and_scalar_kernels_are_bit_identical() {
    let cam = default_camera(211, 97);
    for (n, deg, seed) in [(500, 0, 1), (5000, 3, 2), (20000, 5, 3)] {
        let scene = random_scene(n, deg, seed, 0.005, 0.4);
        let with = |kernel| {
            let opts = RenderOptions {
                kernel,
                ..all_outputs([0.1, 0.2, 0.3])
            };
            render(&scene, &cam, &opts).unwrap()
        };
        // Auto is AVX-512F where the CPU has it, so all three forms are compared there.
        let scalar = with(Kernel::Scalar);
        assert_eq!(
            with(Kernel::Auto),
            scalar,
            "auto, {n} Gaussians, degree {deg}"
        );
        assert_eq!(
            with(Kernel::Avx2),
            scalar,
            "avx2, {n} Gaussians, degree {deg}"
        );
    }
}

/// 100k Gaussians: bit-identical outputs for 1, 2 and 7 threads and across runs.
#[test]
fn render_is_deterministic_across_thread_counts() {
    let scene = random_scene(100_000, 3, 42, 0.002, 0.08);
    let cam: Camera = default_camera(320, 240);
    let opts = all_outputs([0.05, 0.1, 0.15]);
    let reference = with_threads(1, || render(&scene, &cam, &opts).unwrap());
    assert!(reference.report.visible > 90_000);
    for threads in [2, 7, 2] {
        let r = with_threads(threads, || render(&scene, &cam, &opts).unwrap());
        assert_eq!(r, reference, "{threads} threads");
    }
}

/// The eight-lane projection (AVX2) against the one-lane reference, bit for bit, on a scene
/// where a quarter of the Gaussians carry a hard value (NaN, ±∞, ±0, huge, tiny; means on
/// and behind the near plane, at the image border) scattered over every lane position,
/// for SH degrees 0–5, with and without antialiasing, and chunk tails of every length.
#[test]
fn projection_simd_matches_scalar_bitwise() {
    use unseen::raster::project::{Projected, project};
    use unseen::raster::{RenderPlan, RenderReport};
    use unseen::rng::Uniform;
    let specials = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        0.0,
        -0.0,
        1e-30,
        -1e-30,
        1e30,
        -1e30,
        f32::MAX,
        0.01,
        1e-3,
    ];
    let run =
        |g: &Gaussians, cam: &Camera, aa: bool, kernel: Kernel| -> (Projected, RenderReport) {
            let opts = RenderOptions {
                antialiased: aa,
                kernel,
                ..RenderOptions::default()
            };
            let plan = RenderPlan::full(g, &opts);
            let mut report = RenderReport::default();
            (project(g, cam, &plan, &opts, &mut report), report)
        };
    for degree in 0..=5 {
        let base = random_scene(
            1001 + degree as usize,
            degree,
            90 + degree as u64,
            0.002,
            0.5,
        );
        let mut u = Uniform::new(7 + degree as u64);
        let mut g = Gaussians::new(degree).unwrap();
        let stride = g.rest_per_channel() * 3;
        for i in 0..base.len() {
            let (mut m, mut s, mut q) = (base.means[i], base.log_scales[i], base.quats[i]);
            let (mut o, mut dc) = (base.opacity_logits[i], base.sh_dc[i]);
            let mut rest = base.rest(i).to_vec();
            if u.below(4) == 0 {
                let v = specials[u.below(specials.len() as u32) as usize];
                match u.below(9) {
                    0 => m[u.below(3) as usize] = v,
                    1 => m[2] = v, // on, behind or far beyond the near plane
                    2 => s[u.below(3) as usize] = v,
                    3 => q[u.below(4) as usize] = v,
                    4 => q = [v; 4],
                    5 => o = v,
                    6 => dc[u.below(3) as usize] = v,
                    7 if stride > 0 => rest[u.below(stride as u32) as usize] = v,
                    _ => m = [m[0] * 1.6, m[1] * 1.6, 2.0], // at and beyond the border
                }
            }
            g.push(m, s, q, o, dc, &rest);
        }
        for aa in [false, true] {
            for (w, h) in [(64, 48), (1, 1), (300, 7)] {
                let cam = default_camera(w, h);
                // Auto is AVX-512F where the CPU has it: all three forms are compared there.
                let (b, rb) = run(&g, &cam, aa, Kernel::Scalar);
                assert!(rb.visible > 0 && rb.non_finite > 0, "{rb:?}");
                for kernel in [Kernel::Auto, Kernel::Avx2] {
                    let (a, ra) = run(&g, &cam, aa, kernel);
                    let case = format!("{kernel:?}, degree {degree} aa {aa} {w}x{h}");
                    assert_eq!(ra, rb, "{case}");
                    assert_eq!(a.radii, b.radii, "{case}");
                    for (i, (x, y)) in a.splats.iter().zip(&b.splats).enumerate() {
                        let f = |s: &unseen::raster::project::Splat| {
                            let mut v = vec![s.opacity, s.depth];
                            v.extend(s.mean.iter().chain(&s.conic).chain(&s.color));
                            bits(&v)
                        };
                        assert_eq!(f(x), f(y), "Gaussian {i}, {case}");
                    }
                }
            }
        }
    }
}

/// The antialiased mode renders forward only (SPEC.md §5.8): asking for its backward is one
/// clear error, not a gradient of the plain mode.
#[test]
fn antialiased_backward_is_a_clear_error() {
    let scene = random_scene(50, 1, 5, 0.01, 0.2);
    let cam = default_camera(32, 24);
    let opts = RenderOptions {
        antialiased: true,
        ..RenderOptions::default()
    };
    assert!(render(&scene, &cam, &opts).is_ok(), "the forward runs");
    let e = unseen::raster::backward::render_for_backward(&scene, &cam, &opts)
        .err()
        .expect("the backward refuses");
    assert_eq!(e.kind, unseen::error::ErrorKind::Invalid);
    assert!(e.message.contains("antialiased"), "{e}");
}

/// Cut-offs other than gsplat's (a forward-only knob, SPEC.md §5.5): every kernel form
/// gives the same bits under each, the knob changes the image, and the backward refuses it.
#[test]
fn cutoffs_are_the_same_in_every_kernel() {
    use unseen::raster::Cutoffs;
    let scene = random_scene(2000, 3, 5, 0.01, 0.2);
    let cam = default_camera(80, 56);
    let render_with = |cutoffs: Cutoffs, kernel: Kernel| {
        let opts = RenderOptions {
            background: [0.1, 0.2, 0.3],
            outputs: Outputs::ALL,
            kernel,
            cutoffs,
            ..RenderOptions::default()
        };
        render(&scene, &cam, &opts).unwrap()
    };
    let gsplat = render_with(Cutoffs::GSPLAT, Kernel::Auto);
    for (inv_alpha_threshold, transmittance_stop) in
        [(1000.0, 1e-4), (255.0, 1e-6), (f32::INFINITY, 0.0)]
    {
        let cutoffs = Cutoffs {
            inv_alpha_threshold,
            transmittance_stop,
        };
        let reference = render_with(cutoffs, Kernel::Scalar);
        for kernel in [Kernel::Avx2, Kernel::Auto] {
            let r = render_with(cutoffs, kernel);
            assert_eq!(
                bits(r.rgb.as_ref().unwrap()),
                bits(reference.rgb.as_ref().unwrap())
            );
            assert_eq!(
                bits(r.depth.as_ref().unwrap()),
                bits(reference.depth.as_ref().unwrap())
            );
            assert_eq!(r.n_contrib, reference.n_contrib, "{cutoffs:?}, {kernel:?}");
        }
        assert_ne!(
            bits(reference.rgb.as_ref().unwrap()),
            bits(gsplat.rgb.as_ref().unwrap()),
            "{cutoffs:?} changed nothing"
        );
        let opts = RenderOptions {
            cutoffs,
            ..RenderOptions::default()
        };
        let err = unseen::raster::backward::render_for_backward(&scene, &cam, &opts)
            .err()
            .expect("the backward refuses other cut-offs");
        assert!(err.to_string().contains("cut-offs"), "{err}");
    }
    for (inv, stop) in [(0.5, 1e-4), (f32::NAN, 1e-4), (255.0, 1.0), (255.0, -1e-9)] {
        let opts = RenderOptions {
            cutoffs: Cutoffs {
                inv_alpha_threshold: inv,
                transmittance_stop: stop,
            },
            ..RenderOptions::default()
        };
        assert!(
            render(&scene, &cam, &opts).is_err(),
            "{inv}, {stop} accepted"
        );
    }
}

/// With a lower alpha threshold and transmittance stop, the f32 render still agrees with
/// the f64 twin given the same cut-offs to [`CUTOFF_TWIN_ATOL`] where the 3.33σ extent
/// cannot bind (opacities ≤ 0.2: `0.2·e^(−3.33²/2) < 1/1000`, so the threshold, not the
/// extent, ends every splat, as in the twin).
#[test]
fn lower_cutoffs_agree_with_the_f64_twin() {
    use super::twin::{flatten, forward64_cut};
    use unseen::raster::Cutoffs;
    /// f32 rounding of the blend sums (the default cut-offs give 1.8e-6 on the accuracy
    /// bench's scene, `reference_data/accuracy/`), with a margin of 10.
    const CUTOFF_TWIN_ATOL: f64 = 2e-5;
    let mut scene = random_scene(1500, 3, 9, 0.01, 0.2);
    let cap = (0.2f32 / 0.8).ln();
    for l in scene.opacity_logits.iter_mut() {
        *l = l.min(cap);
    }
    let cam = default_camera(64, 48);
    let bg = [0.1f32, 0.2, 0.3];
    for (inv, stop) in [(1000.0f32, 1e-6f32), (255.0, 1e-6), (1000.0, 1e-4)] {
        let opts = RenderOptions {
            background: bg,
            cutoffs: Cutoffs {
                inv_alpha_threshold: inv,
                transmittance_stop: stop,
            },
            ..RenderOptions::default()
        };
        let r = render(&scene, &cam, &opts).unwrap();
        let twin = forward64_cut(
            &scene,
            &flatten(&scene),
            &cam,
            bg.map(f64::from),
            f64::from(1.0 / inv),
            f64::from(stop),
        );
        let err = r
            .rgb
            .unwrap()
            .iter()
            .zip(&twin[0])
            .map(|(&a, &b)| (f64::from(a) - b).abs())
            .fold(0.0, f64::max);
        assert!(err <= CUTOFF_TWIN_ATOL, "1/{inv}, stop {stop}: {err:e}");
    }
}

/// Under a lower alpha threshold the 3.33σ cap can bind (`N·o > 255.9`), so row culling
/// would skip rows where α ≥ 1/N: the minimal plan then evaluates every row of a binned
/// tile, and still gives the full plan's bits (SPEC.md §5.4, review of issue #15's knob).
/// Plans with invalid cut-offs are refused; without a threshold α must still be > 0.
#[test]
fn cutoffs_keep_plan_skips_exact() {
    use unseen::raster::Cutoffs;
    let cam = default_camera(96, 80);
    let mut scene = random_scene(1500, 2, 13, 0.01, 0.3);
    for (k, l) in scene.opacity_logits.iter_mut().enumerate() {
        if k % 3 == 0 {
            *l = 2.5; // o ≈ 0.92: 1000·o is far past the cap
        }
    }
    for inv in [255.0, 1000.0, f32::INFINITY] {
        let opts = RenderOptions {
            background: [0.2, 0.7, 1.0],
            outputs: Outputs::ALL,
            cutoffs: Cutoffs {
                inv_alpha_threshold: inv,
                transmittance_stop: 1e-6,
            },
            ..Default::default()
        };
        assert_eq!(RenderPlan::new(&scene, &opts).cull_rows, inv <= 255.0);
        let minimal = render(&scene, &cam, &opts).unwrap();
        let full = render_with_plan(&scene, &cam, &opts, &RenderPlan::full(&scene, &opts)).unwrap();
        for (a, b) in [
            (&minimal.rgb, &full.rgb),
            (&minimal.alpha, &full.alpha),
            (&minimal.depth, &full.depth),
        ] {
            assert_eq!(
                bits(a.as_ref().unwrap()),
                bits(b.as_ref().unwrap()),
                "1/{inv}"
            );
        }
        assert_eq!(minimal.n_contrib, full.n_contrib, "1/{inv}");
    }
    // A plan's own cut-offs are checked too.
    let opts = RenderOptions::default();
    let mut plan = RenderPlan::new(&scene, &opts);
    plan.cutoffs.inv_alpha_threshold = f32::NAN;
    assert!(render_with_plan(&scene, &cam, &opts, &plan).is_err());
    // Without a threshold "α ≥ threshold" is "α > 0": the threshold is the smallest
    // positive f32, so an α (or opacity) of exactly 0 is never blended.
    let none = Cutoffs {
        inv_alpha_threshold: f32::INFINITY,
        transmittance_stop: 0.0,
    };
    assert_eq!(none.alpha_threshold(), f32::from_bits(1));
    assert_eq!(Cutoffs::GSPLAT.alpha_threshold(), 1.0 / 255.0);
}

/// The tile size is not an accuracy knob (SPEC.md §5.3): every output but `n_contrib` is
/// the blend over one list for the whole image (`twin::blend_untiled::<f32>`: the same f32
/// arithmetic, every visible splat at every pixel, no tiles, no row culling), bit for bit —
/// so any tile size gives these bits. Scenes: small and large splats (lists of one to
/// hundreds of tiles), elongated ones (the rectangle is the bound that must not cut off a
/// pixel with α ≥ 1/255), splats around the image border, and a dense opaque pile where
/// pixels stop at the transmittance floor; an image size that is no multiple of 16.
#[test]
fn tiles_change_no_output_bit() {
    use super::twin::blend_untiled;
    use unseen::raster::render_staged;
    let cam = default_camera(93, 61);
    let elongated = {
        let mut g = random_scene(1500, 1, 5, 0.001, 0.5);
        for ls in g.log_scales.iter_mut() {
            ls[0] += 2.0;
            ls[2] -= 3.0;
        }
        g
    };
    let border = {
        let mut g = random_scene(800, 2, 9, 0.005, 0.1);
        for m in g.means.iter_mut() {
            // x/z and y/z near the frustum's edges (60° horizontal field of view).
            m[0] = m[0].signum() * 0.58 * m[2] + 0.02 * m[0];
        }
        g
    };
    let dense = {
        let mut g = random_scene(3000, 0, 11, 0.02, 0.2);
        g.opacity_logits.iter_mut().for_each(|o| *o = o.abs() + 4.0);
        g
    };
    let scenes = [
        ("small", random_scene(3000, 3, 3, 0.002, 0.02)),
        ("large", random_scene(600, 2, 4, 0.05, 0.6)),
        ("elongated", elongated),
        ("border", border),
        ("dense", dense),
    ];
    for (name, scene) in &scenes {
        for bg in [[0.0; 3], [0.2, 0.7, 1.0]] {
            let opts = all_outputs(bg);
            let plan = RenderPlan::new(scene, &opts);
            let (r, projected, _) = render_staged(scene, &cam, &opts, &plan).unwrap();
            let [rgb, alpha, depth, ed, t] =
                blend_untiled::<f32>(&projected, cam.width as usize, cam.height as usize, bg);
            let what = format!("scene {name}, bg {bg:?}");
            assert_eq!(bits(r.rgb.as_ref().unwrap()), bits(&rgb), "rgb, {what}");
            assert_eq!(
                bits(r.alpha.as_ref().unwrap()),
                bits(&alpha),
                "alpha, {what}"
            );
            assert_eq!(
                bits(r.depth.as_ref().unwrap()),
                bits(&depth),
                "depth, {what}"
            );
            assert_eq!(
                bits(r.expected_depth.as_ref().unwrap()),
                bits(&ed),
                "ED, {what}"
            );
            assert_eq!(
                bits(r.final_t.as_ref().unwrap()),
                bits(&t),
                "final T, {what}"
            );
        }
    }
}

/// The blend kernels' exact rewrites (SPEC.md §5.7: −σ in place of σ, the exponential
/// without its range clamps, masked accumulation) on the splats that probe them: centres
/// exactly on pixel centres with B < 0, = 0 and > 0 (σ = +0 from a cancelling −0, the case
/// where −σ's zero may differ in sign), conics that are not positive definite (σ far below 0
/// over most of the tile: lanes whose unclamped exponential is garbage must stay masked
/// out), a NaN conic, α at the clamp. Forward (every output) and backward (every gradient)
/// of the scalar, AVX2 and Auto kernels compared bit for bit.
#[test]
fn kernels_agree_on_centred_and_degenerate_splats() {
    use unseen::raster::RenderReport;
    use unseen::raster::backward::PixelGrads;
    use unseen::raster::backward::composite::composite_backward;
    use unseen::raster::composite::{Want, composite};
    use unseen::raster::project::{Projected, Splat};
    use unseen::raster::tile::bin;
    use unseen::rng::Uniform;
    let (w, h) = (40usize, 36usize);
    let mut u = Uniform::new(11);
    let mut splats = Vec::new();
    for k in 0..60 {
        let (x, y) = ((k * 7 % w) as f32 + 0.5, (k * 5 % h) as f32 + 0.5);
        let b = [-0.3, 0.0, 0.3][k % 3];
        splats.push(Splat {
            mean: [x, y],
            conic: [0.5, b, 0.4],
            opacity: [0.5, 0.995, 1.0, 0.02][k % 4],
            color: [u.unit(), u.unit(), u.unit()],
            depth: 1.0 + u.unit(),
        });
    }
    for k in 0..30 {
        // Not positive definite: B² > A·C, σ ≈ −B·|dx·dy| down to about −900.
        splats.push(Splat {
            mean: [u.range(0.0, w as f32), u.range(0.0, h as f32)],
            conic: [0.2, [3.0, -4.0, 2.5][k % 3], 0.1],
            opacity: 0.7,
            color: [u.unit(), u.unit(), u.unit()],
            depth: 0.5 + u.unit(),
        });
    }
    splats.push(Splat {
        mean: [10.5, 10.5],
        conic: [f32::NAN, 0.0, 1.0],
        opacity: 0.5,
        color: [0.5; 3],
        depth: 1.0,
    });
    let radii = vec![[14, 14]; splats.len()];
    let p = Projected { splats, radii };
    let scene = random_scene(1, 0, 1, 0.01, 0.1);
    let opts = RenderOptions {
        outputs: Outputs::ALL,
        ..Default::default()
    };
    let plan = RenderPlan::new(&scene, &opts);
    assert!(plan.track_backward_state && plan.accumulate_depth);
    let want = Want {
        rgb: true,
        alpha: true,
        depth: true,
        expected_depth: true,
        backward_state: true,
    };
    let bg = [0.1, 0.2, 0.3];
    let kernels = [Kernel::Scalar, Kernel::Avx2, Kernel::Auto];
    let outs: Vec<_> = kernels
        .iter()
        .map(|&k| {
            let bins = bin(&p, w, h, k);
            let out = composite(
                w,
                h,
                &p,
                &bins,
                &plan,
                bg,
                want,
                k,
                &mut RenderReport::default(),
            );
            (bins, out)
        })
        .collect();
    let (bins, reference) = &outs[0];
    let images = |o: &unseen::raster::composite::CompositeOut| {
        let f = |v: &Option<Vec<f32>>| bits(v.as_deref().unwrap());
        [
            f(&o.rgb),
            f(&o.alpha),
            f(&o.depth),
            f(&o.expected_depth),
            f(&o.final_t),
        ]
    };
    assert!(reference.alpha.as_ref().unwrap().iter().any(|&a| a > 0.5));
    for ((_, out), k) in outs.iter().zip(kernels).skip(1) {
        assert!(images(out) == images(reference), "forward, {k:?}");
        assert_eq!(out.n_contrib, reference.n_contrib, "n_contrib, {k:?}");
        assert_eq!(
            out.blend_halves, reference.blend_halves,
            "blend_halves, {k:?}"
        );
    }
    // The record marks exactly the row halves where some pixel blended the splat: before the
    // pixel's n_contrib, in a row the splat's radius reaches (row culling, SPEC.md §5.4; the
    // radii here are not the conics'), σ ≥ 0 and α ≥ 1/255, with the forward's f32 arithmetic
    // (SPEC.md §5.8); the backward walks only those.
    let (nc, rec) = (
        reference.n_contrib.as_deref().unwrap(),
        reference.blend_halves.as_deref().unwrap(),
    );
    let max_alpha = plan.conventions.max_alpha();
    let mut marked = 0;
    for t in 0..bins.tiles_x * bins.tiles_y {
        let (y0, x0) = ((t / bins.tiles_x) * 16, (t % bins.tiles_x) * 16);
        for (pos, &gid) in bins.tile(t).iter().enumerate() {
            let s = &p.splats[gid as usize];
            let ry = p.radii[gid as usize][1] as f32 + 1.0;
            let reach = ((s.mean[1] - ry).floor() as i64)..((s.mean[1] + ry).ceil() as i64 + 1);
            assert!(plan.cull_rows);
            let mut expected = 0u32;
            for row in 0..16 {
                for l in 0..16 {
                    let (x, y) = (x0 + l, y0 + row);
                    if x >= w
                        || y >= h
                        || pos as u32 >= nc[y * w + x]
                        || !reach.contains(&(y as i64))
                    {
                        continue;
                    }
                    let (dx, dy) = (s.mean[0] - (x as f32 + 0.5), s.mean[1] - (y as f32 + 0.5));
                    let sigma =
                        0.5 * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) + s.conic[1] * dx * dy;
                    let alpha =
                        (s.opacity * unseen::math::fastexp::exp(-sigma.min(30.0))).min(max_alpha);
                    if sigma >= 0.0 && alpha >= unseen::raster::project::ALPHA_THRESHOLD {
                        expected |= 1 << (2 * row + l / 8);
                    }
                }
            }
            assert_eq!(
                rec[bins.offsets[t] + pos],
                expected,
                "tile {t}, position {pos}"
            );
            marked += expected.count_ones();
        }
    }
    assert!(marked > 100, "{marked} row halves blended");
    let n = w * h;
    let v: Vec<f32> = (0..4 * n).map(|_| u.range(-1.0, 1.0)).collect();
    let g = PixelGrads {
        v_rgb: Some(&v[..3 * n]),
        v_alpha: Some(&v[3 * n..]),
        v_depth: None,
        v_expected_depth: None,
        final_t: reference.final_t.as_deref().unwrap(),
        n_contrib: reference.n_contrib.as_deref().unwrap(),
        blend_halves: reference.blend_halves.as_deref().unwrap(),
        depth: None,
    };
    let grads = |k| {
        let r = composite_backward(
            w,
            h,
            &p,
            bins,
            plan.cull_rows,
            plan.conventions.max_alpha(),
            bg,
            &g,
            true,
            k,
        );
        let mut all: Vec<f32> = unseen::raster::backward::SplatGrad::floats(&r.splats).to_vec();
        all.extend(r.background);
        (bits(&all), r.pairs)
    };
    let reference = grads(Kernel::Scalar);
    assert!(reference.0.iter().any(|&b| b != 0));
    for k in [Kernel::Avx2, Kernel::Auto] {
        assert!(grads(k) == reference, "backward, {k:?}");
    }
}
