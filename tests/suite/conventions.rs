//! Convention profiles (SPEC.md §5.2: the α clamp of INRIA / gsplat ≥ 1.5.4 and of gsplat
//! 1.0–1.5.3) and the decision diagnostics a port harness builds on (SPEC.md §8.1).
use crate::support::{TempDir, bits, reference, with_threads};
use std::process::Command;
use unseen::camera::Camera;
use unseen::gaussian::Gaussians;
use unseen::raster::backward::{GradGroups, ImageGrads, backward, render_for_backward};
use unseen::raster::decisions::{
    GAUSSIAN_ILL_CONDITIONED, GAUSSIAN_OPACITY_CULL, Margins, PIXEL_ALPHA_CLAMP,
    PIXEL_ALPHA_THRESHOLD, PIXEL_DEPTH_TIE, PIXEL_FORWARD_FLAGS, PIXEL_ILL_CONDITIONED,
    PIXEL_TRANSMITTANCE_STOP, decisions,
};
use unseen::raster::{Conventions, Cutoffs, Kernel, Outputs, RenderOptions, render};
use unseen::rng::Uniform;
use unseen::scene::{default_camera, random_scene};

const LOGIT_ONE: f32 = 100.0; // sigmoid(100) == 1.0 exactly in f32

fn opts(conventions: Conventions, kernel: Kernel) -> RenderOptions {
    RenderOptions {
        background: [0.3, 0.2, 0.1],
        outputs: Outputs::ALL,
        conventions,
        kernel,
        ..Default::default()
    }
}

/// A flat-coloured isotropic Gaussian (DC only).
fn one(g: &mut Gaussians, mean: [f32; 3], log_scale: f32, logit: f32) {
    let rest = vec![0.0; g.rest_per_channel() * 3];
    g.push(
        mean,
        [log_scale; 3],
        [1.0, 0.0, 0.0, 0.0],
        logit,
        [0.4, -0.2, 0.1],
        &rest,
    );
}

/// A one-pixel camera whose pixel centre looks down +z at the origin's x, y.
fn pixel_camera() -> Camera {
    Camera::new(
        "px",
        1,
        1,
        10.0,
        10.0,
        glam::DMat3::IDENTITY,
        glam::DVec3::ZERO,
    )
    .unwrap()
}

/// The logit whose f32 sigmoid is `o` (within rounding).
fn logit(o: f64) -> f32 {
    (o / (1.0 - o)).ln() as f32
}

#[test]
fn gsplat_profile_clamps_alpha_at_0_999() {
    let cam = default_camera(32, 24);
    let mut g = Gaussians::new(0).unwrap();
    one(&mut g, [0.0, 0.0, 5.0], 1000f32.ln(), LOGIT_ONE);
    for (c, max_alpha) in [
        (Conventions::Inria, 0.99f32),
        (Conventions::Gsplat, 0.999f32),
    ] {
        assert_eq!(c.max_alpha(), max_alpha);
        assert_eq!(Conventions::parse(c.name()).unwrap(), c);
        let r = render(&g, &cam, &opts(c, Kernel::Auto)).unwrap();
        let t = 1.0f32 - max_alpha;
        assert!(r.final_t.unwrap().iter().all(|&v| v == t), "{c}");
        assert!(r.alpha.unwrap().iter().all(|&a| a == 1.0 - t), "{c}");
    }
    assert!(
        Conventions::parse("cuda")
            .unwrap_err()
            .to_string()
            .contains("inria, gsplat")
    );
}

