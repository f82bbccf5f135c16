//! The extrapolation pipeline end to end (SPEC.md §20) on the bundled lounge at 40×30:
//! thread-count bit identity, resume after `kill -9`, tampering, `compare`, bad input and
//! the ground-truth generator's gain on the extrapolated pixels.

use crate::support::tiny_run::{Tiny, TinyRun, lounge, tiny_config};
use crate::support::{TempDir, reference, walk, with_threads};
use std::path::Path;
use std::process::Command;
use unseen::pipeline::compare::compare;
use unseen::pipeline::{self, Event, Inputs, PipelineConfig, SlotNames, load_inputs};

/// Extrapolated-pixel PSNR gain of the tiny ground-truth run over the original scene that
/// the test requires. Measured 7.1 dB (9.03 → 16.15 dB on the 12 evaluation bridge
/// views; the classical slots give 3.3 dB); the floor leaves room for legitimate
/// changes of the recipe while failing a pipeline that does not extrapolate, or that
/// extrapolates no better than the classical slots. The issue's 8 dB is for the quick
/// preset at 80×60 (SPEC.md §20.10).
const TINY_EXTRAPOLATED_GAIN_DB: f64 = 5.0;
/// Largest drop of the training half's PSNR allowed (the issue's 0.5 dB; +1.0 dB measured).
const TRAIN_HALF_DROP_DB: f64 = 0.5;

fn quiet(_: Event) {}

#[test]
#[ignore = "slow tier (~20 s): cargo test -- --include-ignored"]
fn pipeline_extrapolates_and_is_the_same_bits_on_1_2_and_7_threads() {
    let t = TempDir::new("pipeline-threads");
    let Tiny { inp, cfg, .. } = TinyRun::new().build(&t);
    let mut outs = Vec::new();
    for threads in [1, 2, 7] {
        let out = t.path().join(format!("ex{threads}"));
        let o = with_threads(threads, || pipeline::run(&cfg, &inp, &out, false, &quiet)).unwrap();
        outs.push((out, o));
    }
    // The classical slots (the CLI's default) too.
    let classical = PipelineConfig {
        slots: SlotNames::default(),
        ..tiny_config()
    };
    let (c1, c2) = (t.path().join("classical1"), t.path().join("classical2"));
    with_threads(1, || pipeline::run(&classical, &inp, &c1, false, &quiet)).unwrap();
    with_threads(2, || pipeline::run(&classical, &inp, &c2, false, &quiet)).unwrap();
    let c = compare(&c1, &c2, 0.0).unwrap();
    assert!(c.steps.iter().all(|s| s.identical), "{}", c.table());
    for (out, _) in &outs[1..] {
        let c = compare(&outs[0].0, out, 0.0).unwrap();
        assert_eq!(c.first_divergent, None, "{}", c.table());
        assert!(c.steps.iter().all(|s| s.identical), "{}", c.table());
        assert!(c.steps.len() >= 12, "{} steps compared", c.steps.len());
    }
    let m = outs[0].1.metrics.as_ref().unwrap();
    let (orig, last) = (m.row("original").unwrap(), m.row("interpolate").unwrap());
    assert!(
        last.psnr_extrapolated - orig.psnr_extrapolated >= TINY_EXTRAPOLATED_GAIN_DB,
        "{}",
        m.table()
    );
    assert!(
        last.psnr_train_half >= orig.psnr_train_half - TRAIN_HALF_DROP_DB,
        "{}",
        m.table()
    );
    // The run directory: a manifest per step, frustums for a mesh viewer, the plan.
    let ex = &outs[0].0;
    for f in [
        "config.json",
        "timings.json",
        "views/plan.json",
        "views/frustums.obj",
        "stage1/recon/scene.ply",
        "stage2/recon/manifest.json",
        "interpolate/recon/scene.ply",
        "eval/summary.json",
    ] {
        assert!(ex.join(f).is_file(), "{f} missing");
    }
    // Every step's cost: seconds and, where the OS lets the peak be reset and read (Linux
    // `clear_refs`), its peak resident memory.
    let steps: Vec<String> =
        serde_json::from_slice(&std::fs::read(ex.join("steps.json")).unwrap()).unwrap();
    let costs: serde_json::Value =
        serde_json::from_slice(&std::fs::read(ex.join("timings.json")).unwrap()).unwrap();
    for s in &steps {
        assert!(costs[s]["seconds"].as_f64().unwrap() >= 0.0, "{s}");
        if let Some(peak) = costs[s]["peak_rss_bytes"].as_u64() {
            assert!(peak > 1_000_000, "{s}: {peak}");
        }
    }
    let obj = tobj::load_obj(ex.join("views/frustums.obj"), &tobj::LoadOptions::default());
    assert!(obj.is_ok_and(|(m, _)| !m.is_empty()));
}

#[test]
#[ignore = "slow tier (~15 s): cargo test -- --include-ignored"]
fn resume_after_kill_9_gives_the_same_bits() {
    let t = TempDir::new("pipeline-resume");
    let (run, cfg) = TinyRun::new().files(&t);
    let args = |out: &Path| -> Vec<String> {
        [
            "extrapolate",
            run.to_str().unwrap(),
            "--views",
            lounge().join("candidates.json").to_str().unwrap(),
            "--eval",
            lounge().join("evaluation.json").to_str().unwrap(),
            "--dataset",
            lounge().to_str().unwrap(),
            "--config",
            cfg.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    let full = t.path().join("full");
    let st = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .args(args(&full))
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    // Kill at three points: before stage 1's reconstruction finishes, in stage 2, late.
    for (k, marker) in [
        "stage1/propagate/manifest.json",
        "stage2/videos",
        "qa/stage2",
    ]
    .iter()
    .enumerate()
    {
        let out = t.path().join(format!("killed{k}"));
        let mut child = Command::new(env!("CARGO_BIN_EXE_unseen"))
            .args(args(&out))
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let t0 = std::time::Instant::now();
        while !out.join(marker).exists() && t0.elapsed().as_secs() < 60 {
            if child.try_wait().unwrap().is_some() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before the kill at {marker}"
        );
        child.kill().unwrap(); // SIGKILL
        let _ = child.wait();
        assert!(!out.join("steps.json").exists(), "killed before the end");
        let st = Command::new(env!("CARGO_BIN_EXE_unseen"))
            .args(args(&out))
            .arg("--resume")
            .output()
            .unwrap();
        assert!(
            st.status.success(),
            "{}",
            String::from_utf8_lossy(&st.stderr)
        );
        let c = compare(&full, &out, 0.0).unwrap();
        assert!(c.steps.iter().all(|s| s.identical), "{}", c.table());
        // No temporary file survives.
        let tmp = walk(&out).into_iter().filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().contains(".tmp-"))
        });
        assert_eq!(tmp.count(), 0);
    }
    // The CLI's compare agrees (exit 0), reports a divergence with exit 1 and naming the
    // step, and a folder that is no run with exit 2.
    let cmp = |b: &Path| {
        Command::new(env!("CARGO_BIN_EXE_unseen"))
            .args(["compare", full.to_str().unwrap()])
            .arg(b)
            .output()
            .unwrap()
    };
    let ok = cmp(&t.path().join("killed0"));
    assert_eq!(ok.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&ok.stdout).contains("identical"));
    let frame = t.path().join("killed0/stage2/videos/video_0/frame_01.exr");
    let mut img = unseen::io::image::read_exr(&frame, &["R", "G", "B"]).unwrap();
    img.data[0] += 0.5;
    unseen::io::image::write_exr(&frame, &img).unwrap();
    let bad = cmp(&t.path().join("killed0"));
    assert_eq!(bad.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&bad.stdout).contains("first divergent step: stage2/videos"));
    assert_eq!(cmp(&t.path().join("nothing-here")).status.code(), Some(2));
}

#[test]
fn tampered_artifacts_are_recomputed_and_compare_names_the_first_divergent_step() {
    let t = TempDir::new("pipeline-tamper");
    let Tiny { inp, cfg, .. } = TinyRun::new().config(|c| c.interpolation = false).build(&t);
    let a = t.path().join("a");
    pipeline::run(&cfg, &inp, &a, false, &quiet).unwrap();
    let b = t.path().join("b");
    pipeline::run(&cfg, &inp, &b, false, &quiet).unwrap();
    // Change one value of an intermediate frame of a stage-2 clip in B: compare finds it
    // in that step.
    let dep = walk(&b.join("stage2/videos"))
        .into_iter()
        .filter(|p| p.to_string_lossy().ends_with("frame_01.exr"))
        .min()
        .unwrap();
    let mut img = unseen::io::image::read_exr(&dep, &["R", "G", "B"]).unwrap();
    img.data[7] += 0.25;
    unseen::io::image::write_exr(&dep, &img).unwrap();
    let c = compare(&a, &b, 0.0).unwrap();
    assert_eq!(c.first_divergent.as_deref(), Some("stage2/videos"));
    let f = c
        .steps
        .iter()
        .flat_map(|s| &s.files)
        .find(|f| !f.identical)
        .unwrap();
    assert!((f.max_abs.unwrap() - 0.25).abs() < 1e-6, "{f:?}");
    assert!(compare(&a, &b, 0.5).unwrap().first_divergent.is_none());
    // Resume notices the tampered file and recomputes that step; it comes out with the same
    // bits, so the steps after it keep their keys and are not recomputed (content
    // addressing).
    let skipped = std::sync::Mutex::new(Vec::new());
    pipeline::run(&cfg, &inp, &b, true, &|e| {
        if let Event::StepSkipped { step } = e {
            skipped.lock().unwrap().push(step)
        }
    })
    .unwrap();
    let skipped = skipped.into_inner().unwrap();
    assert!(skipped.contains(&"views".to_string()));
    assert!(skipped.contains(&"stage1/recon".to_string()));
    assert!(!skipped.contains(&"stage2/videos".to_string()));
    assert!(skipped.contains(&"stage2/recon".to_string()));
    let c = compare(&a, &b, 0.0).unwrap();
    assert!(c.steps.iter().all(|s| s.identical), "{}", c.table());
}

#[test]
fn bad_pipeline_input_is_one_clear_error() {
    let t = TempDir::new("pipeline-bad");
    let run = TinyRun::new().train(&t);
    let cands = lounge().join("candidates.json");
    let err = |r: unseen::Result<Inputs>| r.err().map(|e| e.to_string()).unwrap_or_default();
    // Empty view list.
    let empty = t.path().join("empty.json");
    std::fs::write(&empty, "[]").unwrap();
    assert!(err(load_inputs(&run, &empty, None, Some(&lounge()))).contains("empty"));
    // Only a candidate at a training pose: set aside (SPEC.md §20.2), so nothing is left
    // to extrapolate — one error naming it and the rule, nothing written for the plan.
    let all: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(lounge().join("cameras.json")).unwrap()).unwrap();
    let train0 = all.iter().find(|c| c["img_name"] == "train_001").unwrap();
    let same = t.path().join("same.json");
    std::fs::write(&same, serde_json::to_string(&[train0]).unwrap()).unwrap();
    let inp = load_inputs(&run, &same, None, Some(&lounge())).unwrap();
    let out = t.path().join("same-out");
    let e = pipeline::run(&tiny_config(), &inp, &out, false, &quiet)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        e.contains("nothing to extrapolate")
            && e.contains("'train_001' is set aside: has the pose of training view 'train_001'"),
        "{e}"
    );
    assert!(!out.join("views/plan.json").exists());
    // A run without a PLY.
    let bare = t.path().join("bare");
    std::fs::create_dir_all(&bare).unwrap();
    std::fs::copy(run.join("config.json"), bare.join("config.json")).unwrap();
    let e = err(load_inputs(&bare, &cands, None, Some(&lounge())));
    assert!(e.contains("point_cloud"), "{e}");
    // A newer-numbered PLY the run's manifest does not list (a stale file): refused.
    let stale = run.join("point_cloud/iteration_999999");
    std::fs::create_dir_all(&stale).unwrap();
    std::fs::copy(reference("demo/scene.ply"), stale.join("point_cloud.ply")).unwrap();
    let e = err(load_inputs(&run, &cands, None, Some(&lounge())));
    assert!(e.contains("stale") && e.contains("iteration_999999"), "{e}");
    std::fs::remove_dir_all(&stale).unwrap();
    // An output folder that holds something, without --resume; an output path that is a file.
    let inp = TinyRun::new().inputs(&run);
    let busy = t.path().join("busy");
    std::fs::create_dir_all(&busy).unwrap();
    std::fs::write(busy.join("x"), "x").unwrap();
    let e = pipeline::run(&tiny_config(), &inp, &busy, false, &quiet).unwrap_err();
    assert!(e.to_string().contains("--resume"), "{e}");
    let file = t.path().join("file");
    std::fs::write(&file, "x").unwrap();
    assert!(pipeline::run(&tiny_config(), &inp, &file, false, &quiet).is_err());
    // A candidate outside the room looking away sees nothing to align to: named.
    let mut away = train0.clone();
    away["img_name"] = "outside".into();
    away["position"] = serde_json::json!([40.0, 1.0, 0.0]);
    // Turned half a turn about the vertical: train_001 looks towards −x, this one to +x.
    for row in [0, 2] {
        for k in 0..3 {
            let v = away["rotation"][row][k].as_f64().unwrap();
            away["rotation"][row][k] = (-v).into();
        }
    }
    let outside = t.path().join("outside.json");
    std::fs::write(&outside, serde_json::to_string(&[away]).unwrap()).unwrap();
    let inp_out = load_inputs(&run, &outside, None, Some(&lounge())).unwrap();
    let cfg = PipelineConfig {
        slots: SlotNames::default(),
        ..tiny_config()
    };
    let out = t.path().join("outside-run");
    let e = pipeline::run(&cfg, &inp_out, &out, false, &quiet).unwrap_err();
    assert!(e.to_string().contains("'outside'"), "{e}");
    // An unknown model is refused where the configuration is read, naming the model, the
    // known ones and the file.
    let file = t.path().join("slot.json");
    let e = PipelineConfig::with_overrides(
        unseen::pipeline::Preset::Quick,
        serde_json::json!({"slots": {"inpaint": "nope"}}),
        &file,
    )
    .unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains("slot.json")
            && text.contains("unknown inpainter 'nope' (known: telea, or onnx:CARD.json)"),
        "{e}"
    );
    let e = PipelineConfig::with_overrides(
        unseen::pipeline::Preset::Quick,
        serde_json::json!({"slots": {"video": "onnx:v.json"}}),
        &file,
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("unknown video generator 'onnx:v.json'"),
        "{e}"
    );
}

