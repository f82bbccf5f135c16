//! Which views the pipeline generates at (SPEC.md §20.2, §20.7): candidate sets as users
//! give them, blind views set aside, gap cameras, the selection rule, the coverage-matched
//! conflicting set, single candidates and candidate families.

use crate::support::TempDir;
use crate::support::quiet;
use crate::support::tiny_run::{Tiny, TinyRun, lounge, tiny_config};
use std::process::Command;
use unseen::pipeline::{self, PipelineConfig, SlotNames};

/// A candidate set as a user gives it (SPEC.md §20.2, "Candidates as users give them"):
/// three bridge views, a held-out view of which the original scene covers no pixel, a
/// training view's pose, and (classical only: the ground-truth generator needs the
/// dataset's views) the same camera again under another name, a view of another size
/// and focal length, a view from outside the room and one from inside a wall. With the classical slots the blind view is set aside (Telea fills
/// only from known pixels), with the ground-truth generator it is extrapolated; the
/// training pose and the repeat are set aside; the run finishes in both families and the
/// report names every set-aside view with its reason.
#[test]
fn candidate_sets_as_users_give_them_are_extrapolated_or_set_aside_never_stop_the_run() {
    use unseen::camera::inria::cameras_json_string;
    use unseen::raster::{Outputs, RenderOptions, render};
    let t = TempDir::new("pipeline-user-candidates");
    let run = TinyRun::new().train(&t);
    let base = TinyRun::new().inputs(&run);
    let data = &base.data;
    // Full size: candidates are given at the dataset's resolution and scaled like the run.
    let full = unseen::camera::inria::read_cameras_json(&lounge().join("cameras.json")).unwrap();
    let at_full = |n: &str| full.iter().find(|c| c.name == n).unwrap().clone();
    let blind = data
        .views
        .iter()
        .filter(|v| v.camera.name.starts_with("heldout_"))
        .find(|v| {
            let r = render(
                &base.scene,
                &v.camera,
                &RenderOptions {
                    background: base.background,
                    outputs: Outputs {
                        alpha: true,
                        ..Outputs::default()
                    },
                    ..RenderOptions::default()
                },
            )
            .unwrap();
            r.alpha.unwrap().iter().all(|&a| a < 0.5)
        })
        .map(|v| v.camera.name.clone())
        .expect("a held-out lounge view the tiny scene does not cover");
    let trained = data.views[data.train[0]].camera.name.clone();
    let mut common = vec![
        at_full("bridge_002"),
        at_full("bridge_008"),
        at_full(&blind),
        at_full("bridge_014"),
        at_full(&trained),
    ];
    let write = |name: &str, cams: &[unseen::camera::Camera]| {
        let p = t.path().join(name);
        std::fs::write(&p, cameras_json_string(cams)).unwrap();
        p
    };
    let truth_list = write("truth.json", &common);
    let mut again = at_full("bridge_008");
    again.name = "bridge_008_again".into();
    let mut other = at_full("bridge_014");
    other.name = "bridge_014_narrow".into();
    (other.width, other.height, other.fx, other.fy) = (120, 96, 1.4 * other.fx, 1.4 * other.fy);
    (other.cx, other.cy) = (60.0, 48.0);
    // Outside the room: 50 m behind a bridge view, looking the same way (through the
    // back of the wall). Inside a wall: at the surface a training view sees at its centre
    // pixel, looking on (the Gaussians there are behind the near plane or around it).
    let mut outside = at_full("bridge_002");
    outside.name = "outside_the_room".into();
    outside.center -= outside.world_from_camera_rotation.col(2) * 50.0;
    let mut in_wall = at_full(&trained);
    in_wall.name = "inside_a_wall".into();
    let t0 = &data.views[data.train[0]];
    let (w0, h0) = (t0.camera.width as usize, t0.camera.height as usize);
    let z = t0.depth.as_ref().unwrap()[(h0 / 2) * w0 + w0 / 2] as f64;
    in_wall.center += in_wall.world_from_camera_rotation.col(2) * z;
    common.push(again);
    common.push(other);
    common.push(outside);
    common.push(in_wall);
    let classical_list = write("classical.json", &common);
    for (family, list) in [("classical", &classical_list), ("truth", &truth_list)] {
        let inp = TinyRun::new().candidates(list).inputs(&run);
        let cfg = PipelineConfig {
            slots: if family == "truth" {
                SlotNames::truth()
            } else {
                SlotNames::default()
            },
            interpolation: false,
            ..tiny_config()
        };
        let out = t.path().join(family);
        let o = pipeline::run(&cfg, &inp, &out, false, &quiet)
            .unwrap_or_else(|e| panic!("{family}: {e}"));
        let plan: unseen::pipeline::views::Plan =
            serde_json::from_slice(&std::fs::read(out.join("views/plan.json")).unwrap()).unwrap();
        let reason = |n: &str| {
            plan.set_aside
                .iter()
                .find(|a| a.name == n)
                .map(|a| a.reason.clone())
        };
        eprintln!("{family}: set aside {:?}", plan.set_aside);
        assert!(
            reason(&trained).is_some_and(|r| r.contains("pose of training view")),
            "{family}: {:?}",
            plan.set_aside
        );
        if family == "classical" {
            assert!(reason(&blind).is_some_and(|r| r.contains("sees nothing")));
            assert!(reason("bridge_008_again").is_some_and(|r| r.contains("same camera")));
            assert!(
                reason("bridge_014_narrow").is_none(),
                "another size is a view"
            );
            assert!(plan.trajectory.iter().any(|n| n == "bridge_014_narrow"));
            // Each is extrapolated, covered or set aside with a reason: never the run's end.
            for n in ["outside_the_room", "inside_a_wall"] {
                let handled = reason(n).is_some()
                    || plan.covered.iter().any(|c| c == n)
                    || plan.trajectory.iter().any(|c| c == n);
                assert!(handled, "{n}: {plan:?}");
                eprintln!(
                    "{n}: {}",
                    reason(n).unwrap_or_else(|| "extrapolated or covered".into())
                );
            }
        } else {
            assert!(
                reason(&blind).is_none(),
                "the truth generator fills from nothing"
            );
            assert!(plan.trajectory.contains(&blind), "{:?}", plan.trajectory);
        }
        let report = pipeline::report::markdown(&cfg, &out, &o, 0.0).unwrap();
        for a in &plan.set_aside {
            assert!(
                report.contains(&format!("- {}: {}", a.name, a.reason)),
                "{family}: the report does not name {}",
                a.name
            );
        }
        let m = o.metrics.as_ref().expect("metrics");
        assert!(m.row("stage2").unwrap().psnr_all.is_finite());
    }
}

