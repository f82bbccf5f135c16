//! Interrupted training (SPEC.md §10, §14.8): `unseen train` killed with SIGKILL at seeded
//! points and continued with `--resume` ends with the same bits as a run that was never
//! interrupted; checkpoint files are checked before use; SIGINT / SIGTERM remove the
//! temporaries in flight and keep finished outputs.
use crate::support::{TempDir, reference, short_train_config};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use unseen::rng::Uniform;
use unseen::train::checkpoint::{Checkpoint, checkpoint_path};

const ITERATIONS: u32 = 400;
const EVERY: u32 = 40;

fn unseen() -> Command {
    Command::new(env!("CARGO_BIN_EXE_unseen"))
}

/// A short recipe that densifies (from 100, every 100), resets opacity (250) and raises
/// the SH degree (every 200), so every part of the state matters after a resume; one PLY
/// saved before the end.
fn write_config(dir: &Path) -> PathBuf {
    let mut c = short_train_config(ITERATIONS);
    c.resolution = 4;
    c.seed = 5;
    c.save_iterations = vec![200];
    let p = dir.join("config.json");
    std::fs::write(&p, serde_json::to_string(&c).unwrap()).unwrap();
    p
}

/// `unseen train` into `run` checkpointing every [`EVERY`] iterations: fresh with
/// `config`, or `--resume`.
fn train(run: &Path, config: Option<&Path>) -> Command {
    train_every(run, config, EVERY)
}

fn train_every(run: &Path, config: Option<&Path>, every: u32) -> Command {
    let mut cmd = unseen();
    cmd.arg("train")
        .arg(reference("scenes/lounge"))
        .arg("--out")
        .arg(run)
        .args(["--checkpoint-every", &every.to_string()]);
    match config {
        Some(c) => cmd.arg("--config").arg(c),
        None => cmd.arg("--resume"),
    };
    cmd
}

/// A child process that is SIGKILLed and reaped when dropped, so a failing test leaves
/// none writing into its temp dir.
struct Reaped(std::process::Child);

impl Drop for Reaped {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The number at the end of `line` if it starts with `prefix`.
fn iteration_after(line: &str, prefix: &str) -> Option<u32> {
    line.strip_prefix(prefix)?.trim().parse().ok()
}

/// What [`kill_at`] saw.
struct Killed {
    /// The iteration the process said it resumed from.
    resumed_from: Option<u32>,
    /// It was killed before it finished.
    killed: bool,
}

/// Start `cmd`; once it reports a checkpoint at iteration `at` or later, wait `delay_ms`
/// and SIGKILL it.
fn kill_at(mut cmd: Command, at: u32, delay_ms: u64) -> Killed {
    let mut child = Reaped(cmd.stderr(Stdio::piped()).spawn().unwrap());
    let mut lines = BufReader::new(child.0.stderr.take().unwrap()).lines();
    let mut resumed_from = None;
    for line in lines.by_ref() {
        let line = line.unwrap();
        resumed_from = resumed_from.or(iteration_after(
            &line,
            "resuming from the checkpoint at iteration",
        ));
        if iteration_after(&line, "checkpoint at iteration").is_some_and(|it| it >= at) {
            break;
        }
    }
    std::thread::sleep(std::time::Duration::from_millis(delay_ms));
    let killed = child.0.try_wait().unwrap().is_none() && child.0.kill().is_ok();
    // Drain, so the child never blocks on a full pipe before the signal lands.
    for _ in lines {}
    let status = child.0.wait().unwrap();
    Killed {
        resumed_from,
        killed: killed && !status.success(),
    }
}

/// `train_stats.json`'s numbers that come from the training state (not the clock).
fn state_stats(run: &Path) -> serde_json::Value {
    let s: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("train_stats.json")).unwrap()).unwrap();
    serde_json::json!([
        s["curve"],
        s["final_loss_ema"],
        s["final_psnr_ema"],
        s["gaussians"]
    ])
}

fn ply(run: &Path, it: u32) -> Vec<u8> {
    let p = run.join(format!("point_cloud/iteration_{it}/point_cloud.ply"));
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn manifest_files(run: &Path) -> Vec<serde_json::Value> {
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("manifest.json")).unwrap()).unwrap();
    m["files"].as_array().unwrap().clone()
}