/// A batch engine's fan-out (SPEC.md §20.8): detection alone, then each independent view's
/// stage-1 step as its own job, then the rest with `--resume`, gives the bits of one run;
/// a job whose inputs are not done is a clear error.
#[test]
fn per_view_jobs_then_resume_equal_one_run() {
    use unseen::pipeline::steps::{Scene, Step};
    use unseen::pipeline::{RunOptions, Scope};
    let run_scoped = |cfg, inp, out: &Path, resume, scope, on_event: &(dyn Fn(Event) + Sync)| {
        let opts = RunOptions {
            resume,
            scope,
            cache: None,
        };
        pipeline::run_with(cfg, inp, out, &opts, on_event)
    };
    let t = TempDir::new("pipeline-batch");
    let Tiny { inp, cfg, .. } = TinyRun::new().config(|c| c.interpolation = false).build(&t);
    let whole = t.path().join("whole");
    pipeline::run(&cfg, &inp, &whole, false, &quiet).unwrap();
    let out = t.path().join("batch");
    let o = run_scoped(&cfg, &inp, &out, false, Scope::Until(Step::Views), &quiet).unwrap();
    assert!(o.scene.is_none());
    assert!(!out.join("stage1").exists(), "nothing after views ran");
    // Again, with views done: still nothing after it. A name that is no step does not
    // parse; a step this run does not have is an error.
    run_scoped(&cfg, &inp, &out, true, Scope::Until(Step::Views), &quiet).unwrap();
    assert!(
        !out.join("stage1").exists(),
        "--until on a done step stops there"
    );
    let typo = t.path().join("typo");
    let e = run_scoped(
        &cfg,
        &inp,
        &typo,
        false,
        Scope::Until(Step::Eval(Scene::Interpolate)),
        &quiet,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("no step called 'eval/interpolate'"), "{e}");
    assert!(
        !typo.exists(),
        "a scope the plan does not have writes nothing"
    );
    let e = "stage9".parse::<Step>().unwrap_err().to_string();
    assert!(e.contains("'stage9' is not a step of a run"), "{e}");
    let plan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("views/plan.json")).unwrap()).unwrap();
    let independent: Vec<String> = plan["independent"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap().to_string())
        .collect();
    assert!(independent.len() >= 2);
    // A job whose inputs are missing names the step it needs.
    let e = run_scoped(
        &cfg,
        &inp,
        &out,
        true,
        Scope::Only(Step::Stage1Recon),
        &quiet,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("is not done") && e.contains("run up to it first with --until"),
        "{e}"
    );
    // One job per independent view, last first (order does not matter).
    for v in independent.iter().rev() {
        let step = Step::Independent(v.clone());
        run_scoped(&cfg, &inp, &out, true, Scope::Only(step.clone()), &quiet).unwrap();
        assert!(step.dir(&out).join("manifest.json").is_file(), "{step}");
    }
    assert!(!out.join("stage1/recon").exists());
    let skipped = std::sync::Mutex::new(Vec::new());
    pipeline::run(&cfg, &inp, &out, true, &|e| {
        if let Event::StepSkipped { step } = e {
            skipped.lock().unwrap().push(step)
        }
    })
    .unwrap();
    let skipped = skipped.into_inner().unwrap();
    for v in &independent {
        assert!(skipped.contains(&format!("stage1/{v}")), "{skipped:?}");
    }
    let c = compare(&whole, &out, 0.0).unwrap();
    assert!(c.steps.iter().all(|s| s.identical), "{}", c.table());
}

/// Camera names become folder names injectively, never `.`, `..` or a separator; empty and
/// reserved names are refused, naming the file.
#[test]
fn view_names_map_to_distinct_safe_folders() {
    use unseen::pipeline::stem;
    let names = [
        "a.b",
        "a_b",
        "a%2Eb",
        "..",
        ".",
        "x/y",
        "IMG_0001.JPG",
        "IMG_0001.png",
    ];
    let stems: Vec<String> = names.iter().map(|n| stem(n)).collect();
    for (i, s) in stems.iter().enumerate() {
        assert!(!s.contains('.') && !s.contains('/') && !s.is_empty(), "{s}");
        for t in &stems[..i] {
            assert_ne!(s, t);
        }
    }
    let t = TempDir::new("pipeline-names");
    let run = TinyRun::new().train(&t);
    let text = std::fs::read(lounge().join("candidates.json")).unwrap();
    let mut cam = serde_json::from_slice::<Vec<serde_json::Value>>(&text)
        .unwrap()
        .remove(0);
    for bad in ["", "recon"] {
        cam["img_name"] = bad.into();
        let p = t.path().join("bad.json");
        std::fs::write(&p, serde_json::to_string(&[&cam]).unwrap()).unwrap();
        let e = load_inputs(&run, &p, None, Some(&lounge()))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            e.contains("reserved") && e.contains("bad.json"),
            "{bad}: {e}"
        );
    }
}

/// A learned slot is keyed by the hashes of its card and weights, so editing either
/// invalidates the steps that called it; classical slots by their name.
#[test]
#[cfg(feature = "onnx")]
fn slot_fingerprints_follow_the_model_files() {
    use unseen::models::inpainter;
    assert_eq!(
        inpainter(&"telea".parse().unwrap()).unwrap().fingerprint(),
        "telea"
    );
    let t = TempDir::new("pipeline-fingerprint");
    let src = reference("onnx/inpaint_tiny");
    for e in std::fs::read_dir(&src).unwrap().flatten() {
        std::fs::copy(e.path(), t.path().join(e.file_name())).unwrap();
    }
    let card = t.path().join("card.json");
    let name = format!("onnx:{}", card.display()).parse().unwrap();
    let a = inpainter(&name).unwrap().fingerprint();
    assert!(a.starts_with("onnx:") && a.len() == 5 + 64 + 1 + 64, "{a}");
    let text = std::fs::read_to_string(&card).unwrap();
    std::fs::write(&card, format!("{text}\n")).unwrap();
    let b = inpainter(&name).unwrap().fingerprint();
    assert_ne!(a, b);
    assert_eq!(a[a.len() - 64..], b[b.len() - 64..], "same weights");
}

/// `unseen extrapolate` / `unseen compare` on bad input: exit ≠ 0, one line on stderr naming
/// the file and what is wrong, and no run directory left behind by a run that could not
/// start.
#[test]
fn cli_extrapolate_bad_input_matrix() {
    let t = TempDir::new("pipeline-cli-bad");
    let run = TinyRun::new().train(&t);
    let cands = lounge().join("candidates.json");
    let empty = t.path().join("empty.json");
    std::fs::write(&empty, "[]").unwrap();
    let broken = t.path().join("broken.json");
    std::fs::write(&broken, "[{\"img_name\": ").unwrap();
    let bad_cfg = t.path().join("bad_cfg.json");
    std::fs::write(&bad_cfg, "{\"inpaintingz\": 3}").unwrap();
    let nan_cam = t.path().join("nan.json");
    std::fs::write(
        &nan_cam,
        std::fs::read_to_string(&cands)
            .unwrap()
            .replacen("\"fx\": ", "\"fx\": -", 1),
    )
    .unwrap();
    let a_file = t.path().join("a_file");
    std::fs::write(&a_file, "x").unwrap();
    let no_run = t.path().join("no_run");
    let cases: Vec<(&str, Vec<std::ffi::OsString>, &str, &str)> = vec![
        (
            "missing run",
            vec![
                no_run.clone().into(),
                "--views".into(),
                cands.clone().into(),
            ],
            "no_run",
            "not an `unseen train` run",
        ),
        (
            "missing views",
            vec![
                run.clone().into(),
                "--views".into(),
                t.path().join("none.json").into(),
            ],
            "none.json",
            "No such file",
        ),
        (
            "empty views",
            vec![run.clone().into(), "--views".into(), empty.clone().into()],
            "empty.json",
            "empty",
        ),
        (
            "malformed views",
            vec![run.clone().into(), "--views".into(), broken.clone().into()],
            "broken.json",
            "cameras.json",
        ),
        (
            "negative fx",
            vec![run.clone().into(), "--views".into(), nan_cam.clone().into()],
            "nan.json",
            "must be finite and positive",
        ),
        (
            "unknown config field",
            vec![
                run.clone().into(),
                "--views".into(),
                cands.clone().into(),
                "--config".into(),
                bad_cfg.clone().into(),
            ],
            "bad_cfg.json",
            "inpaintingz",
        ),
    ];
    for (what, args, file, words) in cases {
        let out = t.path().join(format!("out-{}", what.replace(' ', "-")));
        let st = Command::new(env!("CARGO_BIN_EXE_unseen"))
            .arg("extrapolate")
            .args(&args)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&st.stderr);
        assert!(!st.status.success(), "{what}: succeeded");
        assert_eq!(err.trim().lines().count(), 1, "{what}: {err}");
        assert!(err.contains(file) && err.contains(words), "{what}: {err}");
        assert!(!out.exists(), "{what}: left {}", out.display());
    }
    // The output path is a file: refused, the file untouched.
    let st = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .args(["extrapolate"])
        .arg(&run)
        .arg("--views")
        .arg(&cands)
        .arg("--out")
        .arg(&a_file)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(
        !st.status.success() && err.contains("a_file") && err.contains("is a file"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&a_file).unwrap(), "x");
}

/// A step cache shared by two run directories: a repeat run copies every step, a variant
/// copies the steps whose inputs it shares and computes the rest, both to the bits of a
/// run without the cache; a corrupted cache entry is not used.
#[test]
fn step_cache_shares_equal_steps_across_runs() {
    use unseen::pipeline::{MaskSource, RunOptions};
    let t = TempDir::new("pipeline-cache");
    let Tiny { inp, cfg, .. } = TinyRun::new().config(|c| c.interpolation = false).build(&t);
    let cache = t.path().join("cache");
    let opts = RunOptions {
        cache: Some(cache.clone()),
        ..RunOptions::default()
    };
    let events = |cfg: &PipelineConfig, out: &Path| {
        let log = std::sync::Mutex::new((Vec::new(), Vec::new()));
        pipeline::run_with(cfg, &inp, out, &opts, &|e| match e {
            Event::StepCached { step } => log.lock().unwrap().0.push(step),
            Event::StepFinished { step, .. } => log.lock().unwrap().1.push(step),
            _ => {}
        })
        .unwrap();
        // Per-view steps run in parallel: compare as sets.
        let (mut cached, mut computed) = log.into_inner().unwrap();
        cached.sort();
        computed.sort();
        (cached, computed)
    };
    let a = t.path().join("a");
    let (cached, computed) = events(&cfg, &a);
    assert!(cached.is_empty() && !computed.is_empty());
    let b = t.path().join("b");
    let (cached_b, computed_b) = events(&cfg, &b);
    assert_eq!(cached_b, computed, "a repeat run copies every step");
    assert!(computed_b.is_empty());
    assert!(compare(&a, &b, 0.0).unwrap().first_divergent.is_none());
    // A variant that changes only the reconstructions' weights shares the views and the
    // per-view generation steps.
    let variant = PipelineConfig {
        mask_source: MaskSource::Opacity,
        ..cfg.clone()
    };
    let v = t.path().join("v");
    let (cached_v, computed_v) = events(&variant, &v);
    assert!(cached_v.contains(&"views".to_string()), "{cached_v:?}");
    assert!(
        computed_v.contains(&"stage1/recon".to_string()),
        "{computed_v:?}"
    );
    let plain = t.path().join("plain");
    pipeline::run(&variant, &inp, &plain, false, &quiet).unwrap();
    assert!(compare(&v, &plain, 0.0).unwrap().first_divergent.is_none());
    // Corrupt the cached views step: the next run computes it again.
    let entry = std::fs::read_dir(&cache)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.join("plan.json").is_file())
        .unwrap();
    let plan = entry.join("plan.json");
    let mut text = std::fs::read(&plan).unwrap();
    text.push(b' ');
    std::fs::remove_file(&plan).unwrap(); // the file is a hard link of a's: replace, not edit
    std::fs::write(&plan, text).unwrap();
    let c = t.path().join("c");
    let (cached_c, computed_c) = events(&cfg, &c);
    assert!(computed_c.contains(&"views".to_string()), "{computed_c:?}");
    assert!(!cached_c.contains(&"views".to_string()));
    assert!(compare(&a, &c, 0.0).unwrap().first_divergent.is_none());
    // ... and publishes it again: the entry is repaired, the next run copies it.
    assert_eq!(
        std::fs::read(&plan).unwrap(),
        std::fs::read(a.join("views/plan.json")).unwrap()
    );
    let (cached_d, _) = events(&cfg, &t.path().join("d"));
    assert!(cached_d.contains(&"views".to_string()), "{cached_d:?}");
}

