//! An audit on a batch engine (SPEC.md §21.4): its jobs in dependency waves, a receipt per
//! job, the merge that names every job without a successful receipt, a Slurm submission
//! folder, and the cost estimate its resource requests come from.
//!
//! Nothing here schedules: Slurm does. A worker is `unseen audit … --only JOB`; it writes
//! `DIR/receipts/<job>.json` whether it succeeds or fails; the merge
//! (`unseen audit … --collect`) reads the receipts and the run jobs' `audit_job.json`,
//! computes nothing, and writes the same report a sequential `unseen audit` writes.

use super::jobs::SHARED_BEFORE;
use super::jobs::{Job, JobResult, jobs};
use super::report::Report;
use super::{Audit, AuditConfig, Variant};
use crate::batch::cost::{BASE_BYTES, Calibration, pipeline_work, scoped_work};
use crate::batch::{
    ArrayWave, Cost, Request, SlurmOptions, least_request, request, shell_quote, write_submission,
};
use crate::error::{Error, Result};
use crate::io::{sha256_hex, write_text};
use crate::pipeline::{MaskSource, Paradigm, Scope};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One wave of jobs: every job of a wave may run at once; a wave starts when the one
/// before it has succeeded.
#[derive(Clone, Debug, PartialEq)]
pub struct Wave {
    pub name: &'static str,
    pub jobs: Vec<Job>,
}

/// The audit's jobs in waves: the original scenes (one per seed), the steps a seed's
/// variants share under each generator ([`Job::Shared`]), then every variant's run.
/// Together they are [`jobs`] and the shared-steps jobs.
pub fn waves(cfg: &AuditConfig) -> Vec<Wave> {
    let all = jobs(cfg);
    let originals = all
        .iter()
        .filter(|j| matches!(j, Job::Original { .. }))
        .cloned()
        .collect();
    let runs = all
        .iter()
        .filter(|j| matches!(j, Job::Run { .. }))
        .cloned()
        .collect();
    let shared = cfg
        .seeds
        .clone()
        .flat_map(|seed| {
            cfg.generators
                .iter()
                .map(move |&generator| Job::Shared { generator, seed })
        })
        .collect();
    vec![
        Wave {
            name: "originals",
            jobs: originals,
        },
        Wave {
            name: "shared",
            jobs: shared,
        },
        Wave {
            name: "runs",
            jobs: runs,
        },
    ]
}

// ------------------------------------------------------------------------- receipts

/// The `format` of a receipt.
pub const RECEIPT_FORMAT: &str = "unseen-audit-receipt/1";

/// What a worker leaves for the merge: one per job, written when the job ends (succeeded
/// or failed; a job killed before its end leaves none).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Receipt {
    pub format: String,
    pub job: String,
    /// The worker's host ([`crate::io::host_name`]) and process id.
    pub host: String,
    pub pid: u32,
    /// The batch engine's id of the job (`SLURM_ARRAY_JOB_ID_SLURM_ARRAY_TASK_ID`, or
    /// `SLURM_JOB_ID`), when it ran under one.
    pub batch_job: Option<String>,
    /// The worker's log, as its caller named it (`--log`).
    pub log: Option<String>,
    /// UTC, RFC 3339, to the second.
    pub started: String,
    pub finished: String,
    pub seconds: f64,
    /// 0: the job is done; 1: it failed with `error`.
    pub exit: i32,
    pub error: Option<String>,
    pub crate_version: String,
    pub numerics_revision: u32,
    /// sha256 of what the job leaves, by path under the audit directory: a run's
    /// `audit_job.json`, an original's `manifest.json`, a shared job's step manifests.
    pub digests: BTreeMap<String, String>,
}

/// `DIR/receipts/<job name, '/' as '__'>.json`.
pub fn receipt_path(dir: &Path, job: &Job) -> PathBuf {
    dir.join("receipts")
        .join(format!("{}.json", job.name().replace('/', "__")))
}

