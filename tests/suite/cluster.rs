//! The audit on a batch engine without one (SPEC.md §21.4): workers run as `--only JOB`
//! processes in the emitted waves' order, each leaves a receipt; the merge (`--collect`)
//! names every job without a receipt of a success and writes nothing, then, once all are
//! done, writes the report a sequential audit writes, byte for byte. `.ci/slurm` runs the
//! same through a real Slurm.

use crate::support::TempDir;
use crate::support::tiny_run::{TinyRun, lounge};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The tiny audit's grid (2 seeds × 3 variants, truth-low, seconds per job).
fn grid(config: &Path) -> Vec<std::ffi::OsString> {
    let mut v: Vec<std::ffi::OsString> = vec!["audit".into(), lounge().into(), "--config".into()];
    v.push(config.into());
    for a in [
        "--variants",
        "full,opacity_mask,even_views",
        "--generators",
        "truth-low",
        "--seeds",
        "2",
        "--train-iterations",
        "300",
        "--train-resolution",
        "4",
    ] {
        v.push(a.into());
    }
    v
}

fn audit(config: &Path, out: &Path, more: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_unseen"))
        .args(grid(config))
        .arg("--out")
        .arg(out)
        .args(more)
        .output()
        .unwrap()
}

fn ok(o: &Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn tiny_config(dir: &Path) -> PathBuf {
    let p = dir.join("tiny.json");
    std::fs::write(
        &p,
        r#"{"qa_iterations": 30, "video_frames": 3, "interpolation": false, "fixer_every": 20,
            "stage1": {"iterations": 60, "densify": null},
            "stage2": {"iterations": 60, "densify": null},
            "interpolate": {"iterations": 40, "densify": null}}"#,
    )
    .unwrap();
    p
}