/// The audit on a tiny configuration: two seeds, two variants, one generator. Every job
/// runs, the variants share their common steps through the cache, the report has a
/// verdict for each claim on the variants run, and a second run verifies and reuses
/// everything (the same results bit for bit).
#[test]
#[ignore = "slow tier (~15 s): cargo test -- --include-ignored"]
fn audit_runs_every_job_shares_steps_and_resumes_to_the_same_results() {
    use unseen::audit::{self, AuditConfig, GeneratorKind, Job, Variant};
    let t = TempDir::new("pipeline-audit");
    let cfg = AuditConfig {
        base: PipelineConfig {
            interpolation: false,
            attribution: true,
            ..tiny_config()
        },
        variants: vec![Variant::Full, Variant::OpacityMask],
        generators: vec![GeneratorKind::Truth(unseen::pipeline::Level::Low)],
        seeds: 0..2,
        train_iterations: 300,
        train_resolution: 4,
        planned_seeds: 2,
        candidates: None,
    };
    let dir = t.path().join("audit");
    // A pipeline job before its original scene: a clear error naming the job to run.
    let job = Job::Run {
        generator: GeneratorKind::Truth(unseen::pipeline::Level::Low),
        variant: Variant::Full,
        seed: 0,
    };
    let lounge = lounge();
    let e = audit::Audit::new(&cfg, &lounge, &dir)
        .unwrap()
        .run_job(&job)
        .unwrap_err()
        .to_string();
    assert!(e.contains("original/seed-0"), "{e}");
    let cached = std::sync::Mutex::new(Vec::new());
    let on_cached = |e| {
        if let Event::StepCached { step } = e {
            cached.lock().unwrap().push(step)
        }
    };
    let report = audit::Audit::new(&cfg, &lounge, &dir)
        .unwrap()
        .with_events(&on_cached)
        .run(&[])
        .unwrap();
    assert_eq!(report.results.len(), 4);
    let cached = cached.into_inner().unwrap();
    assert!(
        cached.iter().filter(|s| *s == "views").count() == 2,
        "each seed's second variant copies the views step: {cached:?}"
    );
    // Claims on the opacity-mask variant only, each with both seeds.
    let claims: Vec<&str> = report.verdicts.iter().map(|v| v.claim.id).collect();
    assert_eq!(
        claims,
        [
            "QA-Mask over opacity maps, existing",
            "QA-Mask over opacity maps, extrapolated",
            "no deterioration within original areas"
        ]
    );
    for v in &report.verdicts {
        assert_eq!(v.seeds, 2);
        assert!(v.mean_diff.is_finite() && v.std_diff.is_finite(), "{v:?}");
        // Both seeds have per-view records, but two units are too few for the
        // seeds-then-views interval (HIERARCHICAL_MIN_UNITS); the training half has none.
        let with_records = if v.claim.metric == unseen::audit::Metric::PsnrTrainHalf {
            0
        } else {
            2
        };
        assert!(
            v.hierarchical.is_none() && v.hierarchical_units == with_records,
            "{v:?}"
        );
        assert!(
            ["holds", "contradicted", "inconclusive"].contains(&v.verdict.as_str()),
            "{v:?}"
        );
    }
    // What sharing saved: every step copied from the cache is one execution more than the
    // distinct steps; the views step is computed once per seed.
    let shared = audit::sharing(&report.results);
    let all = shared.last().unwrap();
    assert_eq!(all.stage, "all");
    assert_eq!(all.executions - all.distinct, cached.len(), "{shared:?}");
    let views = shared.iter().find(|r| r.stage == "views").unwrap();
    assert_eq!((views.executions, views.distinct), (4, 2), "{shared:?}");
    for r in &shared {
        assert!(
            r.shared_seconds <= r.unshared_seconds && r.shared_seconds > 0.0,
            "{r:?}"
        );
    }
    // Each run records its scenes on the training half, the original first and the final
    // last (issue #72).
    for r in &report.results {
        let names: Vec<&str> = r.stages.iter().map(|s| s.scene.as_str()).collect();
        assert_eq!(names.first(), Some(&"original"), "{names:?}");
        assert_eq!(names.last(), Some(&r.last.scene.as_str()), "{names:?}");
        let last = r.stages.last().unwrap();
        assert_eq!(
            (last.psnr_train_half, last.gaussians),
            (r.last.psnr_train_half, r.last.gaussians)
        );
        // The lineage: on every scene of the chain but the original (SPEC.md §20.7).
        for s in &r.stages {
            let l = s.lineage.as_ref();
            assert_eq!(l.is_some(), s.scene != "original", "{}: {l:?}", s.scene);
            if let Some(l) = l {
                assert_eq!(l.from_originals + l.added, s.gaussians, "{l:?}");
                // Which views moved the Gaussians (§20.5, on here): recorded by every
                // reconstruction that trained on generated views.
                let a = l.attribution.as_ref().expect("recorded");
                assert!(a.reached > 0 && a.groups.len() == 5, "{a:?}");
                assert!(a.share(unseen::gaussian::Param::Means).is_finite(), "{a:?}");
            }
        }
    }
    // Each run records what it did; the mask variant keeps full's views.
    for r in &report.results {
        let d = r.diagnostics.as_ref().expect("recorded");
        assert!(
            !d.stage1_views.is_empty() && d.stage1_collisions == 0,
            "{d:?}"
        );
        let g = d.stage1.expect("measured");
        assert!(
            (0.0..=1.0).contains(&g.coverage) && g.overlap <= g.coverage,
            "{g:?}"
        );
        assert!((0.0..=1.0).contains(&d.stage2_filled), "{d:?}");
        // Its evaluation pixels' classes: one byte per pixel, the sample of the unseen
        // surface and the points two stage-1 views generated as the diagnostics count them;
        // its final scene where the result says, with the digest it gives.
        let folder = dir.join(
            Job::Run {
                generator: GeneratorKind::by_name(&r.generator).unwrap(),
                variant: r.variant.parse::<Variant>().unwrap(),
                seed: r.seed,
            }
            .folder(),
        );
        let classes = std::fs::read(folder.join(audit::jobs::CLASSES_FILE)).unwrap();
        let evaluated: usize = r.last.views.iter().map(|v| v.all.pixels as usize).sum();
        assert_eq!(classes.len(), evaluated, "{}", folder.display());
        let count = |c: u8| classes.iter().filter(|&&k| k == c).count() as u64;
        use unseen::pipeline::evaluate::{CLASS_CONTESTED, CLASS_OTHER, CLASS_UNCONTESTED};
        assert_eq!(
            count(CLASS_OTHER) + count(CLASS_UNCONTESTED) + count(CLASS_CONTESTED),
            evaluated as u64
        );
        assert_eq!(count(CLASS_UNCONTESTED) + count(CLASS_CONTESTED), g.pixels);
        assert_eq!(count(CLASS_CONTESTED) as f64 / g.pixels as f64, g.overlap);
        let scene = std::fs::read(folder.join(&r.final_scene)).unwrap();
        assert_eq!(unseen::io::sha256_hex(&scene), r.scene_sha256);
        // The pair of this run with itself on its classes: both sides the same bits, the
        // classes' pixels counted, and contested + uncontested the extrapolated pixels with
        // truth depth, whose sums the evaluation's extrapolated class holds.
        let inputs = unseen::pipeline::load_inputs(
            &dir.join(Job::Original { seed: r.seed }.name()),
            &lounge.join("candidates.json"),
            Some(&lounge.join("evaluation.json")),
            Some(&lounge),
        )
        .unwrap();
        let (g, _) = unseen::gaussian::ply::read_ply(&folder.join(&r.final_scene)).unwrap();
        let pair = audit::pairs::score_pair(&inputs, &g, &g, &classes).unwrap();
        assert_eq!(pair.len(), r.last.views.len());
        let (mut contested, mut uncontested, mut whole, mut mutual) = (0, 0, 0, 0);
        for (p, v) in pair.iter().zip(&r.last.views) {
            assert_eq!(p.view, v.view);
            assert_eq!(p.contested[0], p.contested[1]);
            assert_eq!(p.uncontested[0], p.uncontested[1]);
            contested += p.contested[0].pixels;
            uncontested += p.uncontested[0].pixels;
            // Multi-view consistency recorded on every class, over pixels of the class.
            for s in [&p.contested[0], &p.uncontested[0]] {
                let c = s.consistency.expect("recorded");
                assert!(c.pixels <= s.pixels && c.squared_error >= 0.0, "{c:?}");
            }
            mutual += p.uncontested[0].consistency.unwrap().pixels;
            let both = p.contested[0].squared_error + p.uncontested[0].squared_error;
            let pixels = p.contested[0].pixels + p.uncontested[0].pixels;
            assert!(pixels <= v.extrapolated.pixels);
            if pixels == v.extrapolated.pixels {
                let want = v.extrapolated.squared_error;
                assert!(
                    (both - want).abs() <= 1e-12 * want.max(1.0),
                    "{both} {want}"
                );
                whole += 1;
            }
        }
        assert!(
            whole > 0,
            "no view with truth depth on every extrapolated pixel"
        );
        assert!(
            mutual > 0,
            "no unseen pixel seen on one surface by a neighbour"
        );
        assert_eq!(
            (contested, uncontested),
            (count(CLASS_CONTESTED), count(CLASS_UNCONTESTED))
        );
        let wrong = audit::pairs::score_pair(&inputs, &g, &g, &classes[1..]);
        assert!(wrong.unwrap_err().to_string().contains("pixel classes for"));
    }
    // The finished audit paired each run with its seed's full run on the run's classes:
    // what `score_pair` gives from the folders; full itself has no pair.
    let pooled = audit::samples::Samples::read(&dir.join(audit::samples::SAMPLES_FILE)).unwrap();
    for v in &pooled.samples {
        if v.variant == "full" {
            assert!(v.pair.is_none());
            continue;
        }
        let f = pooled
            .samples
            .iter()
            .find(|f| f.variant == "full" && f.seed == v.seed)
            .unwrap();
        let pair = v.pair.as_ref().expect("paired");
        assert_eq!(
            (pair.reference.as_str(), &pair.reference_scene),
            ("full", &f.scene_sha256)
        );
        let folder = |variant: &str| {
            dir.join(
                Job::Run {
                    generator: GeneratorKind::by_name(&v.generator).unwrap(),
                    variant: variant.parse::<Variant>().unwrap(),
                    seed: v.seed,
                }
                .folder(),
            )
        };
        let scene = |variant: &str, file: &str| {
            unseen::gaussian::ply::read_ply(&folder(variant).join(file))
                .unwrap()
                .0
        };
        let inputs = unseen::pipeline::load_inputs(
            &dir.join(Job::Original { seed: v.seed }.name()),
            &lounge.join("candidates.json"),
            Some(&lounge.join("evaluation.json")),
            Some(&lounge),
        )
        .unwrap();
        let classes = std::fs::read(folder(&v.variant).join(audit::jobs::CLASSES_FILE)).unwrap();
        let want = audit::pairs::score_pair(
            &inputs,
            &scene("full", &f.final_scene),
            &scene(&v.variant, &v.final_scene),
            &classes,
        )
        .unwrap();
        assert_eq!(pair.views, want);
        // Its contact sheet: four panels of the crop around the contested pixels of its
        // most contested view, when it has any.
        let sheet = dir.join(audit::pairs::sheet_path(&v.generator, &v.variant, v.seed));
        let contested = classes.contains(&unseen::pipeline::evaluate::CLASS_CONTESTED);
        assert_eq!(sheet.is_file(), contested, "{}", sheet.display());
        if contested {
            let img = unseen::io::image::read_png(&sheet).unwrap();
            let panel = img.width - 3 * 4;
            assert!(
                panel.is_multiple_of(4 * audit::pairs::SHEET_SCALE)
                    && img.height.is_multiple_of(audit::pairs::SHEET_SCALE),
                "{}×{}",
                img.width,
                img.height
            );
        }
    }
    let md = std::fs::read_to_string(dir.join("audit.md")).unwrap();
    assert!(md.contains("| truth-low | opacity_mask |"), "{md}");
    assert!(md.contains("same computation 0 of 2"), "{md}");
    assert!(md.contains("## What the step cache saves"), "{md}");
    assert!(md.contains("## The training half per stage"), "{md}");
    assert!(
        md.contains("| within the originals | added Gaussians |"),
        "{md}"
    );
    assert!(md.contains("QA-Mask over opacity maps, existing"));
    assert!(
        md.contains("### Which views moved the Gaussians the original views see")
            && md.contains("| truth-low | full | 2 | stage1 0."),
        "{md}"
    );
    let svg = std::fs::read_to_string(dir.join("inconsistency.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("<circle"));
    // Again: every job is pooled as this binary computes it, so none starts (not even its
    // original scene) and the verdicts are the same.
    let started = std::sync::Mutex::new(Vec::new());
    let on_started = |e| match e {
        Event::Stage { name } => started.lock().unwrap().push(name),
        Event::StepFinished { step, .. } | Event::StepStarted { step } => {
            started.lock().unwrap().push(step)
        }
        _ => {}
    };
    let verdicts = |r: &audit::Report| serde_json::to_string(&r.verdicts).unwrap();
    let pooled = audit::Audit::new(&cfg, &lounge, &dir)
        .unwrap()
        .with_events(&on_started)
        .run(&[])
        .unwrap();
    assert!(started.lock().unwrap().is_empty(), "{started:?}");
    assert!(pooled.results.is_empty());
    assert_eq!(verdicts(&pooled), verdicts(&report));
    // A sample of another crate version is not this binary's computation: its job runs
    // (resuming its folder: nothing is computed) and gives the same bits. Edited as the
    // uncompressed text of a folder written before compression, which the audit reads and
    // replaces.
    let samples = dir.join(audit::samples::SAMPLES_FILE);
    let mut text = String::new();
    std::io::Read::read_to_string(
        &mut flate2::read::GzDecoder::new(&std::fs::read(&samples).unwrap()[..]),
        &mut text,
    )
    .unwrap();
    let one = "\"variant\":\"opacity_mask\",\"seed\":1,\"numerics_revision\"";
    assert_eq!(text.matches(one).count(), 1, "{text}");
    let at = text.find(one).unwrap();
    let version = format!("\"crate_version\":\"{}\"", env!("CARGO_PKG_VERSION"));
    let v = at + text[at..].find(&version).unwrap();
    let edited = format!(
        "{}\"crate_version\":\"0.0.0\"{}",
        &text[..v],
        &text[v + version.len()..]
    );
    let legacy = dir.join(audit::samples::LEGACY_SAMPLES_FILE);
    std::fs::write(&legacy, edited).unwrap();
    std::fs::remove_file(&samples).unwrap();
    let computed = std::sync::Mutex::new(Vec::new());
    let on_computed = |e| {
        if let Event::StepFinished { step, .. } | Event::StepStarted { step } = e {
            computed.lock().unwrap().push(step)
        }
    };
    let again = audit::Audit::new(&cfg, &lounge, &dir)
        .unwrap()
        .with_events(&on_computed)
        .run(&[])
        .unwrap();
    let names = |r: &audit::Report| -> Vec<String> {
        let v = r
            .results
            .iter()
            .map(|j| format!("{}/{}", j.variant, j.seed));
        v.collect()
    };
    assert_eq!(names(&again), ["opacity_mask/1"]);
    assert!(computed.into_inner().unwrap().is_empty());
    assert!(samples.is_file() && !legacy.exists(), "the text replaced");
    let bits = |r: &audit::JobResult| serde_json::to_string(r).unwrap();
    let first = report
        .results
        .iter()
        .find(|r| r.variant == "opacity_mask" && r.seed == 1);
    assert_eq!(bits(first.unwrap()), bits(&again.results[0]));
    assert_eq!(verdicts(&again), verdicts(&report));
    // The samples alone, pooled into another folder, give the same verdicts.
    let elsewhere = t.path().join("elsewhere");
    let pooled = audit::Audit::new(&cfg, &lounge, &elsewhere)
        .unwrap()
        .report(std::slice::from_ref(&samples))
        .unwrap();
    assert_eq!(verdicts(&pooled), verdicts(&report));
    assert_eq!(pooled.samples, 4);
    // Samples of another original-scene training are not pooled (nothing written).
    let other = AuditConfig {
        train_iterations: 301,
        ..cfg.clone()
    };
    let refused = t.path().join("refused");
    let e = audit::Audit::new(&other, &lounge, &refused)
        .unwrap()
        .report(std::slice::from_ref(&samples))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("trained 300 iterations") && e.contains("samples.json"),
        "{e}"
    );
    assert!(!t.path().join("refused").exists());
    // A second batch of seeds adds to the first.
    let more = AuditConfig {
        seeds: 2..3,
        ..cfg.clone()
    };
    let grown = audit::Audit::new(&more, &lounge, &dir)
        .unwrap()
        .run(&[])
        .unwrap();
    assert_eq!((grown.seeds.clone(), grown.samples), (vec![0, 1, 2], 6));
    assert!(
        grown.verdicts.iter().all(|v| v.seeds == 3),
        "{:?}",
        grown.verdicts
    );
    let md = std::fs::read_to_string(dir.join("audit.md")).unwrap();
    assert!(md.contains("3 seeds (0–2) in 6 samples"), "{md}");
}

/// The audit on a room with a single candidate view: `even_views` picks the one view
/// detection picks, both runs evaluate the same scene on every seed, and the claim says
/// *not tested here* (no test, no MDE) instead of judging Δ = 0; each sample records what
/// its run did (SPEC.md §21.5).
#[test]
#[ignore = "slow tier (~15 s): cargo test -- --include-ignored"]
fn a_one_candidate_room_is_the_same_computation_and_not_tested() {
    use unseen::audit::{self, AuditConfig, GeneratorKind, Variant};
    let t = TempDir::new("pipeline-audit-one");
    // The lounge (images and depths linked) with a candidate family of its first bridge
    // view only, which the audit is given by name.
    let room = t.path().join("room");
    std::fs::create_dir_all(room.join("families")).unwrap();
    let lounge = lounge();
    for e in std::fs::read_dir(&lounge).unwrap() {
        let e = e.unwrap();
        let to = room.join(e.file_name());
        if e.file_name() == "families" {
            continue;
        } else if e.path().is_dir() {
            std::os::unix::fs::symlink(e.path(), &to).unwrap();
        } else {
            std::fs::copy(e.path(), &to).unwrap();
        }
    }
    let all: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(lounge.join("candidates.json")).unwrap()).unwrap();
    let first = serde_json::to_string(&all[..1]).unwrap();
    std::fs::write(room.join("families/first.json"), &first).unwrap();
    let generator = GeneratorKind::Truth(unseen::pipeline::Level::Low);
    let cfg = AuditConfig {
        base: PipelineConfig {
            interpolation: false,
            ..tiny_config()
        },
        variants: vec![Variant::Full, Variant::EvenViews],
        generators: vec![generator],
        seeds: 0..2,
        train_iterations: 300,
        train_resolution: 4,
        planned_seeds: 2,
        candidates: Some("first".into()),
    };
    let dir = t.path().join("audit");
    // A family the dataset does not have: refused before any job, naming those it has.
    let missing = AuditConfig {
        candidates: Some("ring-9".into()),
        ..cfg.clone()
    };
    let e = audit::Audit::new(&missing, &room, &dir)
        .and_then(|a| a.run(&[]))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no candidate family 'ring-9'") && e.contains("has first"),
        "{e}"
    );
    assert!(!dir.exists(), "nothing written: {e}");
    let report = audit::Audit::new(&cfg, &room, &dir)
        .unwrap()
        .run(&[])
        .unwrap();
    let family = report.provenance.candidates.as_ref().expect("recorded");
    assert_eq!(family.name, "first");
    assert_eq!(family.sha256, unseen::io::sha256_hex(first.as_bytes()));
    assert_eq!(report.results.len(), 4);
    // Each result records the family (what `--collect` checks a receipt's result against).
    assert!(
        report
            .results
            .iter()
            .all(|r| r.candidates.as_ref() == Some(family))
    );
    for r in &report.results {
        let d = r.diagnostics.as_ref().expect("recorded");
        assert_eq!((d.candidates, d.pairs, d.collisions), (1, 0, 0), "{d:?}");
        assert_eq!((d.stage1_views.len(), d.stage1_collisions), (1, 0), "{d:?}");
        assert_eq!(d.degenerate_gaps, 1, "a one-view tour: {d:?}");
        let g = d.stage1.expect("the view generates some unseen surface");
        assert!(
            g.pixels > 0 && g.coverage > 0.0 && g.coverage <= 1.0,
            "{g:?}"
        );
        assert_eq!(g.overlap, 0.0, "one view overlaps nothing: {g:?}");
        assert!(g.conflict.is_nan(), "{g:?}");
        assert_eq!(r.scene_sha256.len(), 64);
    }
    for seed in 0..2 {
        let of = |v: &str| {
            report
                .results
                .iter()
                .find(|r| r.seed == seed && r.variant == v)
                .unwrap()
        };
        assert_eq!(of("full").scene_sha256, of("even_views").scene_sha256);
    }
    let v = report
        .verdicts
        .iter()
        .find(|v| v.claim.id == "independent views")
        .unwrap();
    assert_eq!((v.judged, v.same_computation), (0, 2), "{v:?}");
    assert!(v.verdict.starts_with("not tested here"), "{v:?}");
    assert!(v.min_detectable.is_nan() && v.p_holm.is_nan(), "{v:?}");
    let md = std::fs::read_to_string(dir.join("audit.md")).unwrap();
    assert!(md.contains("same computation 2 of 2"), "{md}");
    assert!(md.contains("candidates: the family `first`"), "{md}");
    assert!(md.contains("## What each run did"), "{md}");
    assert!(!md.contains("MDE 0.00"), "{md}");
}