impl Audit<'_> {
    /// [`Audit::run_job`] with its receipt: the old receipt is removed first (a job killed
    /// this time must not pass for done), the new one written at the end, with the error
    /// when the job failed (the job's error is returned either way). Bad input — an invalid
    /// audit, a dataset without its poses, an output path that is a file, a pipeline job
    /// before its original — is refused before anything is written, receipt included
    /// (SPEC.md §21.1); so is a job that fails before it wrote anything into a `dir` that did
    /// not exist (bad input found by the job itself: nothing written, SPEC.md §11), which the
    /// merge then names as without receipt.
    pub fn run_job_with_receipt(&self, job: &Job, log: Option<&Path>) -> Result<Option<JobResult>> {
        let dir = self.dir;
        let path = receipt_path(dir, job);
        if path.exists() {
            std::fs::remove_file(&path).map_err(|e| Error::io(&path, e))?;
        }
        self.cfg.validate()?;
        self.check_inputs()?;
        if let Job::Run { seed, .. } | Job::Shared { seed, .. } = *job {
            self.require_original(job, seed)?;
        }
        let existed = dir.exists();
        let started = std::time::SystemTime::now();
        let t0 = std::time::Instant::now();
        let outcome = self.run_job(job);
        if outcome.is_err() && !existed && !dir.exists() {
            return outcome;
        }
        let digests = match &outcome {
            Ok(_) => job_digests(dir, job)?,
            Err(_) => BTreeMap::new(),
        };
        let env = |k: &str| std::env::var(k).ok().filter(|v| !v.is_empty());
        let batch_job = match (env("SLURM_ARRAY_JOB_ID"), env("SLURM_ARRAY_TASK_ID")) {
            (Some(a), Some(t)) => Some(format!("{a}_{t}")),
            _ => env("SLURM_JOB_ID"),
        };
        let receipt = Receipt {
            format: RECEIPT_FORMAT.into(),
            job: job.name(),
            host: crate::io::host_name(),
            pid: std::process::id(),
            batch_job,
            log: log.map(|p| p.display().to_string()),
            started: utc(started),
            finished: utc(std::time::SystemTime::now()),
            seconds: t0.elapsed().as_secs_f64(),
            exit: i32::from(outcome.is_err()),
            error: outcome.as_ref().err().map(|e| e.to_string()),
            crate_version: env!("CARGO_PKG_VERSION").into(),
            numerics_revision: crate::version::NUMERICS_REVISION,
            digests,
        };
        let text = serde_json::to_string_pretty(&receipt).expect("serializes") + "\n";
        let written = crate::io::create_dir_all(&dir.join("receipts"))
            .and_then(|()| write_text(&path, &text));
        let result = outcome?;
        written?;
        Ok(result)
    }
}

/// What a finished job leaves, with its sha256 ([`Receipt::digests`]): an original's
/// manifest; a run's `audit_job.json` and the manifest of the original it ran on (a run on
/// a scene trained again since is not merged). A shared job's steps are the `full` run's,
/// whose receipt covers them: none.
fn job_digests(dir: &Path, job: &Job) -> Result<BTreeMap<String, String>> {
    let files: Vec<String> = match *job {
        Job::Original { .. } => vec![format!("{}/manifest.json", job.folder())],
        Job::Run { seed, .. } => vec![
            format!("{}/audit_job.json", job.folder()),
            format!("{}/manifest.json", Job::Original { seed }.folder()),
        ],
        Job::Shared { .. } => Vec::new(),
    };
    files
        .into_iter()
        .map(|rel| {
            let p = dir.join(&rel);
            let bytes = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
            Ok((rel, sha256_hex(&bytes)))
        })
        .collect()
}

/// `YYYY-MM-DDTHH:MM:SSZ` of a time (days to civil date: Howard Hinnant's algorithm).
pub fn utc(t: std::time::SystemTime) -> String {
    let secs = t
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rem) = ((secs / 86_400) as i64, secs % 86_400);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

// ---------------------------------------------------------------------------- merge

/// [`waves`] without the jobs a sequential run would not compute beside `pool`
/// (`report::pending`): run jobs pooled as this binary computes them, the originals of
/// seeds with no run left, and the shared steps of a (generator, seed) with no run left.
/// Waves may be left empty.
pub(super) fn pending_waves(cfg: &AuditConfig, pool: &super::samples::Samples) -> Vec<Wave> {
    let todo = super::report::pending(cfg, pool);
    let needed = |job: &Job| match *job {
        Job::Shared { generator, seed } => todo.iter().any(
            |t| matches!(*t, Job::Run { generator: g, seed: s, .. } if (g, s) == (generator, seed)),
        ),
        _ => todo.contains(job),
    };
    waves(cfg)
        .into_iter()
        .map(|mut w| {
            w.jobs.retain(needed);
            w
        })
        .collect()
}

