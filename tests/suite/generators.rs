//! The pipeline under the ground-truth generators (SPEC.md §20.5–§20.6): depth supervision,
//! the fine-tune switches, relative truth depth and its alignments, hallucinating truth, and
//! the perfect generator's guard on the training half.

use crate::support::TempDir;
use crate::support::quiet;
use crate::support::tiny_run::{Tiny, TinyRun, tiny_config};
use std::path::Path;
use unseen::pipeline::{self, PipelineConfig, SlotNames};

/// Depth supervision is the paper's: the generated views' depth priors, not the dataset's
/// depth of the original views (which the lounge has, and which the paper's method never
/// sees). The labelled switch `original_view_depth` adds them back, and a run with it
/// differs from one without (so the trainer does consume what the list carries).
#[test]
fn depth_supervision_reaches_the_generated_views_only_unless_the_non_paper_switch() {
    use unseen::pipeline::recon::original_views;
    let t = TempDir::new("pipeline-original-depth");
    let Tiny { inp, .. } = TinyRun::new().build(&t);
    assert!(
        inp.data
            .train
            .iter()
            .all(|&i| inp.data.views[i].depth.is_some()),
        "the test needs a dataset with depth on its training views"
    );
    let paper = PipelineConfig {
        interpolation: false,
        ..tiny_config()
    };
    assert!(paper.depth_supervision && !paper.original_view_depth);
    let switched = PipelineConfig {
        original_view_depth: true,
        ..paper.clone()
    };
    let no_depth = PipelineConfig {
        depth_supervision: false,
        ..switched.clone()
    };
    assert!(
        original_views(&paper, &inp)
            .iter()
            .all(|v| v.depth.is_none())
    );
    assert!(
        original_views(&switched, &inp)
            .iter()
            .all(|v| v.depth.is_some())
    );
    assert!(
        original_views(&no_depth, &inp)
            .iter()
            .all(|v| v.depth.is_none())
    );
    let scene = |cfg: &PipelineConfig, name: &str| {
        let out = t.path().join(name);
        pipeline::run(cfg, &inp, &out, false, &quiet).unwrap();
        let sup: serde_json::Value = serde_json::from_slice(
            &std::fs::read(out.join("stage1/recon/supervision.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(
            sup["original_views_depth"],
            cfg.depth_supervision && cfg.original_view_depth
        );
        std::fs::read(out.join("stage1/recon/scene.ply")).unwrap()
    };
    assert_ne!(scene(&paper, "paper"), scene(&switched, "switched"));
}

/// The fine-tune switches the paper leaves open (issue #72; SPEC.md §20.5) reach the
/// reconstructions: a continued schedule starts stage 1 at the original scene's iterations
/// and stage 2 after stage 1's (`supervision.json`), a share of iterations on the original
/// views changes the scene, the default writes no offset, and the recipe's control trains
/// on the original views alone.
#[test]
fn the_fine_tune_switches_reach_the_reconstructions() {
    let t = TempDir::new("pipeline-fine-tune-switches");
    let Tiny { inp, .. } = TinyRun::new().build(&t);
    let paper = PipelineConfig {
        interpolation: false,
        ..tiny_config()
    };
    let run = |cfg: &PipelineConfig, name: &str| {
        let out = t.path().join(name);
        pipeline::run(cfg, &inp, &out, false, &quiet).unwrap();
        let sup = |stage: &str| -> serde_json::Value {
            serde_json::from_slice(
                &std::fs::read(out.join(format!("{stage}/recon/supervision.json"))).unwrap(),
            )
            .unwrap()
        };
        (
            [sup("stage1"), sup("stage2")].map(|s| s.get("position_offset").cloned()),
            std::fs::read(out.join("stage1/recon/scene.ply")).unwrap(),
        )
    };
    let (offsets, base) = run(&paper, "paper");
    assert_eq!(offsets, [None, None]);
    let continued = PipelineConfig {
        fine_tune_rates: unseen::pipeline::FineTuneRates::Continue,
        ..paper.clone()
    };
    let (offsets, scene) = run(&continued, "continued");
    assert!(inp.scene_iterations > 0);
    assert_eq!(
        offsets,
        [
            Some(serde_json::json!(inp.scene_iterations)),
            Some(serde_json::json!(
                inp.scene_iterations + paper.stage1.iterations
            ))
        ]
    );
    assert_ne!(scene, base);
    let shared = PipelineConfig {
        original_share: Some(0.5),
        ..paper.clone()
    };
    assert_ne!(run(&shared, "shared").1, base);
    // The cycle's k-th reconstruction continues after the k before it, whose iterations
    // are the total split with the remainder on the first views.
    let cycle = PipelineConfig {
        paradigm: unseen::pipeline::Paradigm::Cycle,
        ..continued.clone()
    };
    let out = t.path().join("cycle");
    pipeline::run(&cycle, &inp, &out, false, &quiet).unwrap();
    let trajectory = (0..)
        .take_while(|k| out.join(format!("cycle/{k}")).is_dir())
        .count();
    assert!(trajectory >= 2, "{trajectory} cycle steps");
    let split = unseen::pipeline::cycle::split_iterations(&cycle, trajectory);
    for k in 0..trajectory {
        let sup: serde_json::Value = serde_json::from_slice(
            &std::fs::read(out.join(format!("cycle/{k}/supervision.json"))).unwrap(),
        )
        .unwrap();
        let before: u32 = split[..k].iter().sum();
        assert_eq!(
            sup["position_offset"],
            serde_json::json!(inp.scene_iterations + before),
            "cycle step {k}"
        );
    }
    // Densification limited to what the pipeline added: the original scene's Gaussians are
    // never pruned (densification on in stage 1 here; the tiny preset has it off).
    let densifying = PipelineConfig {
        stage1: unseen::pipeline::ReconConfig {
            densify: Some(unseen::train::densify::DensifyConfig {
                from_iter: 10,
                interval: 10,
                until_iter: 50,
                opacity_reset_interval: 0,
                ..Default::default()
            }),
            ..paper.stage1
        },
        ..paper.clone()
    };
    let limited = PipelineConfig {
        densify_scope: unseen::pipeline::DensifyScope::Added,
        ..densifying.clone()
    };
    let (_, all_scene) = run(&densifying, "densify-all");
    let (_, added_scene) = run(&limited, "densify-added");
    assert!(all_scene != added_scene, "the scope changed nothing");
    // The lineage (SPEC.md §20.5, §20.7): composed here from the reconstructions' files, it
    // gives the counts each stage's metrics record; under the limited scope every original
    // Gaussian keeps exactly one descendant, at its own index.
    let n = inp.scene.len();
    for (name, limited) in [("densify-all", false), ("densify-added", true)] {
        let dir = t.path().join(name);
        let mut ancestors: Vec<u32> = (0..n as u32).collect();
        for stage in ["stage1", "stage2"] {
            let (_, lineage) =
                unseen::io::npy::read_npy::<u32>(&dir.join(format!("{stage}/recon/lineage.npy")))
                    .unwrap();
            if limited && stage == "stage1" {
                assert_eq!(&lineage[..n], &(0..n as u32).collect::<Vec<_>>()[..]);
            }
            ancestors = lineage
                .iter()
                .map(|&i| ancestors.get(i as usize).copied().unwrap_or(u32::MAX))
                .collect();
            let row: serde_json::Value = serde_json::from_slice(
                &std::fs::read(dir.join(format!("eval/{stage}/metrics.json"))).unwrap(),
            )
            .unwrap();
            let l = &row["lineage"];
            let count = |k: &str| {
                l[k].as_u64()
                    .unwrap_or_else(|| panic!("{name}/{stage}: {k}"))
            };
            let from = ancestors.iter().filter(|&&a| a != u32::MAX).count() as u64;
            let mut per = vec![0u32; n];
            for &a in ancestors.iter().filter(|&&a| a != u32::MAX) {
                per[a as usize] += 1;
            }
            let with = |f: &dyn Fn(u32) -> bool| per.iter().filter(|&&k| f(k)).count() as u64;
            assert_eq!(
                [count("from_originals"), count("added")],
                [from, ancestors.len() as u64 - from],
                "{name}/{stage}"
            );
            assert_eq!(
                [
                    count("originals_lost"),
                    count("originals_one"),
                    count("originals_more")
                ],
                [with(&|k| k == 0), with(&|k| k == 1), with(&|k| k > 1)],
                "{name}/{stage}"
            );
            assert_eq!(row["gaussians"].as_u64(), Some(ancestors.len() as u64));
            assert!(l["psnr_train_half_originals"].as_f64().unwrap().is_finite());
            if limited {
                assert_eq!(count("originals_one"), n as u64, "{name}/{stage}");
            } else if stage == "stage1" {
                assert!(
                    count("originals_lost") + count("originals_more") > 0,
                    "{name}: densification touched no original Gaussian: {l}"
                );
            }
        }
        let original: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("eval/original/metrics.json")).unwrap())
                .unwrap();
        assert!(
            original.get("lineage").is_none(),
            "the original scene has none"
        );
    }
    let (g, _) =
        unseen::gaussian::ply::read_ply(&t.path().join("densify-added/stage1/recon/scene.ply"))
            .unwrap();
    assert!(
        g.len() >= inp.scene.len(),
        "{} < {}",
        g.len(),
        inp.scene.len()
    );
    // The recipe's control: the generated views made and dropped.
    let control = PipelineConfig {
        generated_supervision: false,
        ..paper.clone()
    };
    assert_ne!(run(&control, "control").1, base);
    let sup: serde_json::Value = serde_json::from_slice(
        &std::fs::read(t.path().join("control/stage2/recon/supervision.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(sup["generated"], serde_json::json!([]));
    assert_eq!(sup["generated_supervision"], serde_json::json!(false));
}

/// The relative-depth mode of the ground-truth generator (SPEC.md §20.6) gives alignment
/// real work — Eq. 2 (detection), Eq. 5 (stage-1 clips) and the stage-2 fit must undo a
/// seeded affine map of disparity — and the pipeline still extrapolates: the stage-1
/// alignments fitted scales far from 1, the extrapolated-pixel gain stays above
/// `RELATIVE_GAIN_DB` and within `RELATIVE_COST_DB` of the metric-depth run's (measured at
/// 40×30, interpolation off: 7.01 dB against 6.97 dB — the maps are undone up to their
/// flicker and distortion, which cost nothing measurable here).
#[test]
fn relative_truth_depth_runs_the_alignments_and_still_extrapolates() {
    const RELATIVE_GAIN_DB: f64 = 5.0;
    const RELATIVE_COST_DB: f64 = 1.0;
    let t = TempDir::new("pipeline-relative-depth");
    let Tiny { inp, cfg, .. } = TinyRun::new()
        .config(|c| {
            c.interpolation = false;
            c.inconsistency = unseen::pipeline::Inconsistency::LOW;
            c.truth_depth = unseen::pipeline::TruthDepth::Relative;
        })
        .build(&t);
    let out = t.path().join("out");
    let o = pipeline::run(&cfg, &inp, &out, false, &quiet).unwrap();
    let mut scales = Vec::new();
    for e in std::fs::read_dir(out.join("stage1")).unwrap() {
        let p = e.unwrap().path().join("stage1.json");
        if let Ok(b) = std::fs::read(&p) {
            let v: serde_json::Value = serde_json::from_slice(&b).unwrap();
            if let Some(s) = v["alignment"]["alignment"]["scale"].as_f64() {
                scales.push(s);
            }
        }
    }
    assert!(!scales.is_empty(), "no stage-1 clip was aligned");
    let far = scales.iter().filter(|s| (*s - 1.0).abs() > 0.2).count();
    assert!(2 * far > scales.len(), "scales {scales:?}");
    let m = o.metrics.as_ref().unwrap();
    let (orig, last) = (m.row("original").unwrap(), m.row("stage2").unwrap());
    let gain = last.psnr_extrapolated - orig.psnr_extrapolated;
    let metric = PipelineConfig {
        truth_depth: unseen::pipeline::TruthDepth::Metric,
        ..cfg.clone()
    };
    let om = pipeline::run(&metric, &inp, &t.path().join("metric"), false, &quiet).unwrap();
    let mm = om.metrics.as_ref().unwrap();
    let metric_gain = mm.row("stage2").unwrap().psnr_extrapolated - orig.psnr_extrapolated;
    eprintln!(
        "relative depth: extrapolated gain {gain:.2} dB (metric {metric_gain:.2} dB), stage-1 scales {scales:?}"
    );
    assert!(gain >= RELATIVE_GAIN_DB, "gain {gain} dB");
    assert!(
        gain >= metric_gain - RELATIVE_COST_DB,
        "{gain} vs {metric_gain} dB"
    );
}

/// PSNR (dB) between two RGB images over `pixels`.
fn psnr_over(a: &[f32], b: &[f32], pixels: &[bool]) -> f64 {
    let (mut se, mut n) = (0f64, 0usize);
    for (p, _) in pixels.iter().enumerate().filter(|(_, m)| **m) {
        for c in 0..3 {
            let d = (a[p * 3 + c] - b[p * 3 + c]) as f64;
            se += d * d;
        }
        n += 3;
    }
    -10.0 * (se / n as f64).log10()
}

/// The hallucinating mode of the ground-truth generator (SPEC.md §20.6): content no
/// training view saw differs between two calls (two independent generations conflict:
/// PSNR between them on the unseen pixels below `CONFLICT_DB`, measured 8.7–9.1 dB at high
/// on the 12 lounge candidates at 40×30, 49–87 % of whose pixels no training view saw),
/// is the same for the same call, and the pixels a training view saw are the truth's,
/// bit for bit the non-hallucinating generator's. A candidate with unseen pixels is used
/// (its unseen share is asserted, so the test keeps its teeth).
#[test]
fn hallucinating_truth_conflicts_between_calls_on_unseen_content_only() {
    use unseen::pipeline::generators::{Generators, GroundTruth};
    use unseen::pipeline::{Hallucination, Inconsistency, candidate_truth};
    const CONFLICT_DB: f64 = 15.0;
    let t = TempDir::new("pipeline-hallucination");
    let Tiny { inp, cfg, .. } = TinyRun::new()
        .config(|c| c.hallucination = Hallucination::High)
        .build(&t);
    let seen = pipeline::training_truth(&inp, &cfg).unwrap();
    let store = |level| {
        GroundTruth::new(candidate_truth(&inp).unwrap(), Inconsistency::NONE, 3)
            .hallucinating(level, seen.clone())
    };
    let gens = |level| Generators::new(&SlotNames::truth(), Some(store(level)), 3).unwrap();
    let (high, plain) = (gens(Hallucination::High), gens(Hallucination::None));
    let mut checked = 0;
    for cam in &inp.candidates {
        let truth = high.truth.as_ref().unwrap().get(&cam.name).unwrap().clone();
        let unseen = high.truth.as_ref().unwrap().unseen(cam, &truth.depth);
        let share = unseen.iter().filter(|&&u| u).count() as f64 / unseen.len() as f64;
        if share < 0.1 {
            continue;
        }
        let all = vec![true; unseen.len()];
        let a = high.inpaint(cam, &truth.image, &all, "a").unwrap();
        let a2 = high.inpaint(cam, &truth.image, &all, "a").unwrap();
        let b = high.inpaint(cam, &truth.image, &all, "b").unwrap();
        let p = plain.inpaint(cam, &truth.image, &all, "a").unwrap();
        assert_eq!(
            a.data, a2.data,
            "one call's content is a function of its key"
        );
        for (px, &u) in unseen.iter().enumerate() {
            if !u {
                assert_eq!(a.data[px * 3..px * 3 + 3], p.data[px * 3..px * 3 + 3]);
            }
        }
        let conflict = psnr_over(&a.data, &b.data, &unseen);
        eprintln!(
            "{}: {:.0} % unseen, two calls differ there by {conflict:.1} dB",
            cam.name,
            100.0 * share
        );
        assert!(conflict < CONFLICT_DB, "{}: {conflict} dB", cam.name);
        checked += 1;
    }
    assert!(
        checked >= 3,
        "only {checked} candidates with unseen content"
    );
}

/// The whole pipeline runs with the generator the audit adds for the paper's mechanisms
/// (truth-low with hallucination and relative depth, SPEC.md §20.6), interpolation and its
/// fixer included; its report shows two conflicting generations (`views/conflict.json`,
/// below the conflict bound of the test above); and the hallucinated content costs extrapolated-pixel PSNR against the
/// same run without it (wrong content is wrong: measured gain 8.03 dB → 4.46 dB at 40×30).
#[test]
fn hallucinating_relative_truth_runs_end_to_end_and_costs_unseen_fidelity() {
    use unseen::pipeline::{Hallucination, Inconsistency, TruthDepth};
    let t = TempDir::new("pipeline-hallucinating-run");
    let Tiny { inp, .. } = TinyRun::new().build(&t);
    let gain = |h: Hallucination, name: &str| {
        let cfg = PipelineConfig {
            inconsistency: Inconsistency::LOW,
            truth_depth: TruthDepth::Relative,
            hallucination: h,
            ..tiny_config()
        };
        let out = t.path().join(name);
        let o = pipeline::run(&cfg, &inp, &out, false, &quiet).unwrap();
        let md = pipeline::report::markdown(&cfg, &out, &o, 1.0).unwrap();
        let conflict = std::fs::read(out.join("views/conflict.json")).ok();
        if h == Hallucination::None {
            assert!(conflict.is_none() && !md.contains("Conflicting generations"));
        } else {
            // The report shows two conflicting generations and says by how much.
            let c: serde_json::Value = serde_json::from_slice(&conflict.unwrap()).unwrap();
            let db = c["psnr_db"].as_f64().unwrap();
            assert!(db < 15.0, "{db} dB");
            assert!(md.contains("Conflicting generations") && md.contains("conflict_b.png"));
        }
        let m = o.metrics.unwrap();
        m.row("interpolate").unwrap().psnr_extrapolated
            - m.row("original").unwrap().psnr_extrapolated
    };
    let (plain, hallucinated) = (
        gain(Hallucination::None, "plain"),
        gain(Hallucination::High, "high"),
    );
    eprintln!("extrapolated gain: {plain:.2} dB without hallucination, {hallucinated:.2} dB with");
    assert!(hallucinated < plain, "{hallucinated} vs {plain}");
}

/// Median of `|d − truth| / truth` over the pixels with a positive truth and estimate.
fn median_relative_error(d: &[f32], truth: &[f32]) -> f64 {
    let mut e: Vec<f64> = d
        .iter()
        .zip(truth)
        .filter(|&(&a, &b)| a > 0.0 && b > 0.0)
        .map(|(&a, &b)| ((a - b) / b).abs() as f64)
        .collect();
    assert!(!e.is_empty(), "no pixel with both depths");
    e.sort_by(f64::total_cmp);
    e[e.len() / 2]
}

/// Stage 2's dependent-view depth (SPEC.md §20.4) under relative truth depth: by default
/// the paper's video depth alignment (a clip from the nearest training view, one RANSAC
/// over its frames) undoes the clip's seeded affine map of disparity — every dependent
/// candidate's depth is within `VIDEO_DEPTH_MEDIAN_REL` of the dataset's depth (median
/// relative error; measured 0.13–2.1 % on the 10 lounge bridge views at 40×30, truth-low,
/// whose map distorts depth by up to 5 % and flickers 1 % per frame: the bound is the
/// distortion's) — and more accurately than the labelled deviation `render_fit` (measured
/// 4.3–17 %: a single-image fit to a 60-iteration stage-1 render), which is recorded as
/// such, writes no clip and gives other depths.
#[test]
fn stage2_depth_by_video_alignment_recovers_the_relative_map_and_render_fit_is_the_labelled_deviation()
 {
    use unseen::pipeline::{RunOptions, Scope, Stage2Depth};
    const VIDEO_DEPTH_MEDIAN_REL: f64 = 0.05;
    let t = TempDir::new("pipeline-stage2-depth");
    let Tiny { inp, cfg, .. } = TinyRun::new()
        .config(|c| {
            c.interpolation = false;
            c.inconsistency = unseen::pipeline::Inconsistency::LOW;
            c.truth_depth = unseen::pipeline::TruthDepth::Relative;
        })
        .build(&t);
    assert_eq!(
        cfg.stage2_depth,
        Stage2Depth::Video,
        "the paper's method is the default"
    );
    let until = RunOptions {
        scope: Scope::Until(unseen::pipeline::steps::Step::Dependent),
        ..RunOptions::default()
    };
    let fit_cfg = PipelineConfig {
        stage2_depth: Stage2Depth::RenderFit,
        ..cfg.clone()
    };
    let (video_out, fit_out) = (t.path().join("video"), t.path().join("fit"));
    pipeline::run_with(&cfg, &inp, &video_out, &until, &quiet).unwrap();
    pipeline::run_with(&fit_cfg, &inp, &fit_out, &until, &quiet).unwrap();
    let records = |out: &Path| -> Vec<serde_json::Value> {
        let p = out.join("stage2/dependent/dependent.json");
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
        v["views"].as_array().unwrap().clone()
    };
    let (video, fit) = (records(&video_out), records(&fit_out));
    assert!(!video.is_empty(), "the lounge plan has dependent views");
    assert_eq!(video.len(), fit.len());
    let (mut checked, mut differ, mut sum_video, mut sum_fit) = (0, 0, 0.0, 0.0);
    for (v, f) in video.iter().zip(&fit) {
        let name = v["view"].as_str().unwrap();
        assert_eq!(f["method"], "render_fit", "{f}");
        let stem = pipeline::stem(name);
        assert!(
            !fit_out
                .join("stage2/dependent")
                .join(&stem)
                .join("video")
                .exists()
        );
        assert_eq!(v["method"], "video", "{name}: {v}");
        assert!(
            video_out
                .join("stage2/dependent")
                .join(&stem)
                .join("video/cameras.json")
                .is_file()
        );
        let scale = v["alignment"]["scale"].as_f64().unwrap();
        assert!(
            (scale - 1.0).abs() > 0.2,
            "{name}: scale {scale} (no map to undo?)"
        );
        let Some(truth) = inp
            .data
            .views
            .iter()
            .find(|x| x.camera.name == name)
            .and_then(|x| x.depth.clone().map(|d| (x.camera.clone(), d)))
        else {
            continue; // a gap camera: no dataset view
        };
        let (w, h) = (truth.0.width as usize, truth.0.height as usize);
        let read = |out: &Path| {
            unseen::io::image::read_depth(
                &out.join("stage2/dependent")
                    .join(&stem)
                    .join("inpaint.depth.exr"),
                w,
                h,
            )
            .unwrap()
        };
        let (dv, df) = (read(&video_out), read(&fit_out));
        let (ev, ef) = (
            median_relative_error(&dv, &truth.1),
            median_relative_error(&df, &truth.1),
        );
        eprintln!("{name}: median relative depth error video {ev:.4}, render fit {ef:.4}");
        assert!(ev <= VIDEO_DEPTH_MEDIAN_REL, "{name}: {ev}");
        differ += usize::from(dv != df);
        checked += 1;
        (sum_video, sum_fit) = (sum_video + ev, sum_fit + ef);
    }
    assert!(checked > 0, "no dependent candidate with dataset depth");
    assert!(
        sum_video < sum_fit,
        "video {sum_video} vs render fit {sum_fit}"
    );
    assert_eq!(differ, checked, "the two methods gave the same depth");
}

/// Gain of the training half's PSNR (final scene over the original) that the tiny run must
/// keep with the perfect generator (truth-none). Measured at this commit on seeds 0–7:
/// +1.06, +1.06, +0.88, +0.82, +1.28, +1.30, +1.13, +1.47 dB (mean 1.13, sd 0.22; the tiny
/// original scene trains 300 iterations, so perfect generations and 160 more iterations
/// raise it); the floor is the mean less four sd, rounded down. A change that costs the
/// training half about 0.9 dB more than today with nothing wrong generated fails here.
const TRUTH_NONE_TRAIN_HALF_FLOOR_DB: f64 = 0.2;

/// The perfect-generator guard (issue #72): with generations that are the truth at their
/// poses, the pipeline keeps the training half's gain over the original scene above
/// `TRUTH_NONE_TRAIN_HALF_FLOOR_DB` on two seeds.
#[test]
#[ignore = "slow tier (~20 s): cargo test -- --include-ignored"]
fn a_perfect_generator_keeps_the_training_half() {
    let t = TempDir::new("pipeline-perfect-generator");
    let Tiny { inp, cfg, .. } = TinyRun::new().build(&t);
    assert!(
        cfg.inconsistency.is_none()
            && cfg.hallucination == unseen::pipeline::Hallucination::None
            && cfg.slots == unseen::pipeline::SlotNames::truth()
    );
    for seed in [0, 1] {
        let c = PipelineConfig {
            seed,
            ..cfg.clone()
        };
        let out = t.path().join(format!("seed-{seed}"));
        let rows = pipeline::run(&c, &inp, &out, false, &quiet)
            .unwrap()
            .metrics
            .unwrap()
            .rows;
        let gain = rows.last().unwrap().psnr_train_half - rows[0].psnr_train_half;
        assert!(
            gain >= TRUTH_NONE_TRAIN_HALF_FLOOR_DB,
            "seed {seed}: the training half gains {gain:+.3} dB (floor {TRUTH_NONE_TRAIN_HALF_FLOOR_DB:+.1})"
        );
    }
}