#[test]
#[ignore = "slow tier (~45 s): cargo test -- --include-ignored"]
fn workers_with_receipts_merge_to_the_sequential_report_and_the_merge_names_what_is_missing() {
    let t = TempDir::new("cluster-merge");
    let config = tiny_config(t.path());
    let (dir, sub) = (t.path().join("audit"), t.path().join("submit"));
    // The submission folder: the waves, their arrays, the merge, submit.sh.
    let emitted = ok(&audit(
        &config,
        &dir,
        &["--emit-slurm", sub.to_str().unwrap()],
    ));
    assert!(emitted.contains("runs: 6 jobs"), "{emitted}");
    let jobs: Vec<String> = std::fs::read_to_string(sub.join("jobs.txt"))
        .unwrap()
        .lines()
        .map(String::from)
        .collect();
    assert_eq!(jobs.len(), 10);
    assert_eq!(&jobs[..2], ["original/seed-0", "original/seed-1"]);
    assert_eq!(
        &jobs[2..4],
        ["shared/truth-low/seed-0", "shared/truth-low/seed-1"]
    );
    for (stem, n) in [
        ("wave-1-originals", 2),
        ("wave-2-shared", 2),
        ("wave-3-runs", 6),
    ] {
        let s = std::fs::read_to_string(sub.join(format!("{stem}.sbatch"))).unwrap();
        assert!(s.contains(&format!("#SBATCH --array=0-{}\n", n - 1)), "{s}");
        assert!(
            s.contains("--only \"$job\"") && s.contains("#SBATCH --mem="),
            "{s}"
        );
        let list = std::fs::read_to_string(sub.join(format!("{stem}.txt"))).unwrap();
        assert_eq!(list.lines().count(), n);
    }
    let submit = std::fs::read_to_string(sub.join("submit.sh")).unwrap();
    assert!(
        submit.contains("--dependency=afterok:$w1 wave-2-shared.sbatch"),
        "{submit}"
    );
    assert!(
        submit.contains("--dependency=afterany:$w1:$w2:$w3 merge.sbatch"),
        "{submit}"
    );
    for f in ["submit.sh", "merge.sbatch", "wave-3-runs.sbatch"] {
        if let Ok(st) = Command::new("bash").arg("-n").arg(sub.join(f)).status() {
            assert!(st.success(), "{f} is not valid shell");
        }
    }
    // Nothing has run: the merge names all ten, with the logs the submission gives them.
    let sub_arg = ["--collect", "--submission", sub.to_str().unwrap()];
    let o = audit(&config, &dir, &sub_arg);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert_eq!(
        err.lines().filter(|l| l.starts_with("not done: ")).count(),
        10,
        "{err}"
    );
    assert!(
        err.contains(&format!("(log: {})", sub.join("logs/runs-5.out").display())),
        "{err}"
    );
    assert_eq!(
        err.lines().filter(|l| l.starts_with("error:")).count(),
        1,
        "{err}"
    );
    // The workers, wave by wave; one fails (a file where its folder goes).
    let bad = "runs/truth-low/even_views/seed-1";
    std::fs::create_dir_all(dir.join("runs/truth-low/even_views")).unwrap();
    std::fs::write(dir.join(bad), "x").unwrap();
    for job in &jobs {
        let o = audit(
            &config,
            &dir,
            &["--only", job, "--log", "/logs/of/this.out"],
        );
        assert_eq!(o.status.success(), job != bad, "{job}");
    }
    let receipt: serde_json::Value = serde_json::from_slice(
        &std::fs::read(dir.join("receipts/runs__truth-low__even_views__seed-1.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(receipt["exit"], 1);
    assert!(
        receipt["error"]
            .as_str()
            .unwrap()
            .contains("the output path is a file")
    );
    assert_eq!(receipt["log"], "/logs/of/this.out");
    let o = audit(&config, &dir, &["--collect"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    let named: Vec<&str> = err
        .lines()
        .filter(|l| l.starts_with("not done: "))
        .collect();
    assert_eq!(named.len(), 1, "{err}");
    assert!(
        named[0].starts_with(&format!("not done: {bad}: failed on ")),
        "{err}"
    );
    assert!(named[0].contains("(log: /logs/of/this.out)"), "{err}");
    assert!(
        !dir.join("audit.json").exists(),
        "a refused merge wrote its report"
    );
    // Fixed and run again: the merge is the sequential audit's report.
    std::fs::remove_file(dir.join(bad)).unwrap();
    ok(&audit(&config, &dir, &["--only", bad]));
    // A result changed after its receipt is named, not merged.
    let result = dir.join("runs/truth-low/full/seed-0/audit_job.json");
    let text = std::fs::read_to_string(&result).unwrap();
    std::fs::write(&result, format!("{text} ")).unwrap();
    let o = audit(&config, &dir, &["--collect"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("not done: runs/truth-low/full/seed-0: runs/truth-low/full/seed-0/audit_job.json is missing or changed since the job's receipt"),
        "{err}"
    );
    std::fs::write(&result, text).unwrap();
    // (Once merged, the pooled samples are the record: a later merge or audit of the same
    // grid does not read the job folders again.)
    ok(&audit(&config, &dir, &["--collect"]));
    let seq = t.path().join("sequential");
    ok(&audit(&config, &seq, &[]));
    let read = |d: &Path, f: &str| std::fs::read(d.join(f)).unwrap();
    assert!(
        read(&dir, "audit.json") == read(&seq, "audit.json"),
        "audit.json differs"
    );
    // Pooled: an audit merging these samples submits no wave, only the merge (at once),
    // and merges without a receipt to what a sequential audit of the same pool writes,
    // which runs nothing either. A grid with one variant more submits only its runs and
    // what they need (the originals and shared steps of their seeds).
    let samples = dir.join(unseen::audit::samples::SAMPLES_FILE);
    let merge = ["--merge", samples.to_str().unwrap()];
    let (again, sub2) = (t.path().join("again"), t.path().join("submit2"));
    let printed = ok(&audit(
        &config,
        &again,
        &[&["--emit-slurm", sub2.to_str().unwrap()][..], &merge].concat(),
    ));
    assert!(!printed.contains("jobs,"), "{printed}");
    assert_eq!(std::fs::read_to_string(sub2.join("jobs.txt")).unwrap(), "");
    let submit = std::fs::read_to_string(sub2.join("submit.sh")).unwrap();
    assert!(submit.contains("merge=$(id merge.sbatch)"), "{submit}");
    if let Ok(st) = Command::new("bash")
        .arg("-n")
        .arg(sub2.join("submit.sh"))
        .status()
    {
        assert!(st.success(), "submit.sh is not valid shell");
    }
    ok(&audit(
        &config,
        &again,
        &[&["--collect"][..], &merge].concat(),
    ));
    let pooled = t.path().join("pooled");
    ok(&audit(&config, &pooled, &merge));
    assert!(!pooled.join("runs").exists() && !pooled.join("original").exists());
    assert!(
        read(&again, "audit.json") == read(&pooled, "audit.json"),
        "the pooled merge's audit.json differs from the pooled sequential audit's"
    );
    let mut args = grid(&config);
    let v = args.iter().position(|a| a == "--variants").unwrap() + 1;
    args[v] = "full,opacity_mask,even_views,no_qa_mask".into();
    let more = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .args(args)
        .arg("--out")
        .arg(t.path().join("more"))
        .args(["--emit-slurm", t.path().join("submit3").to_str().unwrap()])
        .args(merge)
        .output()
        .unwrap();
    let printed = ok(&more);
    assert!(
        printed.contains("originals: 2 jobs")
            && printed.contains("shared: 2 jobs")
            && printed.contains("runs: 2 jobs"),
        "{printed}"
    );
    let listed = std::fs::read_to_string(t.path().join("submit3/wave-3-runs.txt")).unwrap();
    assert_eq!(
        listed,
        "runs/truth-low/no_qa_mask/seed-0\nruns/truth-low/no_qa_mask/seed-1\n"
    );
}

/// `--list --estimate`: every wave with its jobs' expected costs; after the jobs ran, the
/// estimate is the audit's own measurement.
#[test]
fn the_estimate_lists_every_wave_and_uses_what_the_audit_measured() {
    let t = TempDir::new("cluster-estimate");
    let config = tiny_config(t.path());
    let dir = t.path().join("audit");
    let est = ok(&audit(&config, &dir, &["--list", "--estimate"]));
    for w in [
        "wave originals: 2 jobs",
        "wave shared: 2 jobs",
        "wave runs: 6 jobs",
    ] {
        assert!(est.contains(w), "{est}");
    }
    assert!(
        est.contains("(0 of 2 from this audit's finished jobs)"),
        "{est}"
    );
    assert!(est.contains("total: 10 jobs"), "{est}");
    assert!(!dir.exists(), "--list wrote {}", dir.display());
    ok(&audit(&config, &dir, &["--only", "original/seed-0"]));
    let est = ok(&audit(&config, &dir, &["--list", "--estimate"]));
    assert!(
        est.contains("wave originals: 2 jobs")
            && est.contains("(2 of 2 from this audit's finished jobs)"),
        "{est}"
    );
}

/// `extrapolate --emit-slurm`: one job array per wave of the plan that fans out (the
/// stage-1 array over every candidate), the waves between them as one job, the whole run
/// last; valid shell; `--plan` lists the largest plan before detection and what
/// detection found after it.
#[test]
fn extrapolate_emits_the_waves_of_its_plan_and_lists_them() {
    let t = TempDir::new("cluster-extrapolate");
    let (run, cfg) = TinyRun::new().files(&t);
    let (out, sub) = (t.path().join("out"), t.path().join("submit"));
    let ex = |more: &[&std::ffi::OsStr]| {
        Command::new(env!("CARGO_BIN_EXE_unseen"))
            .arg("extrapolate")
            .arg(&run)
            .arg("--views")
            .arg(lounge().join("candidates.json"))
            .arg("--config")
            .arg(&cfg)
            .arg("--out")
            .arg(&out)
            .args(more)
            .output()
            .unwrap()
    };
    let printed = ok(&ex(&["--emit-slurm".as_ref(), sub.as_os_str()]));
    assert!(printed.contains("stage1: 12 tasks"), "{printed}");
    assert!(!out.exists(), "--emit-slurm ran something");
    let mut sbatch: Vec<String> = std::fs::read_dir(&sub)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".sbatch"))
        .collect();
    sbatch.sort();
    assert_eq!(
        sbatch.first().map(String::as_str),
        Some("wave-1-views.sbatch")
    );
    assert!(
        sbatch.last().unwrap().ends_with("-finish.sbatch"),
        "{sbatch:?}"
    );
    for name in &sbatch {
        let s = std::fs::read_to_string(sub.join(name)).unwrap();
        assert!(
            s.contains("pipeline-config.json") && s.contains("--resume"),
            "{s}"
        );
        if name == "wave-2-stage1.sbatch" {
            assert!(s.contains("#SBATCH --array=0-11\n"), "{s}");
            assert!(
                s.contains("--wave 1 --task \"$SLURM_ARRAY_TASK_ID\""),
                "{s}"
            );
        }
        if name.ends_with("-finish.sbatch") {
            assert!(!s.contains("--wave"), "the last job is the whole run: {s}");
        }
        if let Ok(st) = Command::new("bash").arg("-n").arg(sub.join(name)).status() {
            assert!(st.success(), "{name} is not valid shell");
        }
    }
    assert!(
        sbatch.contains(&"wave-2-stage1.sbatch".to_string()),
        "{sbatch:?}"
    );
    // Before detection: every candidate in wave 1.
    let independent = |plan: &str| {
        let wave1 = plan.lines().find(|l| l.starts_with("wave 1: ")).unwrap();
        wave1
            .split(' ')
            .filter(|s| s.starts_with("stage1/"))
            .count()
    };
    assert_eq!(independent(&ok(&ex(&["--plan".as_ref()]))), 12);
    ok(&ex(&["--until".as_ref(), "views".as_ref()]));
    let plan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("views/plan.json")).unwrap()).unwrap();
    let n = plan["independent"].as_array().unwrap().len();
    let listed = ok(&ex(&["--plan".as_ref()]));
    assert!(n > 0 && independent(&listed) == n, "{listed}");
    // One task of the stage-1 array past the independent views has nothing to do.
    let o = ok(&ex(&[
        "--wave".as_ref(),
        "1".as_ref(),
        "--task".as_ref(),
        "11".as_ref(),
    ]));
    assert!(o.contains("done: the requested steps"), "{o}");
    assert!(
        !out.join("stage1").exists(),
        "a task past the wave computed a step"
    );
}