/// Under either profile, every kernel form and thread count gives the same bits, forward
/// and backward; the profiles differ where the clamp binds and nowhere else.
#[test]
fn profiles_are_the_same_bits_in_every_kernel_and_differ_only_at_the_clamp() {
    let cam = default_camera(80, 60);
    let mut opaque = random_scene(1500, 2, 7, 0.02, 0.2);
    let mut u = Uniform::new(8);
    for o in opaque.opacity_logits.iter_mut() {
        *o = u.range(2.0, 12.0); // many splats reach 0.99 and 0.999 near their centres
    }
    let faint = random_scene(1500, 2, 7, 0.02, 0.2); // opacities ≤ 0.95: no clamp binds
    let v = ImageGrads {
        rgb: Some(
            (0..80 * 60 * 3)
                .map(|i| ((i * 7919) % 13) as f32 / 13.0 - 0.5)
                .collect(),
        ),
        ..Default::default()
    };
    let run = |g: &Gaussians, c: Conventions, k: Kernel, threads: usize| {
        with_threads(threads, || {
            let o = opts(c, k);
            let r = render(g, &cam, &o).unwrap();
            let fwd = render_for_backward(g, &cam, &o).unwrap();
            let (gr, _) = backward(g, &cam, &o, &fwd, &v, &GradGroups::ALL).unwrap();
            let mut out = bits(r.rgb.as_ref().unwrap());
            out.extend(bits(r.final_t.as_ref().unwrap()));
            out.extend(r.n_contrib.unwrap());
            out.extend(bits(&gr.opacity_logits));
            out.extend(bits(&gr.means.concat()));
            out.extend(bits(&gr.sh_rest));
            out
        })
    };
    for c in Conventions::ALL {
        let want = run(&opaque, c, Kernel::Scalar, 1);
        for (k, t) in [(Kernel::Avx2, 2), (Kernel::Auto, 1), (Kernel::Auto, 2)] {
            assert!(run(&opaque, c, k, t) == want, "{c}: {k:?} on {t} threads");
        }
    }
    assert!(
        run(&opaque, Conventions::Inria, Kernel::Auto, 2)
            != run(&opaque, Conventions::Gsplat, Kernel::Auto, 2)
    );
    assert!(
        run(&faint, Conventions::Inria, Kernel::Auto, 2)
            == run(&faint, Conventions::Gsplat, Kernel::Auto, 2)
    );
}

/// An α between the clamps: INRIA's clamp stops the opacity gradient (gsplat's `opac·vis
/// <= MAX_ALPHA` test), gsplat 1.5.3's lets it through.
#[test]
fn opacity_gradient_stops_at_the_profile_s_clamp() {
    let cam = pixel_camera();
    let mut g = Gaussians::new(0).unwrap();
    one(&mut g, [0.0, 0.0, 2.0], 0.1f32.ln(), logit(0.995));
    let v = ImageGrads {
        rgb: Some(vec![1.0, 1.0, 1.0]),
        ..Default::default()
    };
    let grad = |c| {
        let o = opts(c, Kernel::Auto);
        let fwd = render_for_backward(&g, &cam, &o).unwrap();
        backward(&g, &cam, &o, &fwd, &v, &GradGroups::ALL)
            .unwrap()
            .0
            .opacity_logits[0]
    };
    assert_eq!(grad(Conventions::Inria), 0.0);
    assert!(grad(Conventions::Gsplat) != 0.0);
}

#[test]
fn decisions_flag_constructed_near_decisions() {
    let cam = pixel_camera();
    let m = Margins::default();
    let flags = |g: &Gaussians, c| {
        let d = decisions(g, &cam, &opts(c, Kernel::Auto), &m).unwrap();
        (d.pixel_flags[0], d.gaussian_flags.clone())
    };
    // α at the pixel centre (σ = 0) within 1e-7 of 1/255, over and under.
    for rel in [1e-7, -1e-7] {
        let mut g = Gaussians::new(0).unwrap();
        one(
            &mut g,
            [0.0, 0.0, 2.0],
            0.1f32.ln(),
            logit((1.0 + rel) / 255.0),
        );
        let (p, gf) = flags(&g, Conventions::Inria);
        assert!(p & PIXEL_ALPHA_THRESHOLD != 0, "{rel}: {p:#b}");
        assert!(gf[0] & GAUSSIAN_OPACITY_CULL != 0, "{rel}: {gf:?}");
    }
    // α well clear of every threshold: no flag.
    let mut clear = Gaussians::new(0).unwrap();
    one(&mut clear, [0.0, 0.0, 2.0], 0.1f32.ln(), logit(0.5));
    assert_eq!(flags(&clear, Conventions::Inria), (0, vec![0]));
    // o·exp(−σ) within 1e-7 of each profile's clamp.
    for c in Conventions::ALL {
        let mut g = Gaussians::new(0).unwrap();
        one(
            &mut g,
            [0.0, 0.0, 2.0],
            0.1f32.ln(),
            logit(f64::from(c.max_alpha()) * (1.0 + 1e-7)),
        );
        assert!(flags(&g, c).0 & PIXEL_ALPHA_CLAMP != 0, "{c}");
    }
    // Two opaque splats under the 0.99 clamp: T' = 0.01·0.01, at the 1e-4 stop in f32.
    let mut g = Gaussians::new(0).unwrap();
    one(&mut g, [0.0, 0.0, 2.0], 0.1f32.ln(), LOGIT_ONE);
    one(&mut g, [0.0, 0.0, 3.0], 0.1f32.ln(), LOGIT_ONE);
    assert!(flags(&g, Conventions::Inria).0 & PIXEL_TRANSMITTANCE_STOP != 0);
    // Two half-transparent splats an ulp apart in depth: a tie; at the same depth: none
    // (both sides order bit-equal depths by index, SPEC.md §5.3); 1e-4 apart: none.
    for (dz, tie) in [(2.0f32.next_up() - 2.0, true), (0.0, false), (1e-4, false)] {
        let mut g = Gaussians::new(0).unwrap();
        one(&mut g, [0.0, 0.0, 2.0], 0.1f32.ln(), 0.0);
        one(&mut g, [1e-3, 0.0, 2.0 + dz], 0.1f32.ln(), 0.0);
        assert_eq!(
            flags(&g, Conventions::Inria).0 & PIXEL_DEPTH_TIE != 0,
            tie,
            "{dz}"
        );
    }
}