/// A job the merge cannot take: its name, why, and where its log is (when known).
#[derive(Clone, Debug, PartialEq)]
pub struct Missing {
    pub job: String,
    pub why: String,
    pub log: Option<String>,
}

impl Audit<'_> {
    /// The waves still to run beside the samples in `DIR/samples.json.gz` and the `merge`
    /// files (`pending_waves`): what `--emit-slurm` submits and `--collect` expects.
    pub fn waves_to_run(&self, merge: &[PathBuf]) -> Result<Vec<Wave>> {
        self.cfg.validate()?;
        self.check_inputs()?;
        Ok(pending_waves(self.cfg, &self.gather(merge)?))
    }

    /// The merge: every job of every wave still to run beside the pooled samples
    /// (`pending_waves`: the same jobs `--emit-slurm` submitted, given the same
    /// samples) must have a receipt of a success whose digests still verify; the run jobs' results are read from their `audit_job.json` (nothing is
    /// computed) and reported as [`Audit::run`] reports them. `log_of` names a job's log for
    /// jobs without a receipt (a receipt names its own). `Ok(Err(missing))`: what is missing
    /// or failed, in wave order; nothing is written then.
    pub fn collect(
        &self,
        merge: &[PathBuf],
        log_of: &dyn Fn(&Job) -> Option<String>,
    ) -> Result<std::result::Result<Report, Vec<Missing>>> {
        self.cfg.validate()?;
        self.check_inputs()?;
        let pool = self.gather(merge)?;
        let mut missing = Vec::new();
        let mut results = Vec::new();
        for job in pending_waves(self.cfg, &pool)
            .into_iter()
            .flat_map(|w| w.jobs)
        {
            match self.take(&job) {
                Ok(Some(r)) => results.push(r),
                Ok(None) => {}
                Err((why, log)) => missing.push(Missing {
                    job: job.name(),
                    why,
                    log: log.or_else(|| log_of(&job)),
                }),
            }
        }
        if !missing.is_empty() {
            return Ok(Err(missing));
        }
        // With every job pooled no worker made the folder.
        crate::io::create_dir_all(self.dir)?;
        Ok(Ok(self.finish(pool, results)?))
    }

    /// A finished job's result (`None` for jobs without one), or why it is not finished and
    /// the log its receipt names.
    fn take(&self, job: &Job) -> std::result::Result<Option<JobResult>, (String, Option<String>)> {
        let (cfg, dir) = (self.cfg, self.dir);
        let path = receipt_path(dir, job);
        let bytes = std::fs::read(&path).map_err(|_| {
            (
                "no receipt: the job did not end (killed, out of time or memory, cancelled after \
             a failed wave, or never submitted)"
                    .to_string(),
                None,
            )
        })?;
        let r: Receipt = serde_json::from_slice(&bytes)
            .ok()
            .filter(|r: &Receipt| r.format == RECEIPT_FORMAT && r.job == job.name())
            .ok_or_else(|| (format!("{} is not its receipt", path.display()), None))?;
        let fail = |why: String| (why, r.log.clone());
        if r.exit != 0 {
            return Err(fail(format!(
                "failed on {} after {:.0} s: {}",
                r.host,
                r.seconds,
                r.error.as_deref().unwrap_or("no message")
            )));
        }
        if r.numerics_revision != crate::version::NUMERICS_REVISION {
            return Err(fail(format!(
                "computed by numerics revision {} (this binary: {}): run it again",
                r.numerics_revision,
                crate::version::NUMERICS_REVISION
            )));
        }
        for (rel, sha) in &r.digests {
            let ok = std::fs::read(dir.join(rel)).is_ok_and(|b| sha256_hex(&b) == *sha);
            if !ok {
                return Err(fail(format!(
                    "{rel} is missing or changed since the job's receipt"
                )));
            }
        }
        match job {
            Job::Run {
                generator,
                variant,
                seed,
            } => {
                let p = dir.join(job.folder()).join("audit_job.json");
                let result: JobResult = std::fs::read(&p)
                    .ok()
                    .and_then(|b| serde_json::from_slice(&b).ok())
                    .ok_or_else(|| fail(format!("{} cannot be read", p.display())))?;
                let config = cfg
                    .config_digest(*generator, *variant)
                    .map_err(|e| fail(e.to_string()))?;
                let family = &self.candidates.family;
                let same = result.generator == generator.name()
                    && result.variant == variant.name()
                    && result.seed == *seed
                    && result.config == config
                    && result.candidates == *family;
                if !same {
                    return Err(fail(format!(
                        "{} is of another job or configuration",
                        p.display()
                    )));
                }
                Ok(Some(result))
            }
            Job::Original { seed } => {
                let run = dir.join(job.folder());
                if self.original_done(&run, *seed) {
                    Ok(None)
                } else {
                    Err(fail(
                        "trained on another dataset or with another training configuration than \
                     this audit's (or damaged)"
                            .into(),
                    ))
                }
            }
            Job::Shared { .. } => Ok(None),
        }
    }
}