/// The case a new user met (issue #36): candidates taken from the room's unseen half
/// (every other held-out camera), the classical slots. Several of them see nothing (or
/// almost nothing) of the original scene; `unseen extrapolate` finishes, prints which views it set aside and why,
/// and lists them in `plan.json` and the report.
#[test]
fn cli_extrapolate_on_the_unseen_half_sets_blind_views_aside_and_finishes() {
    let t = TempDir::new("pipeline-cli-unseen-half");
    let (run, cfg) = TinyRun::new().files(&t);
    let full = unseen::camera::inria::read_cameras_json(&lounge().join("cameras.json")).unwrap();
    let held: Vec<unseen::camera::Camera> = full
        .iter()
        .filter(|c| c.name.starts_with("heldout_"))
        .step_by(2)
        .cloned()
        .collect();
    let list = t.path().join("unseen_half.json");
    std::fs::write(&list, unseen::camera::inria::cameras_json_string(&held)).unwrap();
    let out = t.path().join("out");
    let st = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .arg("extrapolate")
        .arg(&run)
        .arg("--views")
        .arg(&list)
        .arg("--config")
        .arg(&cfg)
        .args([
            "--generator",
            "classical",
            "--no-interpolation",
            "--threads",
            "2",
        ])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(st.status.success(), "{err}");
    let plan: unseen::pipeline::views::Plan =
        serde_json::from_slice(&std::fs::read(out.join("views/plan.json")).unwrap()).unwrap();
    assert!(
        !plan.set_aside.is_empty(),
        "no blind view in {}",
        held.len()
    );
    assert!(!plan.independent.is_empty());
    for a in &plan.set_aside {
        // The two classical rules: Telea needs a known pixel, depth-fill known depth.
        assert!(
            a.reason.contains("sees nothing") || a.reason.contains("only extends known depth"),
            "{a:?}"
        );
        assert!(
            err.contains(&format!("candidate '{}' is set aside", a.name)),
            "{err}"
        );
    }
    eprintln!(
        "{} candidates: {} set aside, {} independent, {} dependent",
        held.len(),
        plan.set_aside.len(),
        plan.independent.len(),
        plan.dependent.len()
    );
}