/// A needle 10⁶ times longer than wide lying along the image's x axis is beyond float32:
/// a port's rotation tilts its long axis by ~u radians, which moves the needle's line by
/// that much times the distance along it; on a 2048-pixel-wide image, with a thin width of
/// 0.44 px, the pixels far along the line (not those near the centre) are flagged, and the
/// Gaussian too (its conic's entries lose their relative precision). The same needle
/// turned 45° in the image is not (its entries are good to a few units of rounding); an
/// ordinary Gaussian has no flag at all.
#[test]
fn decisions_flag_needles_beyond_float32() {
    let (w, h) = (2048usize, 64usize);
    let cam = default_camera(w as u32, h as u32);
    let m = Margins::default();
    let o = opts(Conventions::Inria, Kernel::Auto);
    let needle = |turn: f32| {
        let mut g = Gaussians::new(0).unwrap();
        let half = 0.5 * turn;
        g.push(
            [0.0, 0.0, 4.0],
            [1e3f32.ln(), 1e-3f32.ln(), 1e-3f32.ln()],
            [half.cos(), 0.0, 0.0, half.sin()],
            2.0,
            [0.1, 0.2, 0.3],
            &[],
        );
        decisions(&g, &cam, &o, &m).unwrap()
    };
    let flagged = |d: &unseen::raster::decisions::Decisions| -> Vec<(usize, usize)> {
        (0..w * h)
            .filter(|&p| d.pixel_flags[p] & PIXEL_ILL_CONDITIONED != 0)
            .map(|p| (p % w, p / w))
            .collect()
    };
    let flat = needle(0.0);
    assert!(flat.gaussian_flags[0] & GAUSSIAN_ILL_CONDITIONED != 0);
    assert!(
        flat.conic_amplification[0] > 1e4,
        "{}",
        flat.conic_amplification[0]
    );
    assert!(flat.condition[0] > 1e7, "{}", flat.condition[0]);
    let on_line = flagged(&flat);
    assert!(!on_line.is_empty());
    // Only far along the line (the centre projects to (1024, 32)) and on it.
    assert!(
        on_line
            .iter()
            .all(|&(x, y)| x.abs_diff(1024) > 256 && y.abs_diff(32) <= 4),
        "{on_line:?}"
    );
    const { assert!(PIXEL_FORWARD_FLAGS & PIXEL_ILL_CONDITIONED != 0) };
    let turned = needle(std::f32::consts::FRAC_PI_4);
    assert_eq!(turned.gaussian_flags[0] & GAUSSIAN_ILL_CONDITIONED, 0);
    assert!(
        turned.conic_amplification[0] < 10.0,
        "{}",
        turned.conic_amplification[0]
    );
    assert!(
        turned.condition[0] > 1e7,
        "ill-conditioned for a·c − b², resolved here"
    );
    assert!(flagged(&turned).is_empty());
    let mut plain = Gaussians::new(0).unwrap();
    one(&mut plain, [0.0, 0.0, 4.0], 0.1f32.ln(), 2.0);
    let d = decisions(&plain, &cam, &o, &m).unwrap();
    assert_eq!(d.gaussian_flags, vec![0]);
    assert!(flagged(&d).is_empty());
    assert!(
        d.conic_amplification[0] < 10.0,
        "{}",
        d.conic_amplification[0]
    );
}