/// A sample of the audit with the given PSNR (all classes) of its final scene.
fn sample(variant: &str, seed: u32, revision: u32, psnr: f64) -> unseen::audit::JobResult {
    use unseen::pipeline::evaluate::Row;
    let row = Row {
        scene: "interpolate".into(),
        psnr_all: psnr,
        psnr_existing: psnr,
        psnr_extrapolated: psnr,
        ssim_all: 0.5,
        ssim_existing: 0.5,
        ssim_extrapolated: 0.5,
        psnr_train_half: 30.0,
        ssim_train_half: 0.9,
        gaussians: 1,
        lineage: None,
        views: vec![],
    };
    unseen::audit::JobResult {
        generator: "truth-low".into(),
        variant: variant.into(),
        seed,
        numerics_revision: revision,
        crate_version: "0.1.0".into(),
        config: unseen::audit::AuditConfig::preset(unseen::pipeline::Preset::Quick)
            .config_digest(
                unseen::audit::GeneratorKind::by_name("truth-low").unwrap(),
                variant.parse::<unseen::audit::Variant>().unwrap(),
            )
            .unwrap(),
        original: row.clone(),
        last: row,
        stage_seconds: Default::default(),
        steps: vec![],
        scene_sha256: String::new(),
        final_scene: String::new(),
        pair: None,
        diagnostics: None,
        candidates: None,
        stages: vec![],
    }
}

/// "No deterioration within original areas" (SPEC.md §21.2): full's final scene against
/// its own original scene on the training half, as non-inferiority at the margin; it needs
/// only the `full` runs and is never a same computation.
#[test]
fn the_original_areas_claim_is_non_inferiority_of_the_final_scene_against_the_original() {
    use unseen::audit::{AuditConfig, GeneratorKind, Variant, stats::Rule, verdicts};
    let cfg = AuditConfig {
        variants: vec![Variant::Full],
        generators: vec![GeneratorKind::Truth(unseen::pipeline::Level::Low)],
        ..AuditConfig::quick()
    };
    let judge = |loss: f64| {
        let pool: Vec<_> = (0..16)
            .map(|seed| {
                let mut r = sample("full", seed, 7, 20.0);
                // Spread around the loss, the same scene digest as "itself".
                r.last.psnr_train_half = r.original.psnr_train_half - loss + 0.01 * seed as f64;
                r.scene_sha256 = "a".repeat(64);
                r
            })
            .collect();
        let v = verdicts(&cfg, &pool, &Rule::default());
        assert_eq!(
            v.len(),
            1,
            "only the original-areas claim has its runs: {v:?}"
        );
        v[0].clone()
    };
    let small = judge(0.05);
    assert_eq!(small.claim.id, "no deterioration within original areas");
    assert_eq!(
        (small.judged, small.same_computation, small.null),
        (16, 0, -0.2)
    );
    assert_eq!(small.verdict, "holds", "{small:?}");
    let large = judge(1.0);
    assert_eq!(large.verdict, "contradicted", "{large:?}");
}

/// The recipe's control (issue #72): full's final scene against `originals_only`'s (the
/// same fine-tunes on the original views alone) on the training half, as non-inferiority
/// at the margin; judged only where `originals_only` ran.
#[test]
fn generated_views_are_judged_against_the_recipe_on_the_training_half() {
    use unseen::audit::{AuditConfig, GeneratorKind, Variant, stats::Rule, verdicts};
    let id = "generated views cost original areas nothing beyond the recipe";
    let cfg = |variants| AuditConfig {
        variants,
        generators: vec![GeneratorKind::Truth(unseen::pipeline::Level::Low)],
        ..AuditConfig::quick()
    };
    let judge = |cost: f64| {
        let mut pool = Vec::new();
        for seed in 0..16u32 {
            let mut full = sample("full", seed, 8, 20.0);
            full.last.psnr_train_half = 30.0 - cost + 0.01 * f64::from(seed);
            full.scene_sha256 = format!("{seed:064}");
            let mut control = sample("originals_only", seed, 8, 20.0);
            control.scene_sha256 = format!("{:064}", seed + 100);
            pool.extend([full, control]);
        }
        let v = verdicts(
            &cfg(vec![Variant::Full, Variant::OriginalsOnly]),
            &pool,
            &Rule::default(),
        );
        let c = v.iter().find(|v| v.claim.id == id).cloned();
        let without = verdicts(&cfg(vec![Variant::Full]), &pool, &Rule::default());
        assert!(!without.iter().any(|v| v.claim.id == id));
        c.expect("judged where originals_only ran")
    };
    let small = judge(0.05);
    assert_eq!((small.judged, small.null), (16, -0.2), "{small:?}");
    assert_eq!(small.verdict, "holds", "{small:?}");
    assert_eq!(judge(1.0).verdict, "contradicted");
    assert_eq!(
        "originals_only".parse::<Variant>().unwrap(),
        Variant::OriginalsOnly
    );
}