fn assert_clean(run: &Path) {
    assert!(
        !checkpoint_path(run).exists(),
        "checkpoint left after the run"
    );
    let mut stack = vec![run.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            assert!(!name.starts_with('.'), "leftover {}", p.display());
            if p.is_dir() {
                stack.push(p);
            }
        }
    }
}

#[test]
fn train_killed_and_resumed_gives_the_same_bits() {
    let tmp = TempDir::new("resume");
    let config = write_config(tmp.path());
    let whole = tmp.path().join("whole");
    let st = train(&whole, Some(&config)).output().unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    assert_clean(&whole);

    // Seeded kill points: once after an early checkpoint (before any densification), once
    // in a resumed process after iteration 240 (densified twice, SH degree raised, just
    // before the opacity reset at 250), each after a seeded delay.
    let mut rng = Uniform::new(20261124);
    let cut = tmp.path().join("cut");
    let first = kill_at(
        train(&cut, Some(&config)),
        EVERY * (1 + rng.below(2)),
        rng.below(30) as u64,
    );
    assert!(first.killed, "the first run finished before the kill");
    let second = kill_at(
        train(&cut, None),
        EVERY * (6 + rng.below(2)),
        rng.below(30) as u64,
    );
    assert!(second.killed, "the resumed run finished before the kill");
    let from = second.resumed_from.expect("the second run resumed");
    assert!((EVERY..240).contains(&from), "resumed from {from}");
    // Resume until done (a kill that landed after the last checkpoint's rename leaves a
    // complete checkpoint; one that landed during its write leaves the previous one).
    let st = train(&cut, None).output().unwrap();
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(st.status.success(), "{err}");
    let from = err
        .lines()
        .find_map(|l| iteration_after(l, "resuming from the checkpoint at iteration"))
        .expect("the last run resumed");
    assert!(from >= 240, "resumed from {from}");
    assert_clean(&cut);

    for it in [200, ITERATIONS] {
        assert!(
            ply(&whole, it) == ply(&cut, it),
            "PLY of iteration {it} differs"
        );
    }
    let plys = |run: &Path| -> Vec<serde_json::Value> {
        manifest_files(run)
            .into_iter()
            .filter(|f| f["path"].as_str().unwrap().ends_with(".ply"))
            .collect()
    };
    assert_eq!(plys(&whole), plys(&cut));
    assert_eq!(plys(&whole).len(), 2);
    // The averages and the curve continue too (they do not reach the PLYs).
    assert_eq!(state_stats(&whole), state_stats(&cut));

    // A finished run has nothing to resume: a clear error, the outputs untouched.
    let st = train(&cut, None).output().unwrap();
    assert!(!st.status.success());
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(err.contains("nothing to resume"), "{err}");
    assert!(ply(&cut, ITERATIONS) == ply(&whole, ITERATIONS));
}

