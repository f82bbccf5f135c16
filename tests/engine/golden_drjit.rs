//! Renders against the independent Dr.Jit float64 reference
//! (`reference_data/generate/make_raster_goldens.py`).
use crate::support::{case_dirs, reference};
use unseen::camera::inria::read_cameras_json;
use unseen::gaussian::ply::read_ply;
use unseen::io::image::read_exr;
use unseen::raster::{Conventions, Outputs, RenderOptions, render};

/// Colour and alpha: |ours − Dr.Jit f64| ≤ atol + rtol·|ref|. gsplat's own tests use
/// atol 1e-5, rtol 1.3e-6 (f32 CUDA vs f32 PyTorch); against an f64 reference our f32
/// rounding measures ≤ 1.0e-6 on colour and ≤ 4.0e-6 on alpha, so we hold 2× below gsplat.
const GOLDEN_COLOR_ATOL: f64 = 5e-6;
const GOLDEN_COLOR_RTOL: f64 = 1.3e-6;
/// Accumulated depth D is a sum of z (up to ~6) times weights: f32 rounding scales with z.
/// Measured ≤ 1.1e-5 (near case, D ≈ 2–4).
const GOLDEN_DEPTH_ATOL: f64 = 5e-6;
const GOLDEN_DEPTH_RTOL: f64 = 5e-6;
/// At most this fraction of pixels may be excluded as ambiguous (the reference passes within
/// a relative 2e-5 of a 1/255, 0.99 or 1e-4 threshold there).
const MAX_AMBIGUOUS_FRACTION: f64 = 1e-3;

struct Stat {
    max_abs: f64,
    worst_excess: f64,
}

/// max |a−b| and the largest `|a−b| − (atol + rtol·|b|)` over non-ambiguous pixels.
fn compare(got: &[f32], want: &[f32], amb: &[f32], ch: usize, atol: f64, rtol: f64) -> Stat {
    let mut s = Stat {
        max_abs: 0.0,
        worst_excess: f64::NEG_INFINITY,
    };
    for (i, (&g, &w)) in got.iter().zip(want).enumerate() {
        if amb[i / ch] != 0.0 {
            continue;
        }
        let d = (g as f64 - w as f64).abs();
        s.max_abs = s.max_abs.max(d);
        s.worst_excess = s.worst_excess.max(d - (atol + rtol * (w as f64).abs()));
    }
    s
}

#[test]
fn drjit_forward_goldens() {
    let cases = case_dirs("drjit/raster");
    assert!(cases.len() >= 5, "expected at least 5 golden cases");
    let mut failures = Vec::new();
    for dir in cases {
        let meta: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("meta.json")).unwrap()).unwrap();
        let bg: Vec<f32> = meta["background"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() as f32)
            .collect();
        let (scene, _) = read_ply(&dir.join("scene.ply")).unwrap();
        let cam = &read_cameras_json(&dir.join("cameras.json")).unwrap()[0];
        // Every golden states its convention profile (SPEC.md §5.2).
        let conventions = meta["conventions"]
            .as_str()
            .map(|c| Conventions::parse(c).unwrap())
            .expect("meta.json states its conventions");
        let opts = RenderOptions {
            background: [bg[0], bg[1], bg[2]],
            outputs: Outputs::ALL,
            conventions,
            ..Default::default()
        };
        let r = render(&scene, cam, &opts).unwrap();
        let amb = read_exr(&dir.join("ambiguous.exr"), &["Y"]).unwrap().data;
        let rgb = read_exr(&dir.join("rgb.exr"), &["R", "G", "B"])
            .unwrap()
            .data;
        let alpha = read_exr(&dir.join("alpha.exr"), &["Y"]).unwrap().data;
        let depth = read_exr(&dir.join("depth.exr"), &["Y"]).unwrap().data;
        let name = dir.file_name().unwrap().to_string_lossy().into_owned();
        let n_amb = amb.iter().filter(|&&a| a != 0.0).count();
        assert!(
            n_amb as f64 <= MAX_AMBIGUOUS_FRACTION * amb.len() as f64,
            "{name}: {n_amb} ambiguous"
        );
        let mean_alpha = alpha.iter().map(|&a| a as f64).sum::<f64>() / alpha.len() as f64;
        assert!(mean_alpha > 0.1, "{name}: reference image nearly empty");
        // The reference has no off-screen or zero-radius cull, so it may draw more.
        let (v, rep) = (meta["visible"].as_u64().unwrap(), &r.report);
        assert!(
            rep.visible <= v && v <= rep.visible + rep.off_screen + rep.low_opacity,
            "{name}"
        );
        for (what, got, want, ch, atol, rtol) in [
            (
                "rgb",
                r.rgb.as_ref().unwrap(),
                &rgb,
                3,
                GOLDEN_COLOR_ATOL,
                GOLDEN_COLOR_RTOL,
            ),
            (
                "alpha",
                r.alpha.as_ref().unwrap(),
                &alpha,
                1,
                GOLDEN_COLOR_ATOL,
                GOLDEN_COLOR_RTOL,
            ),
            (
                "depth",
                r.depth.as_ref().unwrap(),
                &depth,
                1,
                GOLDEN_DEPTH_ATOL,
                GOLDEN_DEPTH_RTOL,
            ),
        ] {
            let s = compare(got, want, &amb, ch, atol, rtol);
            println!("{name} {what}: max |diff| = {:.3e}", s.max_abs);
            if s.worst_excess > 0.0 {
                failures.push(format!("{name} {what}: max |diff| {:.3e}", s.max_abs));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "outside tolerance:\n{}",
        failures.join("\n")
    );
}