/// Two candidates of different sizes that do not collide (SPEC.md §20.2): their gap camera
/// takes the first's size; the clips between them cannot be made and are recorded; the
/// run finishes.
#[test]
fn independent_views_of_different_sizes_get_a_gap_camera_and_finish() {
    let t = TempDir::new("pipeline-two-sizes");
    let full = unseen::camera::inria::read_cameras_json(&lounge().join("candidates.json")).unwrap();
    let mut two: Vec<unseen::camera::Camera> = full
        .into_iter()
        .filter(|c| c.name == "bridge_002" || c.name == "bridge_014")
        .collect();
    let o = &mut two[1];
    (o.width, o.height, o.fx, o.fy, o.cx, o.cy) = (120, 96, 1.4 * o.fx, 1.4 * o.fy, 60.0, 48.0);
    let list = t.path().join("two.json");
    std::fs::write(&list, unseen::camera::inria::cameras_json_string(&two)).unwrap();
    let Tiny { inp, cfg, .. } = TinyRun::new()
        .candidates(&list)
        .without_evaluation()
        .config(|c| {
            c.slots = SlotNames::default();
            c.interpolation = false;
        })
        .build(&t);
    let out = t.path().join("out");
    pipeline::run(&cfg, &inp, &out, false, &quiet).unwrap();
    let plan: unseen::pipeline::views::Plan =
        serde_json::from_slice(&std::fs::read(out.join("views/plan.json")).unwrap()).unwrap();
    assert_eq!(plan.independent.len(), 2, "{plan:?}");
    let gap = plan
        .dependent
        .iter()
        .find(|d| d.interpolated)
        .expect("a gap camera");
    let cams = unseen::camera::inria::read_cameras_json(&out.join("views/cameras.json")).unwrap();
    let g = cams.iter().find(|c| c.name == gap.name).unwrap();
    let first = cams.iter().find(|c| c.name == gap.between[0]).unwrap();
    assert_eq!(
        (g.width, g.height, g.fx),
        (first.width, first.height, first.fx)
    );
}