/// The point of the diagnostics: a "port" that differs from the oracle by float noise (here
/// the scene's parameters moved by an ulp or two, as another summation order or FMA moves
/// its intermediates) renders within the f32-vs-f32 tolerance plus the per-pixel α-error
/// bound everywhere except at flagged pixels, which stay a small share of the image.
#[test]
fn decisions_cover_what_float_noise_changes() {
    let cam = default_camera(96, 72);
    let (atol, rtol) = (1e-5f32, 2.6e-6f32); // unseen.testing's COLOR_ATOL / _RTOL
    let mut flagged_total = 0usize;
    for seed in 0..6 {
        let mut g = random_scene(4000, 3, 100 + seed, 0.01, 0.15);
        let mut u = Uniform::new(200 + seed);
        for o in g.opacity_logits.iter_mut() {
            *o = u.range(-4.0, 9.0);
        }
        let o = opts(Conventions::Gsplat, Kernel::Auto);
        let d = decisions(&g, &cam, &o, &Margins::default()).unwrap();
        let want = render(&g, &cam, &o).unwrap();
        let mut port = g.clone();
        let mut ulp = |x: &mut f32| *x *= 1.0 + 1.2e-7 * u.range(-1.0, 1.0);
        for v in port.means.iter_mut().chain(port.log_scales.iter_mut()) {
            v.iter_mut().for_each(&mut ulp);
        }
        for q in port.quats.iter_mut() {
            q.iter_mut().for_each(&mut ulp);
        }
        let got = render(&port, &cam, &o).unwrap();
        let (w, g_rgb) = (want.rgb.unwrap(), got.rgb.unwrap());
        let flagged = d
            .pixel_flags
            .iter()
            .filter(|&&f| f & PIXEL_FORWARD_FLAGS != 0)
            .count();
        flagged_total += flagged;
        assert!(
            flagged * 100 <= w.len() / 3,
            "seed {seed}: {flagged} flagged pixels"
        );
        for (i, (a, b)) in w.chunks_exact(3).zip(g_rgb.chunks_exact(3)).enumerate() {
            if d.pixel_flags[i] & PIXEL_FORWARD_FLAGS != 0 {
                continue;
            }
            for k in 0..3 {
                let tol = atol + rtol * a[k].abs() + d.rgb_error[i];
                assert!(
                    (a[k] - b[k]).abs() <= tol,
                    "seed {seed} pixel {i} channel {k}: {} vs {} (tolerance {tol:.3e}, flags {:#b})",
                    a[k],
                    b[k],
                    d.pixel_flags[i]
                );
            }
        }
    }
    assert!(flagged_total > 0, "the noise should meet some decision");
}

#[test]
fn decisions_are_the_same_bits_on_any_thread_count() {
    let cam = default_camera(80, 60);
    let g = random_scene(3000, 3, 11, 0.01, 0.2);
    let o = opts(Conventions::Inria, Kernel::Auto);
    let run = |t| with_threads(t, || decisions(&g, &cam, &o, &Margins::default()).unwrap());
    let (a, b) = (run(1), run(2));
    assert_eq!(a.pixel_flags, b.pixel_flags);
    assert_eq!(bits(&a.alpha_margin), bits(&b.alpha_margin));
    assert_eq!(bits(&a.transmittance_margin), bits(&b.transmittance_margin));
    assert_eq!(bits(&a.rgb_error), bits(&b.rgb_error));
    assert_eq!(a.gaussian_flags, b.gaussian_flags);
}

#[test]
fn decisions_refuse_bad_margins_and_cutoffs() {
    let cam = default_camera(16, 16);
    let g = random_scene(10, 0, 1, 0.01, 0.2);
    let o = opts(Conventions::Inria, Kernel::Auto);
    let bad = Margins {
        sigma: f32::NAN,
        ..Margins::default()
    };
    assert!(
        decisions(&g, &cam, &o, &bad)
            .unwrap_err()
            .to_string()
            .contains("sigma")
    );
    let cut = RenderOptions {
        cutoffs: Cutoffs {
            inv_alpha_threshold: 1000.0,
            ..Cutoffs::GSPLAT
        },
        ..o
    };
    assert!(decisions(&g, &cam, &cut, &Margins::default()).is_err());
}