// ------------------------------------------------------------------------ estimates

/// The work of a job in training iteration-pixels: the model behind [`Audit::estimate`]. A cycle
/// run (SPEC.md §20.11) fine-tunes a QA-Mask at every trajectory view after the first,
/// which the bound plan of one candidate does not hold: its trajectory is priced at the
/// dataset's `candidates` views.
fn work(cfg: &AuditConfig, job: &Job, (pixels, candidates): (f64, usize)) -> f64 {
    let config = |generator, variant, seed| {
        cfg.pipeline_config(generator, variant, seed)
            .unwrap_or_else(|_| cfg.base.clone())
    };
    match *job {
        Job::Original { .. } => f64::from(cfg.train_iterations) * pixels,
        // The `full` run's steps before the stage-1 reconstruction (of them, the original
        // scene's QA-Mask is the training; the generations are small beside it).
        Job::Shared { generator, seed } => scoped_work(
            &config(generator, Variant::Full, seed),
            &Scope::Before(SHARED_BEFORE),
            pixels,
        ),
        Job::Run {
            generator,
            variant,
            seed,
        } => {
            let pc = config(generator, variant, seed);
            let cycle_qa = match (pc.paradigm, pc.mask_source) {
                (Paradigm::Cycle, MaskSource::Qa) => candidates.saturating_sub(1) as f64,
                _ => 0.0,
            };
            pipeline_work(&pc, pixels) + cycle_qa * f64::from(pc.qa_iterations) * pixels
        }
    }
}

/// The training pixels of the dataset at the audit's training resolution (from its first
/// candidate camera's size), and its number of candidate views.
fn training_pixels(cfg: &AuditConfig, file: &Path) -> Result<(f64, usize)> {
    let cams = crate::camera::inria::read_cameras_json(file)?;
    let c = cams
        .first()
        .ok_or_else(|| Error::invalid("lists no camera").at(file))?;
    let r = f64::from(cfg.train_resolution.max(1));
    let pixels = (f64::from(c.width) / r).round() * (f64::from(c.height) / r).round();
    Ok((pixels, cams.len()))
}