/// The choices the paper leaves open and the audit's colliding set (SPEC.md §20.2), on the
/// tiny lounge's detection: every rule keeps an independent set, the maximum rules beat
/// greedy on their own measure, the hull's collisions are the bounding box's or fewer, the
/// colliding set has the independent set's size, a colliding pair and its coverage
/// difference recorded (used within the tolerance), and the default plan records nothing.
#[test]
fn the_stage1_set_follows_the_selection_rule_and_the_conflicting_set_matches_coverage() {
    use unseen::collide::frustum::Outline;
    use unseen::pipeline::selection::{
        CONFLICT_COVERAGE_TOLERANCE, CONFLICT_MIN_OVERLAP, SelectionRule,
    };
    use unseen::pipeline::views::Plan;
    let t = TempDir::new("pipeline-selection");
    let Tiny { inp, cfg, .. } = TinyRun::new().build(&t);
    let detect = |name: &str, change: &dyn Fn(&mut PipelineConfig)| -> (Plan, String) {
        let mut c = cfg.clone();
        change(&mut c);
        let out = t.path().join(name);
        let opts = pipeline::RunOptions {
            scope: pipeline::Scope::Until(pipeline::Step::Views),
            ..Default::default()
        };
        pipeline::run_with(&c, &inp, &out, &opts, &quiet).unwrap();
        let text = std::fs::read_to_string(out.join("views/plan.json")).unwrap();
        (serde_json::from_str(&text).unwrap(), text)
    };
    let independent = |p: &Plan| {
        !p.collisions
            .iter()
            .any(|[x, y]| p.independent.contains(x) && p.independent.contains(y))
    };
    let (default, text) = detect("default", &|_| {});
    assert!(!text.contains("choice"), "{text}");
    let (greedy, _) = detect("greedy", &|c| {
        c.conflicting_views = Some(unseen::pipeline::selection::ConflictMatch::EvaluationCoverage)
    });
    let choice = greedy.choice.clone().unwrap();
    assert_eq!(choice.rule, SelectionRule::Greedy);
    assert_eq!(choice.independent, default.independent);
    let conflicting = choice.conflicting.expect("the tiny lounge has collisions");
    assert_eq!(conflicting.views.len(), default.independent.len());
    assert!(
        greedy
            .collisions
            .iter()
            .any(|[x, y]| conflicting.views.contains(x) && conflicting.views.contains(y)),
        "{conflicting:?}"
    );
    assert_eq!(
        conflicting.used,
        conflicting.coverage_difference <= CONFLICT_COVERAGE_TOLERANCE
            && conflicting.overlap.unwrap() >= CONFLICT_MIN_OVERLAP
    );
    let stage1 = if conflicting.used {
        &conflicting.views
    } else {
        &default.independent
    };
    assert_eq!(&greedy.independent, stage1);
    let (most, _) = detect("most", &|c| c.selection = SelectionRule::MaxCardinality);
    let (widest, _) = detect("widest", &|c| c.selection = SelectionRule::MaxCoverage);
    assert!(independent(&most) && independent(&widest) && independent(&default));
    assert!(most.independent.len() >= default.independent.len());
    assert!(widest.choice.unwrap().coverage >= choice.coverage);
    let (hull, _) = detect("hull", &|c| c.frustum_outline = Outline::Hull);
    assert!(
        hull.collisions
            .iter()
            .all(|e| default.collisions.contains(e)),
        "a hull lies within its bounding box: {:?} vs {:?}",
        hull.collisions,
        default.collisions
    );
}