/// `conflicting_views` where no colliding set qualified (SPEC.md §20.2)
/// generates the independent set, as `full` does, with other random streams: such a seed is
/// not a unit of "conflicts cost at equal coverage" (its Δ would be noise between two runs
/// of one method), and the verdict says on how many seeds the claim was not tested.
#[test]
fn a_conflicting_set_that_was_not_used_is_not_a_unit() {
    use unseen::audit::{AuditConfig, GeneratorKind, Variant, stats::Rule, verdicts};
    let cfg = AuditConfig {
        variants: vec![Variant::Full, Variant::ConflictingViews],
        generators: vec![GeneratorKind::Truth(unseen::pipeline::Level::Low)],
        ..AuditConfig::quick()
    };
    let diagnostics = |used: bool| {
        serde_json::from_value(serde_json::json!({
            "candidates": 12, "covered": 0, "set_aside": [], "collisions": 40, "pairs": 66,
            "stage1_views": ["a", "b"], "stage1_collisions": u32::from(used),
            "dependent_per_gap": [10], "interpolated": 0, "degenerate_gaps": 0,
            "stage1": null, "stage2_filled": 0.1,
            "choice": {"rule": "greedy", "independent": ["a", "b"], "coverage": 100,
                       "conflicting": {"views": ["a", "c"], "coverage": if used { 98 } else { 60 },
                                       "coverage_difference": if used { 0.02 } else { 0.4 },
                                       "used": used}}
        }))
        .unwrap()
    };
    let mut pool = Vec::new();
    for seed in 0..16 {
        let used = seed % 4 != 3; // 12 seeds with a matched set, 4 without
        let mut full = sample("full", seed, 7, 20.0 + 0.1 * seed as f64);
        full.scene_sha256 = format!("{seed:064}");
        let shift = if used { 1.0 } else { -0.5 }; // the unused seeds would pull Δ below 0
        let mut c = sample("conflicting_views", seed, 7, full.last.psnr_all - shift);
        c.scene_sha256 = format!("{:064}", seed + 100);
        c.diagnostics = Some(diagnostics(used));
        pool.extend([full, c]);
    }
    let v = verdicts(&cfg, &pool, &Rule::default());
    let v = v
        .iter()
        .find(|v| v.claim.id == "conflicts cost at equal coverage")
        .unwrap();
    assert_eq!((v.judged, v.same_computation), (12, 4), "{v:?}");
    assert_eq!((v.above, v.below), (12, 0), "{v:?}");
    assert!(v.verdict.contains("not tested on 4 of 16 seeds"), "{v:?}");
}

/// The panel (SPEC.md §21.7): both runs of a pair judged on the variant's contested and
/// uncontested pixels from the variant's `pair`, every Δ oriented so that positive means
/// full is better (GMSD's sign flipped, the detail ratio by its distance from 1), the
/// primary claims in their own Holm family with their uncontested null, the rest in the
/// panel's, the paper's claims untouched; a pair that scored another scene than the
/// pool's full run is no unit; a panel that disagrees with the primary is flagged.
#[test]
fn the_panel_judges_both_runs_on_the_variants_contested_pixels() {
    use unseen::audit::pairs::{Pair, PairView};
    use unseen::audit::{AuditConfig, GeneratorKind, Measure, Variant, stats::Rule, verdicts};
    use unseen::pipeline::evaluate::ClassSums;
    let cfg = AuditConfig {
        variants: vec![Variant::Full, Variant::ConflictingViews],
        generators: vec![GeneratorKind::Truth(unseen::pipeline::Level::Low)],
        ..AuditConfig::quick()
    };
    // Sums of a class of 100 pixels (weight 1 each): squared error `se`, SSIM `ss`, the
    // GMSD deficit's mean `m` and spread `sd`, gradient energy `r` over the truth's 1.
    let sums = |se: f64, ss: f64, m: f64, sd: f64, r: f64| ClassSums {
        pixels: 100,
        squared_error: se,
        ssim_sum: 100.0 * ss,
        gms_weight: 100.0,
        gms_deficit: 100.0 * m,
        gms_deficit_squares: 100.0 * (sd * sd + m * m),
        render_gradient_energy: 100.0 * r,
        truth_gradient_energy: 100.0,
        consistency: None,
    };
    let pool = |mismatched: Option<u32>| {
        let mut pool = Vec::new();
        for seed in 0..16u32 {
            let e = 0.001 * f64::from(seed);
            let mut full = sample("full", seed, 8, 20.0);
            full.scene_sha256 = format!("{seed:064}");
            let mut c = sample("conflicting_views", seed, 8, 20.0);
            c.scene_sha256 = format!("{:064}", seed + 100);
            // On contested pixels the variant averaged two generations: less squared error
            // (PSNR rewards it), a larger GMSD and less detail; on uncontested pixels the
            // two runs differ by noise only.
            let noise = if seed % 2 == 0 { e } else { -e };
            let reference_scene = if mismatched == Some(seed) {
                "another scene".into()
            } else {
                full.scene_sha256.clone()
            };
            c.pair = Some(Pair {
                reference: "full".into(),
                reference_scene,
                views: vec![PairView {
                    view: "v".into(),
                    contested: [
                        sums(3.0, 0.6, 0.1, 0.05, 1.0),
                        sums(2.0 + e, 0.6 - e, 0.1, 0.15 + e, 0.9 - e),
                    ],
                    uncontested: [
                        sums(1.0, 0.8, 0.1, 0.05, 1.01),
                        sums(1.0, 0.8, 0.1, 0.05 + noise, 1.01 + noise),
                    ],
                }],
            });
            // Each run's scene against its own generations: the variant's cannot reproduce
            // both of two disagreeing ones.
            let fidelity = |se: f64| {
                serde_json::from_value(serde_json::json!({
                    "candidates": 4, "covered": 0, "set_aside": [], "collisions": 2, "pairs": 6,
                    "stage1_views": ["a", "b"], "stage1_collisions": 0, "dependent_per_gap": [1],
                    "interpolated": 0, "degenerate_gaps": 0, "stage1": null, "stage2_filled": 0.1,
                    "fidelity": [{"view": "a",
                                  "contested": {"pixels": 50, "squared_error": se, "ssim_sum": 40.0},
                                  "uncontested": {"pixels": 50, "squared_error": se, "ssim_sum": 40.0}}]
                }))
                .unwrap()
            };
            full.diagnostics = Some(fidelity(0.3));
            c.diagnostics = Some(fidelity(0.6 + e));
            pool.extend([full, c]);
        }
        pool
    };
    // A pair that scored another scene than the pool's full run is no Δ: the claim waits
    // for that seed.
    let v = verdicts(&cfg, &pool(Some(15)), &Rule::default());
    let id = "conflicts cost at equal coverage, detail contested";
    let primary = v.iter().find(|v| v.claim.id == id).unwrap();
    assert_eq!(primary.verdict, "interim (15 of 16 seeds)", "{primary:?}");
    // A seed where the variant's views generated no point twice: nowhere for conflicts to
    // act, so counted towards the plan and not as a unit.
    let mut none_contested = pool(None);
    for r in none_contested
        .iter_mut()
        .filter(|r| r.seed == 3 && r.pair.is_some())
    {
        for v in &mut r.pair.as_mut().unwrap().views {
            v.contested = Default::default();
        }
    }
    let v = verdicts(&cfg, &none_contested, &Rule::default());
    let primary = v.iter().find(|v| v.claim.id == id).unwrap();
    assert_eq!(
        (primary.judged, primary.same_computation),
        (15, 1),
        "{primary:?}"
    );
    assert!(
        primary.verdict.contains("not tested on 1 of 16 seeds")
            && primary.verdict.contains("no contested pixel"),
        "{primary:?}"
    );
    let v = verdicts(&cfg, &pool(None), &Rule::default());
    let find = |id: &str| {
        v.iter()
            .find(|v| v.claim.id == id)
            .unwrap_or_else(|| panic!("{id}: {v:#?}"))
    };
    let primary = find("conflicts cost at equal coverage, detail contested");
    assert_eq!(primary.family, "truth-classes");
    // Every seed full closer to 1 by −ln(0.9 − e): the median of 16, the mean of seeds 7
    // and 8's.
    assert_eq!(
        (primary.judged, primary.above, primary.below),
        (16, 16, 0),
        "{primary:?}"
    );
    assert!(primary.verdict.starts_with("holds"), "{primary:?}");
    let want = -0.5 * (0.893f64.ln() + 0.892f64.ln());
    assert!((primary.median_diff - want).abs() < 1e-12, "{primary:?}");
    let null = find("conflicts cost at equal coverage, detail uncontested");
    assert_eq!(null.family, "truth-classes");
    assert!(null.verdict.starts_with("inconclusive"), "{null:?}");
    let psnr = find("conflicts cost at equal coverage, PSNR contested");
    assert_eq!(psnr.family, "truth-panel");
    assert!(psnr.verdict.starts_with("contradicted"), "{psnr:?}");
    // The median of 16 is the mean of seeds 7 and 8's Δ.
    let at = |e: f64| -10.0 * (3.0f64 / 300.0).log10() + 10.0 * ((2.0 + e) / 300.0).log10();
    let want = 0.5 * (at(0.007) + at(0.008));
    assert!((psnr.median_diff - want).abs() < 1e-12, "{psnr:?}");
    // GMSD, lower better: Δ = variant − full = 0.1 + e, in the secondary family.
    let gmsd = find("conflicts cost at equal coverage, GMSD contested");
    assert_eq!(gmsd.family, "truth-panel");
    assert!(gmsd.verdict.starts_with("holds"), "{gmsd:?}");
    assert!((gmsd.median_diff - 0.1075).abs() < 1e-9, "{gmsd:?}");
    // Fidelity: 10·log10 of the squared-error ratio, full better.
    let fid = find("conflicts cost at equal coverage, fidelity to own generations");
    assert_eq!(fid.family, "truth-panel");
    let want = 0.5 * (10.0 * (0.607f64 / 0.3).log10() + 10.0 * (0.608f64 / 0.3).log10());
    assert!((fid.median_diff - want).abs() < 1e-12, "{fid:?}");
    assert!(fid.verdict.starts_with("holds"), "{fid:?}");
    let did = find("conflicts cost at equal coverage, detail contested − uncontested");
    assert!(did.verdict.starts_with("holds"), "{did:?}");
    // The primary holds while PSNR on the same pixels is contradicted: the panel splits.
    let split = primary.panel_splits.as_deref().expect("split flagged");
    assert!(
        split.contains("PSNR contested") && split.contains("contradicted"),
        "{split}"
    );
    assert!(
        !split.contains("GMSD") && !split.contains("detail"),
        "{split}"
    );
    // The paper's claim is judged as before, in its own family.
    let paper = find("conflicts cost at equal coverage");
    assert_eq!(paper.family, "truth");
    assert!(
        paper.verdict.starts_with("no verdict"),
        "Δ = 0 on every seed: {paper:?}"
    );
    // Orientation of each measure.
    assert_eq!(Measure::Gmsd.better(0.1, 0.25), 0.15);
    assert_eq!(Measure::Psnr.better(21.0, 20.0), 1.0);
    assert!((Measure::Detail.better(2.0, 0.25) - (4f64.ln() - 2f64.ln())).abs() < 1e-15);
    assert!(
        v.iter().filter(|v| v.family == "truth-panel").count() == 11,
        "{v:#?}"
    );

    // Pairs recorded before multi-view consistency have no record: its claims skip them.
    assert!(
        !v.iter()
            .any(|v| v.claim.id.contains("multi-view consistency")),
        "{v:#?}"
    );
    // Recorded: each run's renders agree with their neighbours' to `se` on 100 pixels; the
    // variant's less on contested pixels. A seed whose contested pixels no neighbour sees
    // on one surface is nowhere to act.
    let with_consistency = |blind: Option<u32>| {
        let mut pool = pool(None);
        for r in pool.iter_mut().filter(|r| r.pair.is_some()) {
            let (seed, e) = (r.seed, 0.001 * f64::from(r.seed));
            for v in &mut r.pair.as_mut().unwrap().views {
                let c = |pixels: u64, squared_error: f64| {
                    Some(unseen::pipeline::evaluate::Consistency {
                        pixels,
                        squared_error,
                    })
                };
                let contested = if blind == Some(seed) { 0 } else { 100 };
                v.contested[0].consistency = c(contested, 0.3);
                v.contested[1].consistency = c(contested, 0.6 + e);
                v.uncontested[0].consistency = c(100, 0.3);
                v.uncontested[1].consistency = c(100, 0.3 + if seed % 2 == 0 { e } else { -e });
            }
        }
        pool
    };
    let v = verdicts(&cfg, &with_consistency(None), &Rule::default());
    let mvc = |v: &[unseen::audit::Verdict], id: &str| {
        v.iter()
            .find(|v| {
                v.claim.id
                    == format!("conflicts cost at equal coverage, multi-view consistency {id}")
            })
            .cloned()
            .unwrap_or_else(|| panic!("{id}: {v:#?}"))
    };
    let contested = mvc(&v, "contested");
    assert_eq!(contested.family, "truth-panel");
    let want = 0.5 * (10.0 * (0.607f64 / 0.3).log10() + 10.0 * (0.608f64 / 0.3).log10());
    assert!(
        (contested.median_diff - want).abs() < 1e-12,
        "{contested:?}"
    );
    assert!(contested.verdict.starts_with("holds"), "{contested:?}");
    assert!(mvc(&v, "uncontested").verdict.starts_with("inconclusive"));
    assert_eq!(v.iter().filter(|v| v.family == "truth-panel").count(), 14);
    let v = verdicts(&cfg, &with_consistency(Some(3)), &Rule::default());
    let contested = mvc(&v, "contested");
    assert_eq!(
        (contested.judged, contested.same_computation),
        (15, 1),
        "{contested:?}"
    );
    // Each run decides what its own renders see: none on the full run's side is nowhere
    // to act as well (not a planned seed without a Δ, which would keep it interim).
    let mut blind_full = with_consistency(None);
    for r in blind_full.iter_mut().filter(|r| r.seed == 5) {
        for v in r.pair.iter_mut().flat_map(|p| &mut p.views) {
            v.contested[0].consistency = Some(Default::default());
        }
    }
    let contested = mvc(&verdicts(&cfg, &blind_full, &Rule::default()), "contested");
    assert_eq!(
        (contested.judged, contested.same_computation),
        (15, 1),
        "{contested:?}"
    );

    // The report: its own section with each metric's unit, the split, the names in JSON.
    let lounge = reference("scenes/lounge");
    let tmp = TempDir::new("panel-report");
    let mut samples = unseen::audit::samples::Samples::new(unseen::audit::samples::Provenance {
        dataset: "lounge".into(),
        dataset_digest: unseen::audit::samples::dataset_digest(&lounge).unwrap(),
        preset: cfg.base.preset,
        train_iterations: cfg.train_iterations,
        train_resolution: cfg.train_resolution,
        candidates: None,
    });
    for r in pool(None) {
        samples.insert(r);
    }
    samples
        .write(&tmp.join(unseen::audit::samples::SAMPLES_FILE))
        .unwrap();
    unseen::audit::Audit::new(&cfg, &lounge, &tmp)
        .unwrap()
        .report(&[])
        .unwrap();
    let md = std::fs::read_to_string(tmp.join("audit.md")).unwrap();
    let section = md
        .split("## Where conflicts act")
        .nth(1)
        .expect("the panel's section");
    assert!(
        section.contains("| conflicting_views | **detail ratio contested** | truth-low | truth-classes | 16 | +0.1137 | 16 / 0 |"),
        "{section}"
    );
    assert!(
        section.contains("PSNR contested -1.74 dB (contradicted)"),
        "{section}"
    );
    let claims = md
        .split("## Claims")
        .nth(1)
        .unwrap()
        .split("## ")
        .next()
        .unwrap();
    assert!(
        !claims.contains("GMSD"),
        "the paper's table holds its claims only: {claims}"
    );
    let json = std::fs::read_to_string(tmp.join("audit.json")).unwrap();
    assert!(json.contains("\"metric\": \"detail_contested\""), "{json}");
    assert!(json.contains("\"metric\": \"psnr_diff_in_diff\""), "{json}");
}