impl Audit<'_> {
    /// The expected [`Cost`] of every job still to run beside the samples in `DIR` and the
    /// `merge` files ([`Audit::waves_to_run`]), wave by wave. Where `dir` holds finished jobs of this
    /// audit (receipts of successes), their measured seconds and peak memory (the steps'
    /// `cost.json`, the original's `train_stats.json`) replace the calibration for their kind:
    /// seconds per iteration-pixel averaged over them, memory their maximum.
    pub fn estimate(&self, merge: &[PathBuf]) -> Result<Vec<(Wave, Vec<Cost>)>> {
        let (cfg, dir) = (self.cfg, self.dir);
        let shape = training_pixels(cfg, &self.candidates.file)?;
        let pixels = shape.0;
        let kind = |j: &Job| match j {
            Job::Original { .. } => 0,
            Job::Shared { .. } => 1,
            Job::Run { .. } => 2,
        };
        // Measured: (seconds / work summed, work summed, peak memory) per kind.
        let mut measured = [(0.0f64, 0.0f64, 0.0f64); 3];
        for job in waves(cfg).iter().flat_map(|w| &w.jobs) {
            let Some((seconds, peak)) = measured_cost(dir, job) else {
                continue;
            };
            let m = &mut measured[kind(job)];
            m.0 += seconds;
            m.1 += work(cfg, job, shape);
            m.2 = m.2.max(peak);
        }
        Ok(self
            .waves_to_run(merge)?
            .into_iter()
            .map(|w| {
                let costs = w
                    .jobs
                    .iter()
                    .map(|j| {
                        let k = kind(j);
                        let units = work(cfg, j, shape);
                        let c = Calibration::of(cfg.base.preset);
                        let (rate, bytes_per_pixel) = match j {
                            Job::Original { .. } => (c.original_seconds, c.original_bytes),
                            _ => (c.pipeline_seconds, c.pipeline_bytes),
                        };
                        let (s, u, peak) = measured[k];
                        if u > 0.0 && peak > 0.0 {
                            Cost {
                                seconds: s / u * units,
                                peak_rss_bytes: peak,
                                measured: true,
                            }
                        } else {
                            Cost {
                                seconds: rate * units,
                                peak_rss_bytes: BASE_BYTES + bytes_per_pixel * pixels,
                                measured: false,
                            }
                        }
                    })
                    .collect();
                (w, costs)
            })
            .collect())
    }
}

/// A finished job's seconds (its receipt) and peak memory (its steps' or training's
/// records), if it succeeded in `dir`.
fn measured_cost(dir: &Path, job: &Job) -> Option<(f64, f64)> {
    let r: Receipt = serde_json::from_slice(&std::fs::read(receipt_path(dir, job)).ok()?).ok()?;
    if r.exit != 0 || r.seconds <= 0.0 {
        return None;
    }
    let folder = dir.join(job.folder());
    let peak = match job {
        Job::Original { .. } => {
            let s: serde_json::Value =
                serde_json::from_slice(&std::fs::read(folder.join("train_stats.json")).ok()?)
                    .ok()?;
            s["peak_memory_bytes"].as_f64()?
        }
        _ => {
            let t: BTreeMap<String, crate::io::Cost> =
                serde_json::from_slice(&std::fs::read(folder.join("timings.json")).ok()?).ok()?;
            t.values()
                .filter_map(|c| c.peak_rss_bytes)
                .max()
                .map(|b| b as f64)?
        }
    };
    Some((r.seconds, peak))
}

// ------------------------------------------------------------------------- Slurm

impl Audit<'_> {
    /// Write a Slurm submission folder `out` for the jobs of the audit still to run beside
    /// its pooled samples ([`Audit::waves_to_run`]; a wave left empty gets no array)
    /// ([`write_submission`]): also `jobs.txt` (every such job, wave by wave) and per wave `wave-N-<name>.txt` (its jobs; array
    /// task i runs line i+1 as `unseen … --only JOB`); the merge runs `unseen … --collect`.
    /// `command` is the worker's command line without `--only` (binary first, the audit's grid
    /// in absolute paths). Returns the waves with their requests.
    pub fn emit_slurm(
        &self,
        command: &[String],
        merge: &[PathBuf],
        out: &Path,
        opts: &SlurmOptions,
    ) -> Result<Vec<(Wave, Request)>> {
        if out.is_file() {
            return Err(Error::invalid("the submission path is a file").at(out));
        }
        let estimates = self.estimate(merge)?;
        let cpus = opts.cpus.unwrap_or(2).max(1);
        crate::io::create_dir_all(out)?;
        let logs = out.join("logs");
        let cmd: Vec<String> = command.iter().map(|a| shell_quote(a)).collect();
        let cmd = cmd.join(" ");
        let mut all = String::new();
        let mut arrays = Vec::new();
        let mut emitted = Vec::new();
        for (wave, costs) in estimates {
            if wave.jobs.is_empty() {
                continue;
            }
            let list: String = wave.jobs.iter().map(|j| j.name() + "\n").collect();
            all += &list;
            let list_path = out.join(format!("wave-{}-{}.txt", arrays.len() + 1, wave.name));
            write_text(&list_path, &list)?;
            let log = shell_quote(&format!("{}/{}-", logs.display(), wave.name));
            let body = format!(
                "job=$(sed -n \"$((SLURM_ARRAY_TASK_ID + 1))p\" {})\n\
             exec {cmd} --only \"$job\" --threads \"${{SLURM_CPUS_PER_TASK:-{cpus}}}\" \
             --log {log}\"$SLURM_ARRAY_TASK_ID\".out\n",
                shell_quote(&list_path.display().to_string()),
            );
            let req = request(&costs, cpus);
            arrays.push(ArrayWave {
                name: wave.name.into(),
                tasks: wave.jobs.len(),
                request: req.clone(),
                body,
            });
            emitted.push((wave, req));
        }
        write_text(&out.join("jobs.txt"), &all)?;
        let merge = ArrayWave {
            name: "merge".into(),
            tasks: 1,
            request: least_request(1),
            body: format!(
                "exec {cmd} --collect --submission {}\n",
                shell_quote(&out.display().to_string())
            ),
        };
        write_submission(out, &arrays, Some(&merge), opts)?;
        Ok(emitted)
    }
}