/// The audit's colliding set is matched on the coverage its diagnostics report (SPEC.md
/// §20.2, §21.5): the coverages `plan.json` records for the independent and the colliding
/// set are, to the bit, what the diagnostics of the finished runs measure from their
/// stage-1 steps (`full`'s, and the variant's). Without evaluation cameras the variant
/// stops with an error that says what it needs.
#[test]
fn the_conflicting_set_is_matched_on_the_coverage_the_diagnostics_measure() {
    use unseen::pipeline::selection::ConflictMatch;
    use unseen::pipeline::views::Plan;
    let t = TempDir::new("pipeline-conflict-match");
    let Tiny { inp, cfg, .. } = TinyRun::new().build(&t);
    let run = |name: &str, c: &PipelineConfig| {
        let out = t.path().join(name);
        let o = pipeline::run_with(c, &inp, &out, &Default::default(), &quiet).unwrap();
        let plan: Plan =
            serde_json::from_slice(&std::fs::read(out.join("views/plan.json")).unwrap()).unwrap();
        let (scene, _) = unseen::gaussian::ply::read_ply(o.scene.as_ref().unwrap()).unwrap();
        let (d, classes) =
            unseen::audit::diagnostics::diagnose(&inp, &o.steps, Some(&scene)).unwrap();
        // Generation fidelity, from the files: the final scene rendered at each stage-1
        // view against its generation, over the pixels it generated.
        let truth = unseen::pipeline::candidate_truth(&inp).unwrap();
        assert_eq!(d.fidelity.len(), d.stage1_views.len());
        for (f, name) in d.fidelity.iter().zip(&d.stage1_views) {
            assert_eq!(&f.view, name);
            let dir = &o
                .steps
                .iter()
                .find(|s| s.name == format!("stage1/{}", unseen::pipeline::stem(name)))
                .unwrap()
                .dir;
            let image =
                unseen::io::image::read_exr(&dir.join("inpaint.exr"), &["R", "G", "B"]).unwrap();
            let mask = unseen::io::image::read_png(&dir.join("inpaint.mask.png")).unwrap();
            let cam = &truth
                .iter()
                .find(|t| &t.camera.name == name)
                .unwrap()
                .camera;
            let opts = unseen::raster::RenderOptions {
                background: inp.background,
                ..Default::default()
            };
            let rgb = unseen::raster::render(&scene, cam, &opts)
                .unwrap()
                .rgb
                .unwrap();
            let (mut n, mut se) = (0u64, 0f64);
            for p in 0..mask.width * mask.height {
                if mask.data[p * mask.channels] > 0.5 {
                    n += 1;
                    for c in 0..3 {
                        let e =
                            rgb[p * 3 + c].clamp(0.0, 1.0) - image.data[p * 3 + c].clamp(0.0, 1.0);
                        se += f64::from(e) * f64::from(e);
                    }
                }
            }
            assert_eq!(f.contested.pixels + f.uncontested.pixels, n, "{name}");
            let got = f.contested.squared_error + f.uncontested.squared_error;
            assert!(
                (got - se).abs() <= 1e-12 * se.max(1.0),
                "{name}: {got} vs {se}"
            );
        }
        let classes = classes.expect("classes").concat();
        let stage1 = d.stage1.expect("the tiny lounge has truth");
        (plan, stage1, d.fidelity, scene, classes)
    };
    let conflicting = PipelineConfig {
        conflicting_views: Some(ConflictMatch::EvaluationCoverage),
        interpolation: false,
        ..cfg.clone()
    };
    let (plan, measured, fidelity, conflicting_scene, _) = run("conflicting", &conflicting);
    let (_, full_measured, _, full_scene, _) = run(
        "full",
        &PipelineConfig {
            interpolation: false,
            ..cfg.clone()
        },
    );
    let c = plan
        .choice
        .unwrap()
        .conflicting
        .expect("the tiny lounge has collisions");
    assert_eq!(c.matched_on, Some(ConflictMatch::EvaluationCoverage));
    let independent = c.independent_coverage.unwrap();
    assert_eq!(
        independent.to_bits(),
        full_measured.coverage.to_bits(),
        "{c:?}"
    );
    if c.used {
        // Generations that overlap: some generated pixels are contested.
        assert!(
            fidelity.iter().any(|f| f.contested.pixels > 0),
            "{fidelity:?}"
        );
        assert_eq!(c.coverage.to_bits(), measured.coverage.to_bits(), "{c:?}");
        assert_eq!(
            c.overlap.unwrap().to_bits(),
            measured.overlap.to_bits(),
            "{c:?}"
        );
    } else {
        assert_eq!(independent.to_bits(), measured.coverage.to_bits(), "{c:?}");
    }
    assert_eq!(
        c.coverage_difference.to_bits(),
        ((c.coverage - independent).abs() / independent).to_bits()
    );

    // A pair's contact sheet (SPEC.md §21.7) on classes with a 5 × 3 contested block in the
    // second evaluation view (and 2 pixels in the first: fewer, so not the one shown): four
    // panels of the block's crop, the truth, each render and 4·|difference|.
    let sizes: Vec<usize> = inp
        .evaluation
        .iter()
        .map(|&i| inp.data.views[i].image.data.len() / 3)
        .collect();
    let mut classes = vec![0u8; sizes.iter().sum()];
    classes[3] = 2;
    classes[4] = 2;
    let view = &inp.data.views[inp.evaluation[1]];
    let w = view.image.width;
    for y in 7..10 {
        for x in 10..15 {
            classes[sizes[0] + y * w + x] = 2;
        }
    }
    use unseen::audit::pairs::{SHEET_DIFFERENCE_GAIN, SHEET_SCALE as k, contact_sheet};
    let sheet = contact_sheet(&inp, &full_scene, &conflicting_scene, &classes)
        .unwrap()
        .expect("contested pixels");
    assert_eq!((sheet.width, sheet.height), (4 * 5 * k + 12, 3 * k));
    let opts = unseen::raster::RenderOptions {
        background: inp.background,
        ..Default::default()
    };
    let render = |g| {
        unseen::raster::render(g, &view.camera, &opts)
            .unwrap()
            .rgb
            .unwrap()
    };
    let (a, b) = (render(&full_scene), render(&conflicting_scene));
    let p = 8 * w + 12; // (12, 8): panel pixel (2, 1) of the crop
    for c in 0..3 {
        let at = |panel: usize| {
            sheet.data[((k + 1) * sheet.width + panel * (5 * k + 4) + 2 * k + 1) * 3 + c]
        };
        let (ta, tb) = (a[p * 3 + c].clamp(0.0, 1.0), b[p * 3 + c].clamp(0.0, 1.0));
        assert_eq!(at(0), view.image.data[p * 3 + c].clamp(0.0, 1.0));
        assert_eq!((at(1), at(2)), (ta, tb));
        assert_eq!(
            at(3),
            (SHEET_DIFFERENCE_GAIN * (ta - tb).abs()).clamp(0.0, 1.0)
        );
    }
    assert!(
        contact_sheet(
            &inp,
            &full_scene,
            &conflicting_scene,
            &vec![0; classes.len()]
        )
        .unwrap()
        .is_none()
    );
    assert!(contact_sheet(&inp, &full_scene, &conflicting_scene, &classes[1..]).is_err());

    let t2 = TempDir::new("pipeline-conflict-match-no-eval");
    let Tiny { inp, .. } = TinyRun::new().without_evaluation().build(&t2);
    let opts = pipeline::RunOptions {
        scope: pipeline::Scope::Until(pipeline::Step::Views),
        ..Default::default()
    };
    let Err(e) = pipeline::run_with(&conflicting, &inp, &t2.path().join("x"), &opts, &quiet) else {
        panic!("no evaluation cameras, yet the run went on");
    };
    assert!(
        e.to_string().contains("needs evaluation cameras (--eval)"),
        "{e}"
    );
}