/// A dose–response sweep (SPEC.md §21.6): each level is a generator judged as any other
/// (Holm within the sweep), and the response of a claim whose Δ falls with the level
/// crosses 0 between the levels around the sign change, with a plot.
#[test]
fn a_sweep_gives_each_claim_its_response_and_crossing() {
    use unseen::audit::dose::{DoseParam, plot, plot_name, responses};
    use unseen::audit::{AuditConfig, GeneratorKind, Variant, stats::Rule, verdicts};
    let levels = [0u8, 25, 50, 75, 100];
    let cfg = AuditConfig {
        variants: vec![Variant::Full, Variant::EvenViews],
        generators: levels
            .iter()
            .map(|&percent| GeneratorKind::Dose {
                param: DoseParam::Hallucination,
                percent,
            })
            .collect(),
        ..AuditConfig::quick()
    };
    let mut pool = Vec::new();
    for &g in &cfg.generators {
        let GeneratorKind::Dose { percent, .. } = g else {
            unreachable!()
        };
        // Δ = 1 − 4·level ± 0.1: +1 dB at none, −3 dB at full; crosses 0 at 0.25.
        for seed in 0..16u32 {
            let d = 1.0 - 4.0 * f64::from(percent) / 100.0 + 0.01 * f64::from(seed % 5) - 0.02;
            for (variant, psnr) in [("full", 20.0 + d), ("even_views", 20.0)] {
                let mut r = sample(variant, seed, 7, psnr);
                r.generator = g.name();
                r.config = cfg
                    .config_digest(g, variant.parse::<Variant>().unwrap())
                    .unwrap();
                pool.push(r);
            }
        }
    }
    let v = verdicts(&cfg, &pool, &Rule::default());
    let family: Vec<&str> = v.iter().map(|x| x.family.as_str()).collect();
    assert!(
        family.iter().all(|f| *f == "dose-hallucination"),
        "{family:?}"
    );
    let r = responses(&v);
    let views = r.iter().find(|r| r.claim == "independent views").unwrap();
    assert_eq!(views.levels.len(), 5);
    assert_eq!(views.levels[0].verdict, "holds");
    assert_eq!(views.levels[4].verdict, "contradicted");
    assert!((views.crossing - 0.25).abs() < 0.01, "{views:?}");
    let [lo, hi] = views.crossing_range;
    assert!(
        lo.unwrap() <= views.crossing && views.crossing <= hi.unwrap(),
        "{views:?}"
    );
    assert_eq!(plot_name(views), "dose-hallucination-independent-views.svg");
    let svg = plot(views);
    assert!(svg.starts_with("<svg") && svg.matches("<circle").count() == 5);
}

/// The sensitivity rows (SPEC.md §21.2): the independent-views claim under a choice the
/// paper leaves open compares `full` and `even_views` both under that choice, never with
/// the default `full`; every variant's name round-trips and sets its switches.
#[test]
fn sensitivity_rows_compare_full_and_even_views_under_the_same_choice() {
    use unseen::audit::{AuditConfig, GeneratorKind, Variant, stats::Rule, verdicts};
    use unseen::collide::frustum::Outline;
    use unseen::pipeline::selection::SelectionRule;
    // Every variant is named once, round-trips, and is in exactly one of the lists.
    let listed: Vec<Variant> = Variant::PRESET
        .into_iter()
        .chain(Variant::SENSITIVITY)
        .chain(Variant::CONTROLS)
        .collect();
    assert_eq!(listed, Variant::ALL);
    for v in Variant::ALL {
        assert_eq!(v.name().parse::<Variant>().unwrap(), v);
    }
    assert!(
        "nope"
            .parse::<Variant>()
            .unwrap_err()
            .to_string()
            .contains("unknown variant 'nope'")
    );
    let g = GeneratorKind::Truth(unseen::pipeline::Level::Low);
    let cfg = AuditConfig {
        variants: vec![
            Variant::Full,
            Variant::EvenViews,
            Variant::FullMaxCardinality,
            Variant::EvenViewsMaxCardinality,
            Variant::FullHull,
        ],
        generators: vec![g],
        ..AuditConfig::quick()
    };
    let pc = |v| cfg.pipeline_config(g, v, 0).unwrap();
    let even = pc(Variant::EvenViewsMaxCardinality);
    assert!(!even.independent_detection && even.selection == SelectionRule::MaxCardinality);
    assert_eq!(pc(Variant::FullHull).frustum_outline, Outline::Hull);
    assert!(pc(Variant::FullHull).independent_detection);
    // Default full 1 dB above its even views, max-cardinality full 1 dB below its own.
    let mut pool = Vec::new();
    for seed in 0..16u32 {
        let jitter = 0.01 * f64::from(seed);
        for (v, psnr) in [
            (Variant::Full, 21.0 + jitter),
            (Variant::EvenViews, 20.0),
            (Variant::FullMaxCardinality, 19.0 + jitter),
            (Variant::EvenViewsMaxCardinality, 20.0),
            (Variant::FullHull, 20.0),
        ] {
            let mut r = sample(v.name(), seed, 7, psnr);
            r.config = cfg.config_digest(g, v).unwrap();
            pool.push(r);
        }
    }
    let v = verdicts(&cfg, &pool, &Rule::default());
    let of = |id: &str| v.iter().find(|x| x.claim.id == id).unwrap().clone();
    assert_eq!(of("independent views").verdict, "holds");
    let sensitive = of("independent views (maximum-cardinality set)");
    assert_eq!(sensitive.verdict, "contradicted", "{sensitive:?}");
    assert!(sensitive.median_diff < -0.9);
    // The sensitivity rows are a Holm family of their own: the paper's claim gets the
    // p-value it gets without them.
    assert_eq!(
        (
            of("independent views").family.as_str(),
            sensitive.family.as_str()
        ),
        ("truth", "truth-sensitivity")
    );
    let alone = AuditConfig {
        variants: vec![Variant::Full, Variant::EvenViews],
        ..cfg.clone()
    };
    let pool_alone: Vec<_> = pool
        .iter()
        .filter(|r| r.variant == "full" || r.variant == "even_views")
        .cloned()
        .collect();
    let v_alone = verdicts(&alone, &pool_alone, &Rule::default());
    assert_eq!(
        v_alone[0].p_holm.to_bits(),
        of("independent views").p_holm.to_bits()
    );
    // The hull row needs its even views: not run, no row.
    assert!(
        !v.iter()
            .any(|x| x.claim.id == "independent views (hull frustums)")
    );
}

/// The verdicts of pooled samples (SPEC.md §21.2): a unit is a seed at a revision, a pair
/// another revision reproduced bit for bit counts once, a claim below its planned sample is
/// an interim look (the lounge case of the old rule, −0.68 ± 0.45 dB over 3 seeds, is no
/// longer *holds*), a "does not hurt" claim is tested against the margin and a loss beyond
/// it that the planned twelve units show is *contradicted*, seeds beyond the plan are
/// judged nowhere, and identical differences give no verdict.
#[test]
fn audit_verdicts_pool_seeds_and_revisions_and_test_non_inferiority() {
    use unseen::audit::{AuditConfig, GeneratorKind, Variant, stats::Rule, verdicts};
    let cfg = AuditConfig {
        variants: vec![Variant::Full, Variant::NoQaMask],
        generators: vec![GeneratorKind::Truth(unseen::pipeline::Level::Low)],
        ..AuditConfig::quick()
    };
    let rule = Rule::default();
    let claim = |v: &[unseen::audit::Verdict], id: &str| {
        v.iter().find(|x| x.claim.id == id).unwrap().clone()
    };
    // Three seeds at revision 3, Δ = −0.2, −0.7, −1.15 (mean −0.68, sd 0.48).
    let mut pool = Vec::new();
    for (seed, d) in [(0, -0.2), (1, -0.7), (2, -1.15)] {
        pool.push(sample("full", seed, 3, 20.0 + d));
        pool.push(sample("no_qa_mask", seed, 3, 20.0));
    }
    let v = verdicts(&cfg, &pool, &rule);
    let ni = claim(&v, "QA-Mask does not hurt extrapolation");
    assert_eq!((ni.seeds, ni.judged, ni.null), (3, 3, -0.2));
    assert!((ni.mean_diff + 0.6833333).abs() < 1e-6, "{ni:?}");
    // (19.8 − 20 rounds to just above −0.2: that seed counts above the null value.)
    assert!(
        (ni.median_diff + 0.7).abs() < 1e-9 && ni.below == 2,
        "{ni:?}"
    );
    assert_eq!(ni.verdict, "interim (3 of 16 seeds)", "{ni:?}");
    // Three seeds cannot reach the family's Holm level (2/8 > 0.05/3): no interval of the
    // median, an infinite MDE.
    assert!(
        ni.ci.is_none() && ni.min_detectable == f64::INFINITY,
        "{ni:?}"
    );
    // The same three seeds recomputed at revision 4 with the same metrics bits (and the
    // per-view records revision 3 did not write): one draw each.
    let record = |psnr: f64| {
        let sums = unseen::pipeline::evaluate::ClassSums {
            pixels: 1,
            squared_error: 3.0 * 10f64.powf(-psnr / 10.0),
            ssim_sum: 0.5,
            ..Default::default()
        };
        unseen::pipeline::evaluate::ViewRecord {
            view: "v".into(),
            all: sums,
            existing: sums,
            extrapolated: sums,
        }
    };
    for (seed, d) in [(0, -0.2), (1, -0.7), (2, -1.15)] {
        for (variant, psnr) in [("full", 20.0 + d), ("no_qa_mask", 20.0)] {
            let mut s = sample(variant, seed, 4, psnr);
            s.last.views.push(record(psnr));
            pool.push(s);
        }
    }
    let again = claim(
        &verdicts(&cfg, &pool, &rule),
        "QA-Mask does not hurt extrapolation",
    );
    assert_eq!(
        (again.seeds, again.revisions.clone()),
        (3, vec![4]),
        "{again:?}"
    );
    // The draw kept is the one with the records: the views bootstrap runs on all three.
    assert_eq!(again.hierarchical_units, 3, "{again:?}");
    // Nine more seeds at revision 4 and four of the first seeds at revision 5 (other
    // bits: another draw of those seeds, averaged into them): twelve units, with a plan of
    // twelve a loss beyond the margin is contradicted. All with per-view records: the
    // hierarchical interval (from ten units) runs on the newest draw of each seed.
    let with_record = |variant: &str, seed: u32, revision: u32, psnr: f64| {
        let mut s = sample(variant, seed, revision, psnr);
        s.last.views.push(record(psnr));
        s
    };
    for seed in 3..12 {
        let d = -0.68 + 0.05 * (seed as f64 - 7.5);
        pool.push(with_record("full", seed, 4, 20.0 + d));
        pool.push(with_record("no_qa_mask", seed, 4, 20.0));
    }
    for seed in 0..4 {
        let d = -0.6 - 0.03 * seed as f64;
        pool.push(with_record("full", seed, 5, 20.1 + d));
        pool.push(with_record("no_qa_mask", seed, 5, 20.1));
    }
    // A revision that changed only one run of a pair gives no independent draw: seed 4 at
    // revision 5 shares its no_qa_mask run with revision 4's and is not counted.
    pool.push(sample("full", 4, 5, 19.0));
    pool.push(sample("no_qa_mask", 4, 5, 20.0));
    assert_eq!(
        claim(
            &verdicts(&cfg, &pool, &rule),
            "QA-Mask does not hurt extrapolation"
        )
        .verdict,
        "interim (12 of 16 seeds)"
    );
    let rule = Rule {
        planned: 12,
        ..Rule::default()
    };
    let v = verdicts(&cfg, &pool, &rule);
    let ni = claim(&v, "QA-Mask does not hurt extrapolation");
    assert_eq!((ni.seeds, ni.revisions.clone()), (12, vec![4, 5]), "{ni:?}");
    // Seed 0's unit is the mean of its two draws (−0.2 at revision 4, −0.6 at 5): the
    // twelve units' mean is the mean of the seed means.
    let pairs = unseen::audit::pairs(&pool, "truth-low", Variant::NoQaMask);
    let means = unseen::audit::seed_means(&pairs, unseen::audit::Metric::PsnrExtrapolated);
    assert_eq!(means.len(), 12);
    assert!((means[0] + 0.4).abs() < 1e-9, "{means:?}");
    assert!((ni.mean_diff - means.iter().sum::<f64>() / 12.0).abs() < 1e-12);
    assert_eq!(ni.method, Some(unseen::audit::stats::Method::Sign));
    // Eleven units with records (seed 4's draw kept is revision 5's, written without);
    // one view each, so the interval lies within the newest draws' differences.
    let [lo, hi] = ni.hierarchical.expect("eleven units");
    assert_eq!(ni.hierarchical_units, 11, "{ni:?}");
    assert!(-0.71 < lo && lo < hi && hi < -0.5, "{ni:?}");
    // Every unit below −0.2: p = 2·2⁻¹², ×3 by Holm.
    assert_eq!((ni.above, ni.below), (0, 12), "{ni:?}");
    assert!((ni.p_holm - 3.0 * 2.0 / 4096.0).abs() < 1e-15, "{ni:?}");
    assert_eq!(ni.verdict, "contradicted", "{ni:?}");
    // The three claims on no_qa_mask are one Holm family; the "better" claims see the
    // same loss and are contradicted too.
    for id in ["QA-Mask (whole image)", "QA-Mask protects existing regions"] {
        assert_eq!(claim(&v, id).verdict, "contradicted");
    }
    // Seeds beyond the plan are judged nowhere: eight more that gain 1 dB change nothing
    // but the count.
    let mut more = pool.clone();
    for seed in 12..20 {
        more.push(sample("full", seed, 4, 21.0));
        more.push(sample("no_qa_mask", seed, 4, 20.0));
    }
    let beyond = claim(
        &verdicts(&cfg, &more, &rule),
        "QA-Mask does not hurt extrapolation",
    );
    assert_eq!((beyond.seeds, beyond.judged), (20, 12));
    assert_eq!(
        (beyond.verdict.as_str(), beyond.p_holm, beyond.mean_diff),
        (ni.verdict.as_str(), ni.p_holm, ni.mean_diff)
    );
    // One seed: interim, no interval.
    let one = verdicts(&cfg, &pool[..2], &Rule::default());
    assert_eq!(one[0].verdict, "interim (1 of 16 seeds)");
    assert!(one[0].ci.is_none());
    // Twelve seeds whose runs agree bit for bit (Δ = 0), or differ by the same amount on
    // every seed: no verdict, whatever the plan.
    for (d, why) in [
        (
            0.0,
            "no verdict (Δ = 0 on every seed: the variant computes what full computes)",
        ),
        (
            0.5,
            "no verdict (the same Δ on every seed: one draw, not n)",
        ),
    ] {
        let same: Vec<_> = (0..12)
            .flat_map(|seed| {
                [
                    sample("full", seed, 4, 20.0 + d),
                    sample("no_qa_mask", seed, 4, 20.0),
                ]
            })
            .collect();
        let v: Vec<_> = verdicts(&cfg, &same, &rule)
            .into_iter()
            .filter(|x| x.claim.variant == Variant::NoQaMask)
            .collect();
        assert!(v.iter().all(|x| x.verdict == why), "{v:?}");
        assert!(
            v.iter()
                .all(|x| x.min_detectable.is_nan() && x.p_holm.is_nan())
        );
    }
}

