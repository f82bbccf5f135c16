//! QA-Mask: what the fine-tune may change, determinism, holes, and a short-preset check of
//! the paper's claim (the mask finds badly reconstructed pixels of the unseen half).

use crate::support::{reference, short_train_config, with_threads};
use unseen::camera::Camera;
use unseen::dataset::{self, Dataset, LoadOptions, Split};
use unseen::gaussian::{Gaussians, Param};
use unseen::math::sh::num_coeffs;
use unseen::qamask::{QaMaskConfig, audit, fine_tune, mask_scene, render_qa_mask};
use unseen::raster::{RenderOptions, render};
use unseen::train::trainer::Trainer;

/// The lounge train half at 80×60 and a 700-iteration model of it, made once for all tests
/// of this file (training is deterministic, so sharing changes nothing).
fn fixture() -> &'static (Dataset, Gaussians) {
    static F: std::sync::OnceLock<(Dataset, Gaussians)> = std::sync::OnceLock::new();
    F.get_or_init(|| {
        let d = lounge_half();
        let g = trained(&d);
        (d, g)
    })
}

fn lounge_half() -> Dataset {
    dataset::load(
        &reference("scenes/lounge"),
        &LoadOptions {
            resolution: 2,
            ..LoadOptions::default()
        },
    )
    .unwrap()
}

fn trained(d: &Dataset) -> Gaussians {
    let mut t = Trainer::new(d, short_train_config(700)).unwrap();
    while t.iteration < 700 {
        t.step().unwrap();
    }
    t.gaussians
}

fn cams(d: &Dataset, s: Split) -> Vec<Camera> {
    d.split(s)
        .iter()
        .map(|&i| d.views[i].camera.clone())
        .collect()
}

/// A short preset: few iterations, so a learning rate 20× INRIA's `f_rest` rate.
fn short_cfg(iterations: u32, degree: u32) -> QaMaskConfig {
    QaMaskConfig {
        sh_degree: degree,
        iterations,
        lr_sh_rest: 2.5e-3,
        ..QaMaskConfig::default()
    }
}

