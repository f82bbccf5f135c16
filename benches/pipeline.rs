//! One quick-preset pipeline job, step by step: `cargo bench --bench pipeline [-- --runs N]
//! [--threads T,…] [--frozen DIR]`.
//!
//! The demo's extrapolation (lounge, classical slots, quick preset, evaluation on the
//! room's evaluation poses) on a frozen original scene: the demo's training (1 500
//! iterations at 80×60, seed 0) done once into `DIR/original` (default: a folder under
//! `target/`, kept between runs so that a series of runs — and two binaries interleaved —
//! extrapolate the same scene; its PLY sha256 is printed), then the pipeline `N` times per
//! thread count into fresh folders. Prints per step the fastest of the `N` runs (seconds,
//! from the step's own `cost.json`, so copies and bookkeeping between steps are not in a
//! step's figure), the sum of the steps and the wall time of the fastest run, and what the
//! steps' outputs hash to (equal across runs and thread counts, as SPEC.md §20.8 requires:
//! a speed-up that changes it is a numerics revision).
//!
//! For a ratio between two commits, build this bench at each (`cargo bench --bench pipeline
//! --no-run` prints the binary), then run the two binaries alternately with the same
//! `--frozen DIR` and compare the step sums (benches/README.md).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;
use unseen::pipeline::{self, Event, PipelineConfig, load_inputs};
use unseen::train::run::{Checkpointing, latest_ply, train_run};
use unseen::train::trainer::TrainConfig;

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn main() {
    unseen::sys::keep_freed_memory(); // as the CLI does (SPEC.md §6)
    let quick = std::env::args().any(|a| a == "--quick");
    let runs: usize = arg("--runs")
        .and_then(|v| v.parse().ok())
        .unwrap_or(if quick { 1 } else { 3 });
    let threads: Vec<usize> = arg("--threads")
        .map(|v| v.split(',').filter_map(|t| t.parse().ok()).collect())
        .unwrap_or_else(|| vec![2]);
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let frozen = arg("--frozen")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest.join("target/bench-pipeline"));
    let scene = manifest.join("reference_data/scenes/lounge");
    let original = frozen.join("original");
    if latest_ply(&original).is_err() {
        let _ = std::fs::remove_dir_all(&original);
        let tc = TrainConfig {
            iterations: 1500,
            resolution: 2,
            save_iterations: vec![],
            ..TrainConfig::default()
        };
        eprintln!(
            "training the frozen original (the demo's) into {}",
            original.display()
        );
        train_run(
            &scene,
            &original,
            &tc,
            None,
            Checkpointing::default(),
            &mut |_| {},
        )
        .expect("the demo's training");
    }
    let (_, ply) = latest_ply(&original).unwrap();
    let ply_sha = unseen::io::sha256_hex(&std::fs::read(&ply).unwrap());
    let inputs = load_inputs(
        &original,
        &scene.join("candidates.json"),
        Some(&scene.join("evaluation.json")),
        Some(&scene),
    )
    .unwrap();
    let cfg = PipelineConfig::quick();
    println!(
        "pipeline bench: lounge, quick preset, classical slots; original {} (sha256 {}…); best of {runs}",
        ply.display(),
        &ply_sha[..12]
    );
    let quiet = |_: Event| {};
    for &t in &threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap();
        let mut best: BTreeMap<String, f64> = BTreeMap::new();
        let mut order: Vec<String> = Vec::new();
        let mut wall = f64::MAX;
        let mut digest = String::new();
        for r in 0..runs {
            let out = frozen.join(format!("run-{t}-{r}"));
            let _ = std::fs::remove_dir_all(&out);
            let t0 = Instant::now();
            let outcome = pool
                .install(|| pipeline::run(&cfg, &inputs, &out, false, &quiet))
                .expect("the pipeline");
            wall = wall.min(t0.elapsed().as_secs_f64());
            let mut all = String::new();
            for s in &outcome.steps {
                let cost: unseen::io::Cost = serde_json::from_slice(
                    &std::fs::read(s.dir.join(pipeline::rundir::TIMING_FILE)).unwrap(),
                )
                .unwrap();
                let e = best.entry(s.name.clone()).or_insert(f64::MAX);
                *e = e.min(cost.seconds);
                if r == 0 {
                    order.push(s.name.clone());
                }
                all += &s.digest;
            }
            let d = unseen::io::sha256_hex(all.as_bytes());
            assert!(
                digest.is_empty() || digest == d,
                "run {r} on {t} threads computed other bits"
            );
            digest = d;
            std::fs::remove_dir_all(&out).unwrap();
        }
        println!("\n{t} thread(s): steps' outputs sha256 {}…", &digest[..12]);
        println!("{:<24} {:>9}", "step", "seconds");
        let mut sum = 0.0;
        for name in &order {
            println!("{name:<24} {:>9.3}", best[name]);
            sum += best[name];
        }
        println!("{:<24} {sum:>9.3}", "sum of steps");
        println!("{:<24} {wall:>9.3}", "wall (fastest run)");
    }
}