/// The log the submission folder `submission` gives `job` ([`Audit::emit_slurm`]'s names)
/// among the `waves` it submitted ([`Audit::waves_to_run`]).
pub fn log_in_submission(waves: &[Wave], submission: &Path, job: &Job) -> Option<String> {
    waves.iter().find_map(|w| {
        let i = w.jobs.iter().position(|j| j == job)?;
        Some(
            submission
                .join("logs")
                .join(format!("{}-{i}.out", w.name))
                .display()
                .to_string(),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::super::{GeneratorKind, Variant};
    use super::*;

    #[test]
    fn utc_formats_known_instants() {
        let at = |s: u64| utc(std::time::UNIX_EPOCH + std::time::Duration::from_secs(s));
        assert_eq!(at(0), "1970-01-01T00:00:00Z");
        assert_eq!(at(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(at(1_795_675_953), "2026-11-26T06:52:33Z");
    }

    /// A cycle run fine-tunes a QA-Mask at every trajectory view after the first: priced
    /// at the dataset's candidate count, which the bound plan of one candidate misses.
    #[test]
    fn a_cycle_run_is_priced_with_a_qa_mask_per_trajectory_view() {
        let cfg = AuditConfig::quick();
        let run = |variant| Job::Run {
            generator: GeneratorKind::Truth(crate::pipeline::Level::Low),
            variant,
            seed: 0,
        };
        let pc = cfg
            .pipeline_config(
                GeneratorKind::Truth(crate::pipeline::Level::Low),
                Variant::Cycle,
                0,
            )
            .unwrap();
        let base = pipeline_work(&pc, 100.0);
        assert_eq!(work(&cfg, &run(Variant::Cycle), (100.0, 1)), base);
        let twelve = work(&cfg, &run(Variant::Cycle), (100.0, 12));
        assert_eq!(twelve, base + 11.0 * f64::from(pc.qa_iterations) * 100.0);
        // The full run's work does not depend on the candidate count.
        let full = work(&cfg, &run(Variant::Full), (100.0, 12));
        assert_eq!(full, work(&cfg, &run(Variant::Full), (100.0, 1)));
        assert!(twelve > full, "{twelve} vs {full}");
    }

    #[test]
    fn waves_hold_every_job_once_originals_first() {
        let cfg = AuditConfig {
            variants: vec![Variant::Full, Variant::EvenViews],
            seeds: 3..5,
            ..AuditConfig::quick()
        };
        let w = waves(&cfg);
        assert_eq!(
            w.iter().map(|w| w.jobs.len()).collect::<Vec<_>>(),
            [2, 4, 8]
        );
        let flat: Vec<Job> = w.iter().flat_map(|w| w.jobs.clone()).collect();
        let listed = jobs(&cfg);
        assert!(listed.iter().all(|j| flat.contains(j)));
        assert_eq!(w[1].jobs[0].folder(), "runs/classical/full/seed-3");
    }
}