/// Everything but SH rest is bit-identical after the fine-tune; the masks are the same bits
/// on 1 and 2 threads; a camera that sees no Gaussian renders the base colour exactly.
#[test]
#[ignore = "slow tier (~20 s): cargo test -- --include-ignored"]
fn qa_mask_fine_tune_changes_only_sh_rest_and_is_deterministic() {
    let (d, g) = fixture();
    let cfg = short_cfg(300, 3);
    let start = mask_scene(g, &cfg).unwrap();
    let train = cams(d, Split::Train);
    let run = |threads| {
        with_threads(threads, || {
            let mut s = start.clone();
            fine_tune(&mut s, &train, &cfg, &mut |_| {}).unwrap();
            let m = render_qa_mask(&s, &d.views[d.heldout[0]].camera, &cfg).unwrap();
            (s, m)
        })
    };
    let (a, ma) = run(1);
    let (b, mb) = run(2);
    assert_eq!(a, b, "fine-tuned scene differs between 1 and 2 threads");
    assert_eq!(
        ma.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        mb.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(
        bits(a.means.as_flattened()),
        bits(start.means.as_flattened())
    );
    assert_eq!(
        bits(a.log_scales.as_flattened()),
        bits(start.log_scales.as_flattened())
    );
    assert_eq!(
        bits(a.quats.as_flattened()),
        bits(start.quats.as_flattened())
    );
    assert_eq!(bits(&a.opacity_logits), bits(&start.opacity_logits));
    assert_eq!(
        bits(a.sh_dc.as_flattened()),
        bits(start.sh_dc.as_flattened())
    );
    assert_ne!(a.sh_rest, start.sh_rest, "SH rest trained");
    // A hole: looking out of the room from far away sees nothing.
    let away = Camera::look_at(
        "away",
        40,
        30,
        1.0,
        glam::DVec3::new(0.0, 1.0, 50.0),
        glam::DVec3::new(0.0, 1.0, 100.0),
        glam::DVec3::NEG_Y,
    )
    .unwrap();
    let r = render(
        &a,
        &away,
        &RenderOptions {
            background: cfg.base_color,
            ..RenderOptions::default()
        },
    )
    .unwrap();
    assert!(
        r.rgb.unwrap().chunks(3).all(|c| c == cfg.base_color),
        "hole shows the base colour"
    );
    assert!(
        render_qa_mask(&a, &away, &cfg)
            .unwrap()
            .iter()
            .all(|&m| m == 1.0)
    );
}

/// The fine-tune of [`fine_tune`] written out densely: every view's record replayed with
/// [`FrozenBlend::backward_sh`] and a dense [`Adam::step`] over every Gaussian (no skip).
fn dense_fine_tune(scene: &mut Gaussians, views: &[Camera], cfg: &QaMaskConfig) {
    use unseen::raster::Outputs;
    use unseen::raster::backward::GradGroups;
    use unseen::raster::backward::frozen::FrozenBlend;
    use unseen::rng::Uniform;
    use unseen::rng::stage_seed;
    use unseen::train::adam::Adam;
    use unseen::train::loss::{LossInput, image_loss};
    let opts = RenderOptions {
        background: cfg.target_color,
        sh_degree: Some(cfg.sh_degree),
        outputs: Outputs::RGB,
        ..RenderOptions::default()
    };
    let records: Vec<FrozenBlend> = views
        .iter()
        .map(|c| FrozenBlend::record(scene, c, &opts).unwrap())
        .collect();
    let mut adam = Adam::new(cfg.adam, scene).unwrap();
    let mut rng = Uniform::new(stage_seed(cfg.seed, "qa-mask"));
    let mut stack: Vec<usize> = Vec::new();
    for _ in 0..cfg.iterations {
        if stack.is_empty() {
            stack = (0..views.len()).collect();
        }
        let vi = stack.remove(rng.below(stack.len() as u32) as usize);
        let (w, h) = (views[vi].width as usize, views[vi].height as usize);
        let rgb = records[vi].render_rgb(scene).unwrap();
        let target: Vec<f32> = (0..w * h).flat_map(|_| cfg.target_color).collect();
        let out = image_loss(
            &LossInput {
                width: w,
                height: h,
                rgb: &rgb,
                target_rgb: &target,
                depth: None,
                target_depth: None,
                mask: None,
            },
            &cfg.loss,
        )
        .unwrap();
        let g = records[vi]
            .backward_sh(scene, &out.grad_rgb, &GradGroups::SH_REST)
            .unwrap();
        adam.step(scene, Param::ShRest, &g.sh_rest, cfg.lr_sh_rest);
    }
}

/// The fine-tune skips the Gaussians no training view has a splat of (they get a zero
/// gradient at every step, so Adam leaves them as they are): exact. The trained scene plus
/// 700 copies culled everywhere (opacity below the alpha threshold; whole Adam chunks of
/// them, and a few interleaved) fine-tunes to the bits of the dense fine-tune (no skip) of
/// the same scene, and to those of the trained scene alone; the copies keep their zero SH
/// rest.
#[test]
fn qa_mask_fine_tune_skips_unseen_gaussians_exactly() {
    let (d, g) = fixture();
    let cfg = short_cfg(60, 3);
    let train = cams(d, Split::Train);
    let n = g.len();
    let mut extra = g.select(&(0..700).collect::<Vec<_>>());
    extra.opacity_logits.fill(-100.0);
    // Interleaved: the first 7 copies go between the trained Gaussians.
    let mut order: Vec<usize> = (0..n).collect();
    for k in 0..7 {
        order.insert(k * 100 + 50, n + k);
    }
    order.extend(n + 7..n + 700);
    let mut both = g.clone();
    both.append(&extra);
    let both = both.select(&order);
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let tune = |scene: &Gaussians| {
        let mut s = mask_scene(scene, &cfg).unwrap();
        fine_tune(&mut s, &train, &cfg, &mut |_| {}).unwrap();
        s
    };
    let (alone, with_extra) = (tune(g), tune(&both));
    let mut dense = mask_scene(&both, &cfg).unwrap();
    dense_fine_tune(&mut dense, &train, &cfg);
    assert!(
        bits(&dense.sh_rest) == bits(&with_extra.sh_rest),
        "the skipping fine-tune differs from the dense one"
    );
    let k = (num_coeffs(3) - 1) * 3;
    let mut kept = Vec::new();
    for (pos, &i) in order.iter().enumerate() {
        let rest = &with_extra.sh_rest[pos * k..(pos + 1) * k];
        if i < n {
            kept.extend_from_slice(rest);
        } else {
            assert!(
                rest.iter().all(|v| v.to_bits() == 0),
                "culled copy {i} changed"
            );
        }
    }
    assert!(
        bits(&kept) == bits(&alone.sh_rest),
        "the skip changed the fine-tune"
    );
}

/// Another distinguishable pair (green/black) gives the same mask up to the fine-tune's
/// own rounding: the loss, the gradients and the updates are those of red/black with the
/// channels permuted, so the masks agree to f32 rounding.
#[test]
#[ignore = "slow tier (~15 s): cargo test -- --include-ignored"]
fn qa_mask_colour_pair_does_not_matter() {
    let (d, g) = fixture();
    let train = cams(d, Split::Train);
    let red = short_cfg(200, 3);
    let green = QaMaskConfig {
        base_color: [0.0, 1.0, 0.0],
        ..red.clone()
    };
    let mut masks = Vec::new();
    for cfg in [&red, &green] {
        let mut s = mask_scene(g, cfg).unwrap();
        fine_tune(&mut s, &train, cfg, &mut |_| {}).unwrap();
        masks.push(render_qa_mask(&s, &d.views[d.heldout[3]].camera, cfg).unwrap());
    }
    let worst = masks[0]
        .iter()
        .zip(&masks[1])
        .map(|(a, b)| (a - b).abs())
        .fold(0f32, f32::max);
    assert!(
        worst < 1e-5,
        "red/black and green/black masks differ by {worst}"
    );
}

/// The claim on a short preset: on the held-out half, QA-Mask ranks badly reconstructed
/// pixels above well reconstructed ones (AUROC clearly above 0.5), and the in-distribution
/// test views get lower mask values than the held-out views. Measured (session 3): AUROC
/// 0.653, Spearman 0.190, mask mean 0.152 (test) vs 0.980 (heldout); the baselines reach
/// AUROC 0.975 (opacity) and 0.944 (scale) here, because 92 % of held-out pixels are bad
/// and most of them are holes. Full-scale figures: `reference_data/audit/`.
#[test]
#[ignore = "slow tier (~25 s): cargo test -- --include-ignored"]
fn qa_mask_detects_badly_reconstructed_pixels() {
    let (d, g) = fixture();
    let report = audit(g, d, &[short_cfg(1500, 3)], &mut |_, _| {}).unwrap();
    eprintln!("{}", report.table());
    let qa = &report.rows[0];
    assert_eq!(qa.mask, "qa-3");
    assert!(qa.auroc > 0.6, "QA-Mask AUROC {:.3}", qa.auroc);
    assert!(qa.spearman > 0.15, "QA-Mask Spearman {:.3}", qa.spearman);
    assert!(
        qa.mean_test < 0.5 * qa.mean_heldout,
        "mask mean: test {:.3}, heldout {:.3}",
        qa.mean_test,
        qa.mean_heldout
    );
    let names: Vec<&str> = report.rows.iter().map(|r| r.mask.as_str()).collect();
    assert_eq!(names, ["qa-3", "opacity", "scale"]);
    assert!(report.bad_fraction > 0.0 && report.bad_fraction < 1.0);
}

/// The scene a fine-tune hands its progress callback at iteration k is the k-iteration
/// fine-tune's, bit for bit (nothing in a step depends on the budget): the accuracy bench
/// reads shorter budgets off one long run.
#[test]
#[ignore = "slow tier (~15 s): cargo test -- --include-ignored"]
fn qa_mask_fine_tune_checkpoints_are_shorter_fine_tunes() {
    let (d, g) = fixture();
    let train = cams(d, Split::Train);
    let long = short_cfg(250, 3);
    let start = mask_scene(g, &long).unwrap();
    let mut seen = Vec::new();
    let mut s = start.clone();
    fine_tune(&mut s, &train, &long, &mut |p| {
        if p.iteration % 100 == 0 || p.iteration == 1 {
            seen.push((p.iteration, p.scene.clone()));
        }
    })
    .unwrap();
    assert_eq!(seen.len(), 3);
    for (k, at_k) in &seen {
        let mut short = start.clone();
        fine_tune(&mut short, &train, &short_cfg(*k, 3), &mut |_| {}).unwrap();
        assert!(
            short == *at_k,
            "checkpoint {k} differs from a {k}-iteration fine-tune"
        );
        assert!(short != start, "iteration {k} changed nothing");
    }
}