/// Evenly spaced views (the ablation of independent view detection) with the classical
/// slots: a stage-2 clip `morph` cannot make is recorded and left out, the run finishes.
#[test]
fn a_clip_the_video_slot_cannot_make_is_left_out() {
    let t = TempDir::new("pipeline-failed-clip");
    let Tiny { inp, cfg, .. } = TinyRun::new()
        .config(|c| {
            c.slots = SlotNames::default();
            c.independent_detection = false;
        })
        .build(&t);
    let out = t.path().join("out");
    let o = pipeline::run(&cfg, &inp, &out, false, &quiet).unwrap();
    assert!(o.scene.is_some());
    let list: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("stage2/videos/videos.json")).unwrap())
            .unwrap();
    let (made, failed) = (
        list["made"].as_array().unwrap().len(),
        list["failed_clips"].as_array().unwrap().len(),
    );
    assert_eq!(made + failed, list["pairs"].as_array().unwrap().len());
    // This configuration has such a clip (measured: 11 made, 1 failed), so the test runs
    // the path it is about; before, the whole run stopped on it.
    assert!(failed >= 1 && made >= 1, "made {made}, failed {failed}");
}

/// `unseen audit` with bad input: one line naming what is wrong, nothing written.
#[test]
fn cli_audit_bad_input_is_one_clear_error() {
    let t = TempDir::new("pipeline-cli-audit");
    let a_file = t.path().join("a_file");
    std::fs::write(&a_file, "x").unwrap();
    let lounge = lounge();
    let cases: Vec<(&str, Vec<std::ffi::OsString>, &str)> = vec![
        ("no candidates", vec![t.path().into()], "candidates.json"),
        (
            "unknown variant",
            vec![
                lounge.clone().into(),
                "--variants".into(),
                "full,bogus".into(),
            ],
            "unknown variant 'bogus'",
        ),
        (
            "unknown generator",
            vec![
                lounge.clone().into(),
                "--generators".into(),
                "truth-medium".into(),
            ],
            "unknown generator 'truth-medium'",
        ),
        (
            "no full variant",
            vec![
                lounge.clone().into(),
                "--variants".into(),
                "no_qa_mask".into(),
            ],
            "include the variant 'full'",
        ),
        (
            "unknown candidate family",
            vec![
                lounge.clone().into(),
                "--candidates".into(),
                "ring-99".into(),
            ],
            "no candidate family 'ring-99' (families/ring-99.json); this dataset has ring-13, ring-7, walk-0, walk-1",
        ),
        (
            "bad family name",
            vec![
                lounge.clone().into(),
                "--candidates".into(),
                "../candidates".into(),
            ],
            "'../candidates' is not a candidate family name",
        ),
        (
            "job before its original",
            vec![
                lounge.clone().into(),
                "--only".into(),
                "runs/truth-low/full/seed-0".into(),
            ],
            "original/seed-0",
        ),
        (
            "duplicate variant",
            vec![
                lounge.clone().into(),
                "--variants".into(),
                "full,full".into(),
            ],
            "listed twice",
        ),
        (
            "no candidates, one job",
            vec![t.path().into(), "--only".into(), "original/seed-0".into()],
            "candidates.json",
        ),
        (
            "unknown job",
            vec![lounge.clone().into(), "--only".into(), "runs/x".into()],
            "no job 'runs/x'",
        ),
        (
            "empty seed range",
            vec![lounge.clone().into(), "--seeds".into(), "3..3".into()],
            "the seed range '3..3' is empty",
        ),
        (
            "merge file missing",
            vec![
                lounge.clone().into(),
                "--merge".into(),
                t.path().join("nowhere.json").into(),
            ],
            "nowhere.json",
        ),
        (
            "merge file not samples",
            vec![
                lounge.clone().into(),
                "--merge".into(),
                a_file.clone().into(),
            ],
            "not JSON",
        ),
        (
            "report of nothing",
            vec![lounge.clone().into(), "--report-only".into()],
            "no samples to report",
        ),
    ];
    for (what, args, words) in cases {
        let out = t.path().join(format!("out-{}", what.replace(' ', "-")));
        let st = Command::new(env!("CARGO_BIN_EXE_unseen"))
            .arg("audit")
            .args(&args)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&st.stderr);
        assert!(!st.status.success(), "{what}: succeeded");
        assert_eq!(err.trim().lines().count(), 1, "{what}: {err}");
        assert!(err.contains(words), "{what}: {err}");
        assert!(!out.exists(), "{what}: left {}", out.display());
    }
    let st = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .arg("audit")
        .arg(&lounge)
        .arg("--out")
        .arg(&a_file)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(!st.status.success() && err.contains("is a file"), "{err}");
    assert_eq!(std::fs::read_to_string(&a_file).unwrap(), "x");
    // `--list`: the originals, then one job per generator × variant (quick: 2 × 9).
    let st = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .arg("audit")
        .arg(&lounge)
        .arg("--out")
        .arg(t.path().join("listed"))
        .arg("--list")
        .output()
        .unwrap();
    let jobs = String::from_utf8_lossy(&st.stdout);
    assert!(st.status.success());
    // One original, 12 variants × 2 generators.
    assert_eq!(jobs.lines().count(), 25, "{jobs}");
    assert_eq!(jobs.lines().next(), Some("original/seed-0"));
    assert!(jobs.contains("runs/truth-low/even_views/seed-0"));
    assert!(!t.path().join("listed").exists());
}

/// `samples.json.gz` read back: the same samples, and the same bits for the same samples;
/// its text uncompressed (a folder written before compression) reads the same; damaged
/// (truncated anywhere, compressed or not, another format, a sample listed twice or without
/// its revision), a clear error naming the file; extreme values parse and are judged
/// without a panic.
#[test]
fn audit_samples_round_trip_and_damaged_files_are_clear_errors() {
    use unseen::audit::samples::{Provenance, Samples};
    use unseen::audit::{AuditConfig, stats::Rule, verdicts};
    let t = TempDir::new("pipeline-audit-samples");
    let mut s = Samples::new(Provenance {
        dataset: "lounge".into(),
        dataset_digest: "ab".repeat(32),
        preset: unseen::pipeline::Preset::Quick,
        train_iterations: 1500,
        train_resolution: 2,
        candidates: None,
    });
    for seed in 0..3 {
        s.insert(sample("full", seed, 4, 20.0 + seed as f64 * 0.1));
        s.insert(sample("no_qa_mask", seed, 4, 20.0));
    }
    let path = t.path().join(unseen::audit::samples::SAMPLES_FILE);
    s.write(&path).unwrap();
    assert_eq!(Samples::read(&path).unwrap(), s);
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(&bytes[..2], &[0x1f, 0x8b], "gzip");
    s.write(&path).unwrap();
    assert_eq!(
        std::fs::read(&path).unwrap(),
        bytes,
        "no time stamp in the bytes"
    );
    let gunzip = |b: &[u8]| {
        let mut text = String::new();
        std::io::Read::read_to_string(&mut flate2::read::GzDecoder::new(b), &mut text).unwrap();
        text
    };
    let legacy = t.path().join(unseen::audit::samples::LEGACY_SAMPLES_FILE);
    std::fs::write(&legacy, gunzip(&bytes)).unwrap();
    assert_eq!(Samples::read(&legacy).unwrap(), s, "uncompressed text");
    // Pools of what another dataset, candidate family, preset or training measures are
    // refused, naming what differs.
    let other = |f: &dyn Fn(&mut Provenance)| {
        let mut o = s.clone();
        f(&mut o.provenance);
        let e = s.clone().pool(o, &path).unwrap_err().to_string();
        assert!(e.contains("samples.json.gz"), "{e}");
        e
    };
    let family = unseen::audit::family::Family {
        name: "ring-7".into(),
        sha256: "cd".repeat(32),
    };
    let e = other(&|p| p.candidates = Some(family.clone()));
    assert!(
        e.contains("candidate family 'ring-7' (cdcdcdcdcdcd…), not the bundled candidates"),
        "{e}"
    );
    assert!(other(&|p| p.dataset_digest = "ef".repeat(32)).contains("other content"));
    assert!(other(&|p| p.preset = unseen::pipeline::Preset::Paper).contains("preset 'paper'"));
    assert!(other(&|p| p.train_iterations = 30_000).contains("30000 iterations"));
    let mut same = s.clone();
    same.pool(s.clone(), &path).unwrap();
    assert_eq!(same, s, "pooling a pool with itself changes nothing");
    let mut fam = s.clone();
    fam.provenance.candidates = Some(family);
    fam.write(&path).unwrap();
    assert_eq!(Samples::read(&path).unwrap(), fam, "the family round-trips");
    let damaged = t.path().join("family.json");
    let text = gunzip(&std::fs::read(&path).unwrap());
    std::fs::write(&damaged, text.replace(&"cd".repeat(32), "aéééé")).unwrap();
    let e = Samples::read(&damaged).unwrap_err().to_string();
    assert!(
        e.contains("family.json") && e.contains("64 hex digits"),
        "{e}"
    );
    s.write(&path).unwrap();
    let gz = std::fs::read(&path).unwrap();
    let text = gunzip(&gz);
    assert_eq!(
        text.lines().filter(|l| l.contains("\"seed\"")).count(),
        6,
        "one per line"
    );
    let bad = t.path().join("bad.json");
    let mut cases: Vec<(String, String)> = (1..text.len())
        .step_by(41)
        .filter(|&i| text.is_char_boundary(i))
        .map(|i| (format!("cut at {i}"), text[..i].to_string()))
        .collect();
    cases.push((
        "format".into(),
        text.replace("unseen-audit-samples/1", "unseen-audit-samples/9"),
    ));
    cases.push((
        "revision 0".into(),
        text.replacen("\"numerics_revision\":4", "\"numerics_revision\":0", 1),
    ));
    cases.push(("twice".into(), text.replacen("\"seed\":1", "\"seed\":0", 2)));
    for (what, body) in cases {
        std::fs::write(&bad, body).unwrap();
        let e = Samples::read(&bad).unwrap_err().to_string();
        assert!(e.contains("bad.json"), "{what}: {e}");
    }
    // The compressed file cut anywhere after its magic bytes, or with a byte of its
    // stream or check sum flipped.
    let bad_gz = t.path().join("bad.json.gz");
    let mut flipped = gz.clone();
    let n = flipped.len();
    flipped[n - 6] ^= 0x40;
    let cuts = (2..gz.len()).step_by(7).map(|i| gz[..i].to_vec());
    for body in cuts.chain([flipped]) {
        std::fs::write(&bad_gz, &body).unwrap();
        let e = Samples::read(&bad_gz).unwrap_err().to_string();
        assert!(e.contains("bad.json.gz"), "{} bytes: {e}", body.len());
    }
    // Extreme values: parse, and the statistics do not panic.
    let mut s2 = s.clone();
    s2.insert(sample("full", u32::MAX, 4, 1e308));
    s2.insert(sample("no_qa_mask", u32::MAX, 4, -1e308));
    s2.insert(sample("full", u32::MAX - 1, 4, f64::NAN));
    s2.insert(sample("no_qa_mask", u32::MAX - 1, 4, 0.0));
    s2.write(&path).unwrap();
    let back = Samples::read(&path).unwrap();
    let cfg = AuditConfig {
        generators: vec![unseen::audit::GeneratorKind::Truth(
            unseen::pipeline::Level::Low,
        )],
        ..AuditConfig::quick()
    };
    let v = verdicts(&cfg, &back.samples, &Rule::default());
    assert!(!v.is_empty());
}

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