/// One candidate (SPEC.md §20.2: one view is a trajectory with a gap to itself): both
/// families finish and extrapolate that view.
#[test]
fn a_single_candidate_view_runs_in_both_families() {
    let t = TempDir::new("pipeline-single-view");
    let full = unseen::camera::inria::read_cameras_json(&lounge().join("candidates.json")).unwrap();
    let one: Vec<unseen::camera::Camera> = full
        .into_iter()
        .filter(|c| c.name == "bridge_008")
        .collect();
    let list = t.path().join("one.json");
    std::fs::write(&list, unseen::camera::inria::cameras_json_string(&one)).unwrap();
    let Tiny { inp, .. } = TinyRun::new().candidates(&list).build(&t);
    for slots in [SlotNames::default(), SlotNames::truth()] {
        let cfg = PipelineConfig {
            slots,
            interpolation: false,
            ..tiny_config()
        };
        let out = t.path().join(cfg.slots.inpaint.to_string());
        let o = pipeline::run(&cfg, &inp, &out, false, &quiet).unwrap();
        let plan: unseen::pipeline::views::Plan =
            serde_json::from_slice(&std::fs::read(out.join("views/plan.json")).unwrap()).unwrap();
        assert_eq!(plan.independent, vec!["bridge_008".to_string()]);
        let m = o.metrics.as_ref().unwrap();
        assert!(
            m.row("stage2").unwrap().psnr_extrapolated
                > m.row("original").unwrap().psnr_extrapolated,
            "{}",
            cfg.slots.inpaint
        );
    }
}

/// A candidate family's views are not in the dataset's cameras.json: their truth comes by
/// name (SPEC.md §20.7). Two ring views facing apart (azimuths −90° and +90°) leave a gap
/// whose half-way camera sees neither end, so the ground-truth generator cannot make its
/// truth and the plan gets no camera there; two neighbours can (SPEC.md §20.2).
#[test]
fn a_ring_family_brings_its_truth_and_a_gap_facing_apart_cannot_be_made() {
    use unseen::pipeline::generators::{GroundTruth, candidate_truth};
    let t = TempDir::new("pipeline-ring");
    let ring = lounge().join("families/ring-13.json");
    let Tiny { inp, .. } = TinyRun::new().candidates(&ring).build(t.path());
    let truth = candidate_truth(&inp).unwrap();
    assert_eq!(truth.len(), 13);
    assert!(truth.iter().all(|v| v.depth.iter().any(|&z| z > 0.0)));
    let gt = GroundTruth::new(truth, unseen::pipeline::Inconsistency::NONE, 0);
    assert!(!gt.can_make_between("ring_012", "ring_000").unwrap());
    assert!(gt.can_make_between("ring_000", "ring_001").unwrap());
}