/// A checkpoint is written and read back to the same state; a damaged, truncated or
/// foreign file is refused with an error naming it, and `--resume` with one fails cleanly.
#[test]
fn checkpoint_files_are_checked() {
    let tmp = TempDir::new("checkpoint-files");
    let config = write_config(tmp.path());
    let run = tmp.path().join("run");
    // Kill after the first checkpoint: the run directory holds a checkpoint.
    assert!(kill_at(train(&run, Some(&config)), EVERY, 0).killed);
    let ck = checkpoint_path(&run);
    let good = std::fs::read(&ck).unwrap();
    let c = Checkpoint::read(&ck).unwrap();
    assert!(c.header.iteration >= EVERY && c.header.iteration.is_multiple_of(EVERY));
    assert_eq!(c.gaussians.len(), c.header.gaussians);
    assert_eq!(c.adam_m.len(), c.gaussians.len());
    assert_eq!(c.stats.count.len(), c.gaussians.len());
    // Written again, the same bytes.
    let again = tmp.path().join("again.bin");
    c.write(&again).unwrap();
    assert!(std::fs::read(&again).unwrap() == good);

    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty", vec![], "not an unseen training checkpoint"),
        (
            "truncated",
            good[..good.len() / 2].to_vec(),
            "checksum does not match",
        ),
        (
            "flipped",
            {
                let mut b = good.clone();
                let i = b.len() - 100;
                b[i] ^= 1;
                b
            },
            "checksum does not match",
        ),
        ("ply", ply_like(), "not an unseen training checkpoint"),
    ];
    for (name, bytes, want) in cases {
        std::fs::write(&ck, &bytes).unwrap();
        let e = Checkpoint::read(&ck).err().unwrap().to_string();
        assert!(
            e.contains(want) && e.contains("checkpoint.bin"),
            "{name}: {e}"
        );
        let st = train(&run, None).output().unwrap();
        assert!(!st.status.success(), "{name}");
        let err = String::from_utf8_lossy(&st.stderr);
        assert!(
            err.contains("checkpoint.bin") && err.contains(want),
            "{name}: {err}"
        );
        assert_eq!(err.lines().count(), 1, "{name}: {err}");
    }
    // A header announcing more Gaussians than the file holds is refused before any
    // allocation (the digest is recomputed, so only the count is wrong).
    let hlen = u64::from_le_bytes(good[12..20].try_into().unwrap()) as usize;
    let header = std::str::from_utf8(&good[20..20 + hlen]).unwrap();
    let n = c.header.gaussians;
    let huge = header.replace(
        &format!("\"gaussians\":{n},"),
        "\"gaussians\":1000000000000,",
    );
    assert_ne!(huge, header);
    let mut b = b"UNSEENCK".to_vec();
    b.extend_from_slice(&1u32.to_le_bytes());
    b.extend_from_slice(&(huge.len() as u64).to_le_bytes());
    b.extend_from_slice(huge.as_bytes());
    b.extend_from_slice(&good[20 + hlen..good.len() - 32]);
    use sha2::Digest;
    let d = sha2::Sha256::digest(&b);
    b.extend_from_slice(&d);
    std::fs::write(&ck, &b).unwrap();
    let e = Checkpoint::read(&ck).err().unwrap().to_string();
    assert!(e.contains("announces 1000000000000 Gaussians"), "{e}");
}

fn ply_like() -> Vec<u8> {
    b"ply\nformat binary_little_endian 1.0\nelement vertex 0\nend_header\n".repeat(2)
}

/// SIGINT and SIGTERM at seeded moments of a run that checkpoints after every iteration (so
/// a write is in flight most of the time): exit code 130, no temporary left, the finished
/// outputs whole (the checkpoint reads back and verifies).
#[test]
fn interrupts_remove_temporaries_and_keep_finished_outputs() {
    let tmp = TempDir::new("interrupt");
    let config = write_config(tmp.path());
    let mut rng = Uniform::new(7_2026);
    for (i, signal) in [libc::SIGINT, libc::SIGTERM, libc::SIGINT, libc::SIGTERM]
        .into_iter()
        .enumerate()
    {
        let run = tmp.path().join(format!("run{i}"));
        let mut child = Reaped(
            train_every(&run, Some(&config), 1)
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        );
        let mut lines = BufReader::new(child.0.stderr.take().unwrap()).lines();
        let mut err = String::new();
        for line in lines.by_ref() {
            let line = line.unwrap();
            if line.starts_with("checkpoint at iteration") {
                break;
            }
            err += &line;
        }
        std::thread::sleep(std::time::Duration::from_millis(rng.below(60) as u64));
        assert!(
            child.0.try_wait().unwrap().is_none(),
            "finished before the signal"
        );
        // SAFETY: signalling our own child, alive (not yet reaped) until we wait for it.
        assert_eq!(unsafe { libc::kill(child.0.id() as i32, signal) }, 0);
        for line in lines {
            err += &line.unwrap();
        }
        let status = child.0.wait().unwrap();
        assert_eq!(status.code(), Some(130), "signal {signal}: {err}");
        assert!(err.contains("interrupted"), "{err}");
        let ck = checkpoint_path(&run);
        Checkpoint::read(&ck).unwrap();
        std::fs::remove_file(&ck).unwrap();
        assert_clean(&run);
        let cfg = std::fs::read(run.join("config.json")).unwrap();
        serde_json::from_slice::<serde_json::Value>(&cfg).unwrap();
    }
}