/// The PLY written by the golden script (INRIA layout, degrees 0–5) loads with the values the
/// script wrote: f_rest channel-major in the file, coefficient-major in memory.
#[test]
fn drjit_ply_values_load_exactly() {
    let mut degrees = Vec::new();
    for dir in case_dirs("drjit/raster") {
        let head: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("params_head.json")).unwrap()).unwrap();
        let (g, info) = read_ply(&dir.join("scene.ply")).unwrap();
        assert!(info.ignored_properties.is_empty());
        degrees.push(g.sh_degree);
        let f = |v: &serde_json::Value| v.as_f64().unwrap() as f32;
        for i in 0..4 {
            for k in 0..3 {
                assert_eq!(g.means[i][k], f(&head["means"][i][k]));
                assert_eq!(g.log_scales[i][k], f(&head["log_scales"][i][k]));
                assert_eq!(g.sh_dc[i][k], f(&head["sh_dc"][i][k]));
            }
            for k in 0..4 {
                assert_eq!(g.quats[i][k], f(&head["quats"][i][k]));
            }
            assert_eq!(g.opacity_logits[i], f(&head["opacity_logits"][i]));
            let rest = g.rest(i);
            for j in 0..g.rest_per_channel() {
                for c in 0..3 {
                    assert_eq!(
                        rest[j * 3 + c],
                        f(&head["sh_rest"][i][j][c]),
                        "rest {i} {j} {c}"
                    );
                }
            }
        }
    }
    assert!(degrees.contains(&3) && degrees.contains(&5));
}

/// SH basis values against Dr.Jit's `sh_eval` (f64) on 256 random unit directions.
/// f32 evaluation of the degree-5 polynomials: measured ≤ 7.7e-7; the issue asks 1e-6.
const SH_F32_ATOL: f64 = 1e-6;

#[test]
fn sh_basis_matches_drjit() {
    use unseen::math::sh::{num_coeffs, sh_basis};
    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(reference("drjit/sh/sh.json")).unwrap()).unwrap();
    let dirs = j["directions"].as_array().unwrap();
    let vals = j["values"].as_array().unwrap();
    let mut worst = 0f64;
    for (d, v) in dirs.iter().zip(vals) {
        let d: Vec<f64> = d
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        for degree in 0..=5 {
            let mut out32 = [0f32; 36];
            let mut out64 = [0f64; 36];
            sh_basis(degree, d[0] as f32, d[1] as f32, d[2] as f32, &mut out32);
            sh_basis(degree, d[0], d[1], d[2], &mut out64);
            for k in 0..num_coeffs(degree) {
                let want = v[k].as_f64().unwrap();
                worst = worst.max((out32[k] as f64 - want).abs());
                assert!(
                    (out32[k] as f64 - want).abs() <= SH_F32_ATOL,
                    "deg {degree} k {k}"
                );
                assert!((out64[k] - want).abs() <= 1e-13, "f64 deg {degree} k {k}");
            }
        }
    }
    println!("SH f32 worst error vs Dr.Jit: {worst:.2e}");
}