/// `unseen oracle --conventions gsplat` renders with gsplat's clamp, and every dump's
/// manifest names its profile.
#[test]
fn oracle_dump_records_its_profile() {
    let demo = reference("demo");
    let out = TempDir::path_only("oracle-profile");
    let dump = |name: &str, extra: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_unseen"))
            .args(["oracle", "forward", "--scene"])
            .arg(demo.join("scene.ply"))
            .arg("--cameras")
            .arg(demo.join("cameras.json"))
            .args(extra)
            .arg("--out")
            .arg(out.join(name))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let m: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join(name).join("manifest.json")).unwrap())
                .unwrap();
        m
    };
    let inria = dump("inria", &[]);
    let gsplat = dump("gsplat", &["--conventions", "gsplat"]);
    assert_eq!(inria["conventions"], "inria");
    assert_eq!(inria["inputs"]["conventions"], "inria");
    assert_eq!(gsplat["conventions"], "gsplat");
    assert_eq!(gsplat["inputs"]["conventions"], "gsplat");
    let o = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .args([
            "oracle",
            "forward",
            "--conventions",
            "cuda",
            "--scene",
            "x",
            "--cameras",
            "y",
            "--out",
        ])
        .arg(out.join("bad"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("inria, gsplat"));
}

/// A training run follows its configuration's profile: the file records a non-default
/// one (a default run's config keeps its bytes), and training under gsplat's clamp gives
/// another scene where opacities pass 0.99.
#[test]
fn training_runs_under_their_configured_profile() {
    use unseen::train::trainer::{TrainConfig, TrainOverrides, Trainer};
    let default = serde_json::to_value(TrainConfig::default()).unwrap();
    assert!(default.get("conventions").is_none());
    let gsplat = TrainConfig::from_file_and_flags(
        None,
        &TrainOverrides {
            conventions: Some(Conventions::Gsplat),
            ..Default::default()
        },
    )
    .unwrap();
    let text = serde_json::to_string(&gsplat).unwrap();
    assert!(text.contains(r#""conventions":"gsplat""#), "{text}");
    assert_eq!(serde_json::from_str::<TrainConfig>(&text).unwrap(), gsplat);
    let d = unseen::dataset::load(
        &reference("scenes/lounge"),
        &unseen::dataset::LoadOptions {
            resolution: 4,
            ..Default::default()
        },
    )
    .unwrap();
    // The point-cloud initialisation with opacities of 0.9975: the clamps bind at once.
    let cfg = crate::support::short_train_config(20);
    let mut init = Trainer::new(&d, cfg.clone()).unwrap().gaussians;
    init.opacity_logits.iter_mut().for_each(|o| *o = 6.0);
    let run = |c| {
        let cfg = TrainConfig {
            conventions: c,
            ..cfg.clone()
        };
        let mut t = Trainer::from_gaussians(&d, cfg, init.clone(), 0).unwrap();
        assert_eq!(t.render_options(false).conventions, c);
        while t.iteration < 20 {
            t.step().unwrap();
        }
        unseen::gaussian::ply::ply_bytes(&t.gaussians).unwrap()
    };
    assert!(run(Conventions::Inria) != run(Conventions::Gsplat));
}

/// `unseen train --conventions gsplat` records the profile in the run's config (its key),
/// `--resume` refuses to change it, and the pipeline, `unseen qa-mask` and `unseen
/// mask-audit` refuse such a run (they render `inria`).
#[test]
fn cli_train_records_its_profile_and_the_pipeline_refuses_another() {
    let scene = reference("scenes/lounge");
    let dir = TempDir::new("train-profile");
    let run = dir.path().join("run");
    let o = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .arg("train")
        .arg(&scene)
        .arg("--out")
        .arg(&run)
        .args([
            "--iterations",
            "5",
            "--resolution",
            "8",
            "--conventions",
            "gsplat",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cfg = unseen::train::run::read_config(&run).unwrap();
    assert_eq!(cfg.conventions, Conventions::Gsplat);
    let o = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .arg("train")
        .arg(&scene)
        .arg("--out")
        .arg(&run)
        .args(["--resume", "--conventions", "inria"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = unseen::pipeline::load_inputs(&run, &scene.join("candidates.json"), None, None)
        .err()
        .expect("a gsplat run is refused")
        .to_string();
    assert!(
        err.contains("conventions 'gsplat'") && err.contains("config.json"),
        "{err}"
    );
}