/// The PSNR of identical images is +∞ (SPEC.md §20.7): metrics files write it as `"inf"`
/// (`io::json_float`), read it back as +∞ bit for bit — `null` stays NaN, an empty class —
/// and the tables print "∞".
#[test]
fn psnr_of_identical_images_is_infinity_in_json_and_reports() {
    use unseen::pipeline::evaluate::{ClassSums, Row, Summary};
    let x = vec![0.25f32; 30];
    let inf = unseen::train::loss::psnr(&x, &x);
    assert_eq!(inf, f64::INFINITY);
    let exact = ClassSums {
        pixels: 10,
        squared_error: 0.0,
        ssim_sum: 10.0,
        ..Default::default()
    };
    assert_eq!(ClassSums::psnr([&exact]), f64::INFINITY);
    let row = Row {
        scene: "stage2".into(),
        psnr_all: inf,
        psnr_existing: inf,
        psnr_extrapolated: f64::NAN,
        ssim_all: 1.0,
        ssim_existing: 1.0,
        ssim_extrapolated: f64::NAN,
        psnr_train_half: 31.5,
        ssim_train_half: 0.9,
        gaussians: 7,
        lineage: None,
        views: Vec::new(),
    };
    let s = Summary {
        evaluation_views: 1,
        existing_fraction: 1.0,
        rows: vec![row],
    };
    let text = serde_json::to_string(&s).unwrap();
    assert!(text.contains("\"psnr_all\":\"inf\""), "{text}");
    assert!(text.contains("\"psnr_extrapolated\":null"), "{text}");
    let back: Summary = serde_json::from_str(&text).unwrap();
    let r = &back.rows[0];
    assert_eq!(r.psnr_all, f64::INFINITY);
    assert!(r.psnr_extrapolated.is_nan());
    assert_eq!(r.psnr_train_half.to_bits(), 31.5f64.to_bits());
    assert!(
        back.table().contains("| stage2 | ∞ | NaN | ∞ |"),
        "{}",
        back.table()
    );
    let e = unseen::eval::EvalReport {
        split: unseen::dataset::Split::Test,
        views: vec![unseen::eval::ViewMetrics {
            name: "v".into(),
            psnr: inf,
            ssim: 1.0,
        }],
        mean_psnr: inf,
        mean_ssim: 1.0,
    };
    let back: unseen::eval::EvalReport =
        serde_json::from_str(&serde_json::to_string(&e).unwrap()).unwrap();
    assert_eq!(back, e);
    assert!(back.table().contains("**∞**"));
}

/// Damage on disk (SPEC.md §20.8): a byte flipped in a finished step's file, a truncated
/// manifest, a deleted file, an interrupted step (a folder without manifest), and a
/// damaged step-cache entry. `--resume` (and a run reading the cache) finds each by hash,
/// names the step and the fault, recomputes it, and ends with the same bits as an
/// undamaged run.
#[test]
fn damaged_steps_and_cache_entries_are_named_recomputed_and_end_in_the_same_bits() {
    let t = TempDir::new("pipeline-damage");
    let Tiny { inp, cfg, .. } = TinyRun::new().config(|c| c.interpolation = false).build(&t);
    let reference = t.path().join("reference");
    pipeline::run(&cfg, &inp, &reference, false, &quiet).unwrap();
    let a = t.path().join("a");
    pipeline::run(&cfg, &inp, &a, false, &quiet).unwrap();
    let first = |dir: &Path, suffix: &str| {
        walk(dir)
            .into_iter()
            .filter(|p| p.to_string_lossy().ends_with(suffix))
            .min()
            .unwrap()
    };
    // A flipped byte (written in place), a truncated manifest, a deleted file, and a
    // step folder left without its manifest.
    let flipped = first(&a.join("views"), "render.png");
    let mut b = std::fs::read(&flipped).unwrap();
    let k = b.len() / 2;
    b[k] ^= 0x40;
    std::fs::write(&flipped, &b).unwrap();
    let manifest = a.join("stage1/recon/manifest.json");
    let m = std::fs::read(&manifest).unwrap();
    std::fs::write(&manifest, &m[..m.len() / 3]).unwrap();
    let deleted = first(&a.join("stage2/dependent"), "inpaint.png");
    std::fs::remove_file(&deleted).unwrap();
    std::fs::remove_file(a.join("stage2/videos/manifest.json")).unwrap();
    let notes = std::sync::Mutex::new(Vec::new());
    let collect = |e: Event| {
        if let Event::Note(n) = e {
            notes.lock().unwrap().push(n)
        }
    };
    pipeline::run(&cfg, &inp, &a, true, &collect).unwrap();
    let notes = notes.into_inner().unwrap();
    let said = |step: &str, words: &str| {
        notes.iter().any(|n| {
            n.starts_with(&format!("{step}: ")) && n.contains(words) && n.ends_with("recomputed")
        })
    };
    let rel = |p: &Path, step: &str| {
        p.strip_prefix(a.join(step))
            .unwrap()
            .to_string_lossy()
            .into_owned()
    };
    assert!(
        said(
            "views",
            &format!("{} does not match its sha256", rel(&flipped, "views"))
        ),
        "{notes:?}"
    );
    assert!(
        said("stage1/recon", "manifest.json is damaged"),
        "{notes:?}"
    );
    assert!(
        said(
            "stage2/dependent",
            &format!("{} cannot be read", rel(&deleted, "stage2/dependent"))
        ),
        "{notes:?}"
    );
    assert!(said("stage2/videos", "interrupted"), "{notes:?}");
    let c = compare(&reference, &a, 0.0).unwrap();
    assert!(c.steps.iter().all(|s| s.identical), "{}", c.table());

    // The step cache: an entry with a flipped byte is not copied — the run says so,
    // computes the step, and ends with the same bits.
    let cache = t.path().join("cache");
    let opts = unseen::pipeline::RunOptions {
        cache: Some(cache.clone()),
        ..Default::default()
    };
    pipeline::run_with(&cfg, &inp, &t.path().join("c"), &opts, &quiet).unwrap();
    let entry = std::fs::read_dir(&cache)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            std::fs::read_to_string(p.join("manifest.json"))
                .is_ok_and(|m| m.contains("\"step\": \"views\""))
        })
        .expect("the views step in the cache");
    let damaged = first(&entry, "render.png");
    let mut b = std::fs::read(&damaged).unwrap();
    let j = b.len() / 2;
    b[j] ^= 0x40;
    // A new inode: the run folder `c` hard-linked to the entry keeps its bytes.
    std::fs::remove_file(&damaged).unwrap();
    std::fs::write(&damaged, &b).unwrap();
    let notes = std::sync::Mutex::new(Vec::new());
    let collect = |e: Event| {
        if let Event::Note(n) = e {
            notes.lock().unwrap().push(n)
        }
    };
    let d = t.path().join("d");
    pipeline::run_with(&cfg, &inp, &d, &opts, &collect).unwrap();
    let notes = notes.into_inner().unwrap();
    assert!(
        notes.iter().any(
            |n| n.starts_with("views: the step cache's entry is not usable")
                && n.contains("does not match its sha256")
        ),
        "{notes:?}"
    );
    let c = compare(&reference, &d, 0.0).unwrap();
    assert!(c.steps.iter().all(|s| s.identical), "{}", c.table());
}

/// The cycle paradigm (SPEC.md §20.11; not the paper's method): after detection, one step
/// per trajectory view in trajectory order (gap cameras too), together the full method's
/// iterations; no stage runs; the original and the cycle are evaluated; the report says
/// it is the cycle. A copy of the run whose middle step was removed resumes to the same
/// bits (that step recomputed, the later ones verified as they were).
#[test]
fn the_cycle_paradigm_visits_the_trajectory_in_order_and_resumes_to_the_same_bits() {
    use unseen::pipeline::Paradigm;
    use unseen::pipeline::cycle::total_iterations;
    use unseen::pipeline::steps::Step;
    let t = TempDir::new("pipeline-cycle");
    let Tiny { inp, cfg, .. } = TinyRun::new()
        .config(|c| c.paradigm = Paradigm::Cycle)
        .build(&t);
    let (a, b) = (t.path().join("a"), t.path().join("b"));
    let o = pipeline::run(&cfg, &inp, &a, false, &quiet).unwrap();
    let plan: unseen::pipeline::views::Plan =
        serde_json::from_slice(&std::fs::read(a.join("views/plan.json")).unwrap()).unwrap();
    let k_views = plan.trajectory.len();
    assert!(
        k_views > plan.independent.len()
            && plan.independent.iter().all(|v| plan.trajectory.contains(v)),
        "the trajectory holds the independent and the dependent views: {plan:?}"
    );
    // The trajectory's views in order, together the full method's iterations.
    let mut iterations = 0u64;
    for (k, name) in plan.trajectory.iter().enumerate() {
        let dir = Step::Cycle(k).dir(&a);
        let read = |f: &str| -> serde_json::Value {
            serde_json::from_slice(&std::fs::read(dir.join(f)).unwrap()).unwrap()
        };
        let r = read("cycle.json");
        assert_eq!(
            (r["view"].as_str(), r["index"].as_u64()),
            (Some(name.as_str()), Some(k as u64))
        );
        iterations += read("supervision.json")["iterations"].as_u64().unwrap();
        // Every view generated so far supervises, this one last.
        let supervised = r["supervised"].as_array().unwrap();
        if r["generated"].as_bool().unwrap() {
            assert_eq!(supervised.last().unwrap(), name.as_str());
        }
    }
    assert_eq!(iterations, total_iterations(&cfg));
    assert_eq!(
        total_iterations(&cfg),
        160,
        "stage 1 + stage 2 + interpolation"
    );
    assert!(!Step::Cycle(k_views).dir(&a).exists());
    for stage in ["stage1", "stage2", "interpolate"] {
        assert!(!a.join(stage).exists(), "{stage} ran under the cycle");
    }
    let m = o.metrics.as_ref().unwrap();
    let scenes: Vec<&str> = m.rows.iter().map(|r| r.scene.as_str()).collect();
    assert_eq!(scenes, ["original", "cycle"]);
    assert!(
        m.row("cycle").unwrap().psnr_extrapolated > m.row("original").unwrap().psnr_extrapolated,
        "{}",
        m.table()
    );
    let steps: Vec<String> =
        serde_json::from_slice(&std::fs::read(a.join("steps.json")).unwrap()).unwrap();
    // views, qa/original, the cycle's, eval/masks, eval/original, eval/cycle.
    assert_eq!(steps.len(), k_views + 5, "{steps:?}");
    let md = pipeline::report::markdown(&cfg, &a, &o, 0.0).unwrap();
    assert!(md.contains("not the paper's method"), "{md}");
    // A copy without a middle step, resumed: that step recomputed, the later ones verified.
    for f in walk(&a) {
        let to = b.join(f.strip_prefix(&a).unwrap());
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(&f, &to).unwrap();
    }
    let middle = Step::Cycle(k_views / 2);
    std::fs::remove_dir_all(middle.dir(&b)).unwrap();
    let events = std::sync::Mutex::new(Vec::new());
    let record = |e: Event| events.lock().unwrap().push(e);
    pipeline::run(&cfg, &inp, &b, true, &record).unwrap();
    let events = events.into_inner().unwrap();
    let finished = |s: &Step| {
        events
            .iter()
            .any(|e| matches!(e, Event::StepFinished { step, .. } if *step == s.to_string()))
    };
    assert!(finished(&middle));
    assert!(!finished(&Step::Cycle(k_views / 2 + 1)) && !finished(&Step::Cycle(0)));
    let c = compare(&a, &b, 0.0).unwrap();
    assert!(c.steps.iter().all(|s| s.identical), "{}", c.table());
    assert_eq!(c.steps.len(), k_views + 5);
}

/// The cycle paradigm gives the same bits on 1 and 2 threads.
#[test]
#[ignore = "slow tier (~16 s): cargo test -- --include-ignored"]
fn the_cycle_paradigm_is_the_same_bits_on_1_and_2_threads() {
    use unseen::pipeline::Paradigm;
    let t = TempDir::new("pipeline-cycle-threads");
    let Tiny { inp, cfg, .. } = TinyRun::new()
        .config(|c| c.paradigm = Paradigm::Cycle)
        .build(&t);
    let (a, b) = (t.path().join("a"), t.path().join("b"));
    with_threads(2, || pipeline::run(&cfg, &inp, &a, false, &quiet)).unwrap();
    with_threads(1, || pipeline::run(&cfg, &inp, &b, false, &quiet)).unwrap();
    let c = compare(&a, &b, 0.0).unwrap();
    assert!(c.steps.iter().all(|s| s.identical), "{}", c.table());
    assert!(c.steps.len() >= 8, "{} steps compared", c.steps.len());
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
