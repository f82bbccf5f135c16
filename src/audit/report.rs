//! The audit's report: gathering the samples, `audit.json`, `audit.md` and its plot.

use super::jobs::{Job, JobResult, jobs, sharing};
use super::samples::{self, Samples};
use super::stats;
use super::verdicts::{Metric, Region, Verdict, mean_std, median_seed, metrics_only, verdicts};
use super::{Audit, AuditConfig, GeneratorKind, Variant};
use crate::error::{Error, Result};
use crate::pipeline::Event;
use crate::pipeline::Level;
use crate::pipeline::evaluate::Row;
use std::path::PathBuf;

/// What `audit.json` holds.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Report {
    /// The binary that made the report: samples of other revisions are pooled (each
    /// sample names its own, in `samples.json.gz`).
    pub crate_version: String,
    pub numerics_revision: u32,
    #[serde(flatten)]
    pub provenance: samples::Provenance,
    /// Distinct seeds and numerics revisions of the pooled samples.
    pub seeds: Vec<u32>,
    pub revisions: Vec<u32>,
    pub samples: usize,
    /// Samples of another pipeline configuration of their (generator, variant) than this
    /// binary's: kept in `samples.json.gz`, left out of every verdict.
    pub other_config: usize,
    pub generators: Vec<String>,
    pub variants: Vec<String>,
    /// The verdict rule's parameters.
    pub rule: stats::Rule,
    pub verdicts: Vec<Verdict>,
    /// Each claim's Δ along each generator sweep (SPEC.md §21.6; absent without one).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub responses: Vec<super::dose::Response>,
    /// This batch's job results (with their steps): what the step cache saved.
    #[serde(skip)]
    pub results: Vec<JobResult>,
    /// Every pooled sample.
    #[serde(skip)]
    pub pool: Vec<JobResult>,
    /// Per primary claim on contested pixels (by its index in `verdicts`), the contact
    /// sheet of the seed nearest its median among those whose sheet the audit's folder
    /// has (SPEC.md §21.7).
    #[serde(skip)]
    /// `(verdict, seed, whether it is the median seed itself, path)`.
    pub sheets: Vec<(usize, u32, bool, std::path::PathBuf)>,
}

impl Audit<'_> {
    /// The samples an audit of `cfg` in `dir` pools with its own batch: `dir`'s
    /// [`samples::SAMPLES_FILE`] and every `merge` file (another audit's samples, or an
    /// `audit.json` of an earlier version). Read before any job runs, so that a file that
    /// cannot be pooled fails the audit at once.
    pub(super) fn gather(&self, merge: &[PathBuf]) -> Result<Samples> {
        let Audit {
            cfg, dataset, dir, ..
        } = *self;
        let mut pool = Samples::new(samples::Provenance {
            dataset: samples::dataset_name(dataset),
            dataset_digest: samples::dataset_digest(dataset)?,
            preset: cfg.base.preset,
            train_iterations: cfg.train_iterations,
            train_resolution: cfg.train_resolution,
            candidates: self.candidates.family.clone(),
        });
        for f in samples::files_in(dir)
            .into_iter()
            .chain(merge.iter().cloned())
        {
            let s = Samples::read(&f)?;
            pool.pool(s, &f)?;
        }
        Ok(pool)
    }

    /// Run every job of `cfg` that is not done — neither pooled as this binary would compute
    /// it (`pending`) nor finished in its folder (each resumes its own) — pool the
    /// results with the samples already in `dir` and in `merge` files, then write
    /// `DIR/samples.json.gz`, `DIR/audit.json`, `DIR/audit.md` and `DIR/inconsistency.svg`.
    pub fn run(&self, merge: &[PathBuf]) -> Result<Report> {
        self.cfg.validate()?;
        self.check_inputs()?;
        let pool = self.gather(merge)?;
        crate::io::create_dir_all(self.dir)?;
        let todo = pending(self.cfg, &pool);
        let runs = |v: &[Job]| v.iter().filter(|j| matches!(j, Job::Run { .. })).count();
        let pooled = runs(&jobs(self.cfg)) - runs(&todo);
        if pooled > 0 {
            (self.on_event)(Event::Note(format!(
                "{pooled} run jobs are pooled as this binary computes them: not run again"
            )));
        }
        let mut results = Vec::new();
        for job in todo {
            if let Some(r) = self.run_job(&job)? {
                results.push(r);
            }
        }
        self.finish(pool, results)
    }

    /// The report of the samples in `dir` and `merge` files alone (no job runs).
    pub fn report(&self, merge: &[PathBuf]) -> Result<Report> {
        let dir = self.dir;
        self.cfg.validate()?;
        self.check_inputs()?;
        let pool = self.gather(merge)?;
        if pool.samples.is_empty() {
            return Err(Error::invalid(format!(
                "no samples to report (no {} or {} here and no --merge file)",
                samples::SAMPLES_FILE,
                samples::LEGACY_SAMPLES_FILE
            ))
            .at(dir));
        }
        crate::io::create_dir_all(dir)?;
        self.finish(pool, Vec::new())
    }

    pub(super) fn finish(&self, mut pool: Samples, results: Vec<JobResult>) -> Result<Report> {
        let (cfg, dir) = (self.cfg, self.dir);
        for r in &results {
            pool.insert(r.clone());
        }
        self.pair_up(&mut pool)?;
        pool.write(&dir.join(samples::SAMPLES_FILE))?;
        let legacy = dir.join(samples::LEGACY_SAMPLES_FILE);
        if legacy.is_file() {
            // Its samples were pooled by `gather` and are now in the compressed file.
            std::fs::remove_file(&legacy).map_err(|e| Error::io(&legacy, e))?;
        }
        let rule = stats::Rule {
            planned: cfg.planned_seeds,
            ..stats::Rule::default()
        };
        let (seeds, revisions) = pool.seeds_and_revisions();
        let names = |mut v: Vec<String>| {
            v.dedup();
            v
        };
        // Samples of another configuration of their cell than this binary's are kept in the
        // file and left out of everything reported.
        let other = |r: &JobResult| {
            let (Ok(g), Ok(v)) = (
                GeneratorKind::by_name(&r.generator),
                r.variant.parse::<Variant>(),
            ) else {
                return false;
            };
            cfg.config_digest(g, v).is_ok_and(|d| d != r.config)
        };
        let total = pool.samples.len();
        let usable: Vec<JobResult> = pool.samples.into_iter().filter(|r| !other(r)).collect();
        let verdicts = verdicts(cfg, &usable, &rule);
        let responses = super::dose::responses(&verdicts);
        let sheets = verdicts
            .iter()
            .enumerate()
            .filter(|(_, v)| {
                v.claim.metric.is_primary()
                    && matches!(v.claim.metric, Metric::Classes(_, Region::Contested))
            })
            .filter_map(|(k, v)| {
                let path = |seed| {
                    super::pairs::sheet_path(&v.generator.name(), v.claim.variant.name(), seed)
                };
                let seed = median_seed(&usable, v, |seed| dir.join(path(seed)).is_file())?;
                let median = median_seed(&usable, v, |_| true) == Some(seed);
                Some((k, seed, median, path(seed)))
            })
            .collect();
        let report = Report {
            crate_version: env!("CARGO_PKG_VERSION").into(),
            numerics_revision: crate::version::NUMERICS_REVISION,
            provenance: pool.provenance.clone(),
            seeds,
            revisions,
            samples: usable.len(),
            other_config: total - usable.len(),
            generators: names(cfg.generators.iter().map(|g| g.name()).collect()),
            variants: names(cfg.variants.iter().map(|v| v.name().to_string()).collect()),
            verdicts,
            responses,
            rule,
            results,
            pool: usable,
            sheets,
        };
        let json = serde_json::to_string_pretty(&report).expect("serializes") + "\n";
        crate::io::write_text(&dir.join("audit.json"), &json)?;
        crate::io::write_text(&dir.join("inconsistency.svg"), &plot(cfg, &report.pool))?;
        for r in &report.responses {
            crate::io::write_text(&dir.join(super::dose::plot_name(r)), &super::dose::plot(r))?;
        }
        crate::io::write_text(&dir.join("audit.md"), &markdown(cfg, &report))?;
        Ok(report)
    }
}

/// The jobs of [`jobs`] that a sequential run still computes beside `pool`: a run job whose
/// sample is pooled as this binary would compute it ([`JobResult::reproduces`]) is not
/// run again, and neither is the original scene of a seed none of whose runs is left.
/// Dose grids and new variants on seeds already pooled then compute only what is new.
pub(super) fn pending(cfg: &AuditConfig, pool: &Samples) -> Vec<Job> {
    let done = |generator: GeneratorKind, variant: Variant, seed: u32| {
        let (g, v) = (generator.name(), variant.name());
        pool.samples.iter().any(|r| {
            (r.generator.as_str(), r.variant.as_str(), r.seed) == (g.as_str(), v, seed)
                && cfg
                    .config_digest(generator, variant)
                    .is_ok_and(|d| r.reproduces(&d))
        })
    };
    let runs: Vec<Job> = jobs(cfg)
        .into_iter()
        .filter(|j| match *j {
            Job::Run {
                generator,
                variant,
                seed,
            } => !done(generator, variant, seed),
            _ => false,
        })
        .collect();
    let needs_original = |s: u32| {
        runs.iter()
            .any(|j| matches!(*j, Job::Run { seed, .. } if seed == s))
    };
    let mut out: Vec<Job> = cfg
        .seeds
        .clone()
        .filter(|&s| needs_original(s))
        .map(|seed| Job::Original { seed })
        .collect();
    out.extend(runs);
    out
}

/// `mean ± std` over the seeds of one (generator, variant), or `mean` with one seed.
fn stat(results: &[&JobResult], f: impl Fn(&JobResult) -> f64, digits: usize) -> String {
    let v: Vec<f64> = results.iter().map(|r| f(r)).collect();
    let (m, s) = mean_std(&v);
    let m = crate::io::json_float::show(m, digits);
    if s.is_finite() {
        format!("{m} ± {s:.digits$}")
    } else {
        m
    }
}

/// The distinct samples of one (generator, variant) in pool order (a sample another
/// revision reproduced bit for bit counts once).
fn group<'a>(results: &'a [JobResult], generator: &str, variant: Variant) -> Vec<&'a JobResult> {
    let bits = |r: &JobResult| serde_json::to_string(&metrics_only(&r.last)).expect("serializes");
    let mut out: Vec<&JobResult> = Vec::new();
    for r in results
        .iter()
        .filter(|r| r.generator == generator && r.variant == variant.name())
    {
        if !out.iter().any(|o| o.seed == r.seed && bits(o) == bits(r)) {
            out.push(r);
        }
    }
    out
}

/// `0–11, 14` for seeds 0..=11 and 14.
fn seed_ranges(seeds: &[u32]) -> String {
    let mut parts = Vec::new();
    let mut i = 0;
    while i < seeds.len() {
        let mut j = i;
        while j + 1 < seeds.len() && seeds[j].checked_add(1) == Some(seeds[j + 1]) {
            j += 1;
        }
        parts.push(if j > i {
            format!("{}–{}", seeds[i], seeds[j])
        } else {
            seeds[i].to_string()
        });
        i = j + 1;
    }
    parts.join(", ")
}

/// The six metric cells of a table row (PSNR existing, extrapolated, all; SSIM existing,
/// extrapolated; train-half PSNR) of the scene `pick` selects, over the seeds.
fn metric_cells(rows: &[&JobResult], pick: impl Fn(&JobResult) -> &Row) -> String {
    [
        stat(rows, |r| pick(r).psnr_existing, 2),
        stat(rows, |r| pick(r).psnr_extrapolated, 2),
        stat(rows, |r| pick(r).psnr_all, 2),
        stat(rows, |r| pick(r).ssim_existing, 4),
        stat(rows, |r| pick(r).ssim_extrapolated, 4),
        stat(rows, |r| pick(r).psnr_train_half, 2),
    ]
    .join(" | ")
}

/// Diagnostics of one (generator, variant), mean over the seeds that recorded them.
struct DiagnosticsMean {
    seeds: usize,
    candidates: f64,
    covered: f64,
    set_aside: f64,
    collisions: f64,
    pairs: f64,
    stage1_views: f64,
    stage1_collisions: f64,
    dependent_per_gap: f64,
    degenerate_gaps: f64,
    unmade_gaps: f64,
    coverage: f64,
    overlap: f64,
    conflict: f64,
    stage2_filled: f64,
}

fn diagnostics_mean(rows: &[&JobResult]) -> Option<DiagnosticsMean> {
    let d: Vec<&super::diagnostics::Diagnostics> =
        rows.iter().filter_map(|r| r.diagnostics.as_ref()).collect();
    if d.is_empty() {
        return None;
    }
    // The mean of the finite values (NaN when none is).
    let mean = |f: &dyn Fn(&super::diagnostics::Diagnostics) -> f64| {
        let v: Vec<f64> = d.iter().map(|x| f(x)).filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    let generated = |f: fn(&super::diagnostics::Generation) -> f64| {
        mean(&|x| x.stage1.as_ref().map_or(f64::NAN, f))
    };
    Some(DiagnosticsMean {
        seeds: d.len(),
        candidates: mean(&|x| x.candidates as f64),
        covered: mean(&|x| x.covered as f64),
        set_aside: mean(&|x| x.set_aside.len() as f64),
        collisions: mean(&|x| x.collisions as f64),
        pairs: mean(&|x| x.pairs as f64),
        stage1_views: mean(&|x| x.stage1_views.len() as f64),
        stage1_collisions: mean(&|x| x.stage1_collisions as f64),
        dependent_per_gap: mean(&|x| {
            let g = &x.dependent_per_gap;
            g.iter().sum::<usize>() as f64 / g.len().max(1) as f64
        }),
        degenerate_gaps: mean(&|x| x.degenerate_gaps as f64),
        unmade_gaps: mean(&|x| x.unmade_gaps as f64),
        coverage: generated(|g| g.coverage),
        overlap: generated(|g| g.overlap),
        conflict: generated(|g| g.conflict),
        stage2_filled: mean(&|x| x.stage2_filled),
    })
}

/// A number with `digits` decimals, `∞`, or `–` (NaN, −∞: nothing to show).
/// A p-value to three decimals, or `< 0.001` below (never a p of "0.000").
fn p_value(p: f64) -> String {
    if p < 0.001 {
        "< 0.001".into()
    } else {
        format!("{p:.3}")
    }
}

fn num(x: f64, digits: usize) -> String {
    if x.is_finite() {
        format!("{x:.digits$}")
    } else if x == f64::INFINITY {
        "∞".into()
    } else {
        "–".into()
    }
}

/// A share as a percentage, or `–`.
fn percent(x: f64) -> String {
    if x.is_finite() {
        format!("{:.0} %", 100.0 * x)
    } else {
        "–".into()
    }
}

/// The claims table's *rests on* cell: the stage-1 views, their coverage, overlap and
/// conflict under full → under the variant, and the seeds on which both runs are the same
/// computation.
fn rests_on(pool: &[JobResult], v: &Verdict) -> String {
    let claim = &v.claim;
    if claim.baseline == super::verdicts::Baseline::Original {
        return "full's final scene against its original scene".into();
    }
    let (full, var) = (
        group(pool, &v.generator.name(), claim.reference),
        group(pool, &v.generator.name(), claim.variant),
    );
    let (Some(a), Some(b)) = (diagnostics_mean(&full), diagnostics_mean(&var)) else {
        return "(not recorded)".into();
    };
    // The verdict's own count, over the seeds of its plan.
    let (same, paired) = (v.same_computation, v.same_computation + v.judged);
    // The conflicting set's match of the independent set's coverage (SPEC.md §20.2).
    let weights: Vec<f64> = var
        .iter()
        .filter_map(|r| {
            r.diagnostics
                .as_ref()?
                .choice
                .as_ref()?
                .conflicting
                .as_ref()
        })
        .filter(|c| c.used)
        .map(|c| c.coverage_difference)
        .collect();
    let matched = if weights.is_empty() {
        String::new()
    } else {
        let worst = weights.iter().copied().fold(0.0, f64::max);
        format!(
            "; coverage matched on {} runs (worst {:.1} %)",
            weights.len(),
            100.0 * worst
        )
    };
    // Seeds where the conflicting set was not used count as not tested too (verdicts'
    // `Pair::not_applied`).
    let untested = if claim.variant == Variant::ConflictingViews {
        format!("not tested {same} of {paired} (same scene, or no colliding set qualified)")
    } else {
        format!("same computation {same} of {paired}")
    };
    format!(
        "views {} → {}; coverage {} → {}; overlap {} → {}; conflict {} → {}; {untested}{matched}",
        num(a.stage1_views, 1),
        num(b.stage1_views, 1),
        percent(a.coverage),
        percent(b.coverage),
        percent(a.overlap),
        percent(b.overlap),
        num(a.conflict, 4),
        num(b.conflict, 4),
    )
}

/// `audit.md`'s table of what each (generator, variant) did, mean over its seeds
/// (SPEC.md §21.5), and the reasons candidates were set aside.
fn diagnostics_table(cfg: &AuditConfig, pool: &[JobResult]) -> String {
    let mut s = "\n## What each run did (diagnostics, mean over seeds)\n\n*Candidates*: given (covered by the scene / set aside). *Collisions*: colliding pairs of the candidates left, of all their pairs. *Stage-1 views*: the set stage 1 generates (its colliding pairs). *Coverage* / *overlap*: share of the evaluation views' extrapolated pixels (truth depth: the unseen surface) whose surface point ≥ 1 / ≥ 2 stage-1 views generated; *conflict*: mean squared colour difference of two stage-1 generations of one point. *Stage 2 filled*: share of the dependent views' pixels stage 2 inpainted. †: the cycle has no stage 1; the views detection picked, which its trajectory runs through (it generates every trajectory view in turn, so no stage-1 coverage is measured). Degenerate gaps run from a view to itself (a one-view tour); *unmade* gaps got no camera (the truth half-way cannot be made: its camera sees neither end).\n\n| generator | variant | seeds | candidates (covered / set aside) | collisions / pairs | stage-1 views (colliding pairs) | dependent per gap | degenerate / unmade gaps | coverage | overlap | conflict | stage 2 filled |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n".to_string();
    let mut reasons: Vec<(String, usize)> = Vec::new();
    for g in &cfg.generators {
        let g = g.name();
        for v in &cfg.variants {
            let rows = group(pool, &g, *v);
            for a in rows
                .iter()
                .filter_map(|r| r.diagnostics.as_ref())
                .flat_map(|d| &d.set_aside)
            {
                match reasons.iter_mut().find(|(r, _)| *r == a.reason) {
                    Some((_, n)) => *n += 1,
                    None => reasons.push((a.reason.clone(), 1)),
                }
            }
            let Some(d) = diagnostics_mean(&rows) else {
                continue;
            };
            s += &format!(
                "| {g} | {} | {} | {} ({} / {}) | {} / {} | {} ({}){} | {} | {} / {} | {} | {} | {} | {} |\n",
                v.name(),
                d.seeds,
                num(d.candidates, 1),
                num(d.covered, 1),
                num(d.set_aside, 1),
                num(d.collisions, 1),
                num(d.pairs, 1),
                num(d.stage1_views, 1),
                num(d.stage1_collisions, 1),
                if *v == Variant::Cycle { " †" } else { "" },
                num(d.dependent_per_gap, 1),
                num(d.degenerate_gaps, 1),
                num(d.unmade_gaps, 1),
                percent(d.coverage),
                percent(d.overlap),
                num(d.conflict, 4),
                percent(d.stage2_filled),
            );
        }
    }
    if !reasons.is_empty() {
        s += "\nSet aside (runs × candidates): ";
        let list: Vec<String> = reasons.iter().map(|(r, n)| format!("{n} × {r}")).collect();
        s += &list.join("; ");
        s += ".\n";
    }
    s
}

/// `audit.md`'s sensitivity rows: the independent-views claim under each choice the
/// paper leaves open that was run (empty when none was).
/// audit.md's training half per stage (issue #72): per generator and variant, over the
/// seeds that recorded their stages ([`super::jobs::StageRecord`]), each scene's change of
/// training-half PSNR from the scene before it and the whole run's, as the median with the
/// seeds above / below 0, and the Gaussian counts; empty when no sample recorded them.
fn training_half_table(cfg: &AuditConfig, pool: &[JobResult]) -> String {
    let median = |v: &[f64]| {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        super::stats::quantile_sorted(&s, 0.5)
    };
    let mut rows = String::new();
    for g in &cfg.generators {
        let g = g.name();
        for v in &cfg.variants {
            let runs: Vec<&JobResult> = group(pool, &g, *v)
                .into_iter()
                .filter(|r| r.stages.len() >= 2)
                .collect();
            let Some(first) = runs.first() else {
                continue;
            };
            // The scenes of the first run; runs with another sequence are left out.
            let names: Vec<&str> = first.stages.iter().map(|s| s.scene.as_str()).collect();
            let runs: Vec<&JobResult> = runs
                .into_iter()
                .filter(|r| {
                    r.stages
                        .iter()
                        .map(|s| s.scene.as_str())
                        .eq(names.iter().copied())
                })
                .collect();
            let change = |k: usize, from: usize| {
                let d: Vec<f64> = runs
                    .iter()
                    .map(|r| r.stages[k].psnr_train_half - r.stages[from].psnr_train_half)
                    .filter(|d| d.is_finite())
                    .collect();
                if d.is_empty() {
                    return "–".to_string();
                }
                let (up, down) = (
                    d.iter().filter(|&&x| x > 0.0).count(),
                    d.iter().filter(|&&x| x < 0.0).count(),
                );
                format!("{:+.2} ({up} / {down})", median(&d))
            };
            let steps: Vec<String> = (1..names.len())
                .map(|k| format!("{} {}", names[k], change(k, k - 1)))
                .collect();
            let orig: Vec<f64> = runs.iter().map(|r| r.stages[0].psnr_train_half).collect();
            // The final scene's change split along its lineage (runs that recorded it):
            // the original Gaussians' descendants alone against the original scene, and
            // what the added Gaussians do on top.
            let last = names.len() - 1;
            let split = |part: &dyn Fn(&JobResult) -> Option<f64>| {
                let d: Vec<f64> = runs
                    .iter()
                    .filter_map(|r| part(r))
                    .filter(|d| d.is_finite())
                    .collect();
                if d.is_empty() {
                    return "–".to_string();
                }
                let (up, down) = (
                    d.iter().filter(|&&x| x > 0.0).count(),
                    d.iter().filter(|&&x| x < 0.0).count(),
                );
                format!("{:+.2} ({up} / {down})", median(&d))
            };
            let within = split(&|r| {
                let l = r.stages[last].lineage.as_ref()?;
                Some(l.psnr_train_half_originals - r.stages[0].psnr_train_half)
            });
            let added = split(&|r| {
                let l = r.stages[last].lineage.as_ref()?;
                Some(r.stages[last].psnr_train_half - l.psnr_train_half_originals)
            });
            let count = |k: usize| {
                runs.iter()
                    .map(|r| r.stages[k].gaussians as f64)
                    .sum::<f64>()
                    / runs.len() as f64
            };
            rows += &format!(
                "| {g} | {} | {} | {:.2} | {} | {} | {within} | {added} | {:.0} → {:.0} |\n",
                v.name(),
                runs.len(),
                median(&orig),
                steps.join("; "),
                change(last, 0),
                count(0),
                count(last)
            );
        }
    }
    if rows.is_empty() {
        return rows;
    }
    let attribution = attribution_table(cfg, pool);
    training_half_text(rows) + &attribution
}

/// The training-half table's text around its rows.
fn training_half_text(rows: String) -> String {
    "\n## The training half per stage (issue #72)\n\nWhere original areas change: each scene's training-half PSNR (dB) against the scene before it, and the final scene's against the original, as the median over the seeds with the seeds above / below 0; the Gaussians of the original and the final scene (mean). The final change split along the Gaussians' lineage (runs that recorded it): the final scene's Gaussians descending from the original scene's, rendered alone, against the original scene (*within the originals*: moved, densified, pruned), and the whole final scene against them (*added Gaussians*: what the pipeline's Gaussians do on the training views). The recipe's control `originals_only` runs the same fine-tunes on the original views alone.\n\n| generator | variant | seeds | original (median) | change per stage | final − original | within the originals | added Gaussians | Gaussians |\n|---|---|---|---|---|---|---|---|---|\n".to_string() + &rows
}

/// audit.md's attribution of the reconstructions' movement (SPEC.md §20.5, issue #72): per
/// generator and variant and per reconstruction, the median over the seeds of the generated
/// views' share of the movement of the Gaussians the original views' gradients reached, for
/// the means, the opacities and the colour (SH DC); empty when no sample recorded it (runs
/// made before it was: their folders' reports keep their bytes).
fn attribution_table(cfg: &AuditConfig, pool: &[JobResult]) -> String {
    use crate::gaussian::Param;
    let mut rows = String::new();
    for g in &cfg.generators {
        let g = g.name();
        for v in &cfg.variants {
            let runs = group(pool, &g, *v);
            let Some(first) = runs.iter().find(|r| r.stages.len() >= 2) else {
                continue;
            };
            let mut cells = Vec::new();
            let mut seeds = 0;
            for (k, stage) in first.stages.iter().enumerate().skip(1) {
                let records: Vec<_> = runs
                    .iter()
                    .filter_map(|r| r.stages.get(k).filter(|s| s.scene == stage.scene))
                    .filter_map(|s| s.lineage.as_ref()?.attribution.as_ref())
                    .collect();
                if records.is_empty() {
                    continue;
                }
                seeds = seeds.max(records.len());
                let share = |p: Param| {
                    let mut d: Vec<f64> = records
                        .iter()
                        .map(|a| a.share(p))
                        .filter(|x| x.is_finite())
                        .collect();
                    d.sort_by(f64::total_cmp);
                    if d.is_empty() {
                        return "–".to_string();
                    }
                    format!("{:.2}", super::stats::quantile_sorted(&d, 0.5))
                };
                cells.push(format!(
                    "{} {} · {} · {}",
                    stage.scene,
                    share(Param::Means),
                    share(Param::OpacityLogits),
                    share(Param::ShDc)
                ));
            }
            if !cells.is_empty() {
                rows += &format!("| {g} | {} | {seeds} | {} |\n", v.name(), cells.join("; "));
            }
        }
    }
    if rows.is_empty() {
        return rows;
    }
    "\n### Which views moved the Gaussians the original views see\n\nEvery Adam step of a reconstruction split exactly between the original and the generated views' gradients (SPEC.md §20.5): over the Gaussians the original views' gradients reached, the generated views' share of their net movement (`Σ moved · moved_generated / Σ moved²`; the original views' is one minus it), median over the seeds, per reconstruction, for the means · the opacities · the colour (SH DC). Near 0: the original views moved them, as the original training did; near 1: the generated views did.\n\n| generator | variant | seeds | generated views' share per reconstruction (means · opacity · colour) |\n|---|---|---|---|\n".to_string() + &rows
}

fn sensitivity(report: &Report) -> String {
    let choices = [
        (
            Variant::EvenViews,
            "the default: greedy in file order, bounding-box frustums",
        ),
        (
            Variant::EvenViewsMaxCardinality,
            "maximum-cardinality independent set",
        ),
        (
            Variant::EvenViewsMaxCoverage,
            "maximum-coverage independent set",
        ),
        (Variant::EvenViewsHull, "hull frustums"),
    ];
    let rows: Vec<(&str, &Verdict)> = choices
        .iter()
        .flat_map(|(v, label)| {
            report
                .verdicts
                .iter()
                .filter(move |x| x.claim.variant == *v && !x.claim.metric.is_panel())
                .map(move |x| (*label, x))
        })
        .collect();
    if !rows
        .iter()
        .any(|(_, v)| v.claim.variant != Variant::EvenViews)
    {
        return String::new();
    }
    let mut s = "\n## Sensitivity: the independent-views claim under the choices the paper leaves open\n\nEach row: detection by that choice against the same number of evenly spaced views under it (SPEC.md §20.2).\n\n| choice | generator | n | median Δ (dB) | + / − | 95 % CI | verdict | rests on (full → variant) |\n|---|---|---|---|---|---|---|---|\n".to_string();
    for (label, v) in rows {
        let ci = v.ci.map_or_else(
            || "–".to_string(),
            |[lo, hi]| format!("[{lo:+.2}, {hi:+.2}]"),
        );
        s += &format!(
            "| {label} | {} | {} | {:+.2} | {} / {} | {ci} | **{}** | {} |\n",
            v.generator,
            v.judged,
            v.median_diff,
            v.above,
            v.below,
            v.verdict,
            rests_on(&report.pool, v)
        );
    }
    s
}

/// `audit.md`'s section of the panel's claims (SPEC.md §21.7; empty without them).
fn where_conflicts_act(report: &Report) -> String {
    let rows: Vec<&Verdict> = report
        .verdicts
        .iter()
        .filter(|v| v.claim.metric.is_panel())
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    let mut s = format!(
        "\n## Where conflicts act: the panel on contested pixels (SPEC.md §21.7)\n\nBoth runs of a seed scored on the *variant's* pixel classes: *contested* (its truth surface point was generated by ≥ 2 of the variant's stage-1 views: where conflicts can act), *uncontested* (the rest of the unseen surface: the within-pair null) and their difference in differences. Δ is oriented so that **positive = the full method better**: full − variant in PSNR (dB) and SSIM, variant − full in GMSD (lower is better), and for the detail ratio r (render over truth gradient energy) `|ln r_variant| − |ln r_full|` (closer to 1). The **primary** metric, registered before these samples, is {} on contested pixels (Holm family `…-classes`, with its uncontested null); the rest is a secondary family (`…-panel`). *Panel splits*: the contested and difference-in-differences rows disagree in sign with the primary while one of them is decided.\n\n| claim | metric | generator | family | n | median Δ | + / − | 95 % CI | hierarchical | p (Holm) | MDE | verdict | panel splits |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        super::verdicts::PRIMARY_MEASURE.label()
    );
    for v in rows {
        let d = if v.claim.metric.unit().is_empty() {
            4
        } else {
            2
        };
        let interval = |ci: Option<[f64; 2]>| {
            ci.map_or_else(
                || "–".to_string(),
                |[lo, hi]| format!("[{lo:+.d$}, {hi:+.d$}]"),
            )
        };
        let p = if v.p_holm.is_finite() && !v.verdict.starts_with("interim") {
            p_value(v.p_holm)
        } else {
            "–".into()
        };
        let primary = if v.claim.metric.is_primary() {
            "**"
        } else {
            ""
        };
        s += &format!(
            "| {} | {primary}{}{primary} | {} | {} | {} | {} | {} / {} | {} | {} | {p} | {} | **{}** | {} |\n",
            v.claim.variant.name(),
            v.claim.metric.label(),
            v.generator,
            v.family,
            v.judged,
            v.median_shown(),
            v.above,
            v.below,
            interval(v.ci),
            interval(v.hierarchical),
            if v.min_detectable.is_finite() {
                super::verdicts::shown_delta(v.min_detectable, v.claim.metric)
                    .trim_start_matches('+')
                    .to_string()
            } else {
                "∞".into()
            },
            v.verdict,
            v.panel_splits.as_deref().unwrap_or("–"),
        );
    }
    for (k, seed, median, path) in &report.sheets {
        let v = &report.verdicts[*k];
        let which = if *median {
            format!("at its median seed ({seed})")
        } else {
            format!("at seed {seed}, the nearest its median of the seeds whose sheet was kept")
        };
        s += &format!(
            "\n**{}, {}, {which}**: truth | full | {} | {}·|full − {}| on the most contested evaluation view, cropped to its contested pixels (the rest dimmed).\n\n![{} at seed {seed}]({})\n",
            v.claim.id,
            v.generator,
            v.claim.variant.name(),
            super::pairs::SHEET_DIFFERENCE_GAIN,
            v.claim.variant.name(),
            v.claim.id,
            path.display()
        );
    }
    s
}

/// `audit.md`.
pub fn markdown(cfg: &AuditConfig, report: &Report) -> String {
    let mut s = heading(report);
    s += &claims_table(report);
    s += &sensitivity(report);
    s += &where_conflicts_act(report);
    s += &every_variant_table(cfg, report);
    s += &diagnostics_table(cfg, &report.pool);
    s += &training_half_table(cfg, &report.pool);
    s += &compute_table(cfg, report);
    s += &cache_table(report);
    s += &super::dose::markdown(&report.responses);
    s += "\n![PSNR against the generator's inconsistency](inconsistency.svg)\n";
    s
}

/// `audit.md`'s title, what was run, and samples of another configuration.
fn heading(report: &Report) -> String {
    let revisions: Vec<String> = report.revisions.iter().map(|r| r.to_string()).collect();
    let mut s = format!(
        "# Audit of the paper's claims\n\nDataset `{}`; candidates: {}; preset `{}`; {} seeds ({}) in {} samples at numerics revision{} {}; original scene: {} iterations at resolution 1/{} on the training half. Metrics on the evaluation poses, pixels split into *existing* (seen by the training half) and *extrapolated*. Made by `unseen audit` (SPEC.md §21), crate {} at numerics revision {}; the samples are in `samples.json.gz` (a later batch of seeds adds to them).\n\n",
        report.provenance.dataset,
        report.provenance.candidates.as_ref().map_or_else(
            || "the bundled bridge views (`candidates.json`)".to_string(),
            |f| format!(
                "the family `{}` (`families/{}.json`, SHA-256 {}…)",
                f.name,
                f.name,
                f.short()
            )
        ),
        report.provenance.preset,
        report.seeds.len(),
        seed_ranges(&report.seeds),
        report.samples,
        if revisions.len() > 1 { "s" } else { "" },
        revisions.join(", "),
        report.provenance.train_iterations,
        report.provenance.train_resolution,
        report.crate_version,
        report.numerics_revision
    );
    if report.other_config > 0 {
        s += &format!(
            "**{} samples ran another pipeline configuration** than this binary's for their generator and variant (another version of the preset): kept in `samples.json.gz`, left out of every verdict and table.\n\n",
            report.other_config
        );
    }
    s
}

/// The paper's claims: how to read them, then a row per claim off the panel.
fn claims_table(report: &Report) -> String {
    let mut s = String::new();
    let r = &report.rule;
    s += &format!(
        "## Claims\n\n**How to read this.** Δ = full − variant (dB), one value per seed: both runs of a seed start from the same original scene with the same random numbers, so Δ is paired; the same seed at another numerics revision is another draw when both of its runs changed (a pair sharing a run's bits with one already counted counts once), and a seed's Δ is the mean of its draws (draws of one seed are correlated: the seed is the unit). **The plan**: each claim is judged on seeds 0 to {} − 1; with fewer it is **interim** — a look at a growing pool, not a verdict, and without a p-value here (stopping at the first decisive look would make false verdicts several times as likely) — and seeds beyond the plan are judged nowhere. **The test** is the sign test of the *median* Δ: the count of seeds above (+) and below (−) the null value against a fair coin, exact for every distribution of Δ (skewed ones too, where no test of the mean keeps its error rate at these sizes; SPEC.md §21.2). So a verdict is about the *typical seed*, not the average: where the mean lies on the other side of the null value the claim stays inconclusive. A claim that the full method is better **holds** when the median Δ is significantly above 0 and is **contradicted** when significantly below; a claim that the full method *does not hurt* (non-inferiority) holds when the median Δ is significantly above −{} dB (the margin) and is contradicted when significantly below it. *Significantly*: the two-sided p-value, after Holm's correction over the claims of the same generator family (classical; truth: every truth-* generator together) on this dataset (the sensitivity rows below form a family of their own), is below α = {}. Otherwise **inconclusive**: the *MDE* column is the smallest shift of the median from the null value that this many seeds find with {:.0} % power at the family's strictest Holm level, were Δ normal with the measured spread (∞: too few seeds to reach that level) — an effect smaller than that could be there. **No verdict** where every seed gave the same Δ: the seeds do not vary the comparison. **Not tested here** where both runs of a seed evaluated the same scene (equal final-scene digests: the variant changed nothing on that seed, e.g. both picked the same views), or where the variant's mechanism did not apply (`conflicting_views` found no colliding set that qualifies — coverage within 10 % of the independent set's and generations overlapping on ≥ 5 % of the evaluated surface — and generated the independent set): such a seed counts towards the plan but is no unit, and a claim with only such seeds gets no test and no MDE. *Rests on*: what the two runs did, mean over the seeds (section *What each run did*). *95 % CI*: the median's distribution-free interval (order statistics, from 6 seeds). *Hierarchical*: a 95 % percentile interval of the mean from resampling seeds, then each seed's evaluation views (pooled PSNR), from {} seeds with per-view records. The paper's numbers are from ScanNet++ / Mip-NeRF 360 with diffusion generators: compare directions, not values.\n\n| claim | metric | paper | generator | n | median Δ (dB) | + / − | 95 % CI | mean ± sd | hierarchical | p (Holm) | MDE (dB) | verdict | rests on (full → variant) |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        r.planned,
        r.margin,
        r.alpha,
        100.0 * r.power,
        super::verdicts::HIERARCHICAL_MIN_UNITS,
    );
    let interval = |ci: Option<[f64; 2]>| {
        ci.map_or_else(
            || "–".to_string(),
            |[lo, hi]| format!("[{lo:+.2}, {hi:+.2}]"),
        )
    };
    for v in report
        .verdicts
        .iter()
        .filter(|v| !v.claim.metric.is_panel())
    {
        let null = if v.null != 0.0 {
            format!(" (vs {:+.1})", v.null)
        } else {
            String::new()
        };
        // Seeds in the pool beyond the planned ones (the planned seeds that were not tested
        // are counted in the verdict, not here).
        let beyond = v.seeds.saturating_sub(v.judged + v.same_computation);
        let n = if beyond > 0 {
            format!("{} (+{beyond} beyond the plan)", v.judged)
        } else {
            v.judged.to_string()
        };
        s += &format!(
            "| {} | {} | {} | {} | {n} | {:+.2}{null} | {} / {} | {} | {:+.2} ± {} | {} | {} | {} | **{}** | {} |\n",
            v.claim.id,
            v.claim.metric.label(),
            v.claim.paper,
            v.generator,
            v.median_diff,
            v.above,
            v.below,
            interval(v.ci),
            v.mean_diff,
            num(v.std_diff, 2),
            interval(v.hierarchical),
            // (An interim look's p invites stopping at it: in audit.json only.)
            if v.p_holm.is_finite() && !v.verdict.starts_with("interim") {
                p_value(v.p_holm)
            } else {
                "–".into()
            },
            num(v.min_detectable, 2),
            v.verdict,
            rests_on(&report.pool, v)
        );
    }
    s
}

/// Every variant's metrics per generator, the original scene first.
fn every_variant_table(cfg: &AuditConfig, report: &Report) -> String {
    let mut s = String::new();
    s += "\n## Every variant\n\n| generator | variant | PSNR existing | PSNR extrapolated | PSNR all | SSIM existing | SSIM extrapolated | train-half PSNR | compute (s) |\n|---|---|---|---|---|---|---|---|---|\n";
    for g in &cfg.generators {
        let g = g.name();
        let rows = group(&report.pool, &g, Variant::Full);
        if !rows.is_empty() {
            s += &format!(
                "| {g} | *original scene* | {} | |\n",
                metric_cells(&rows, |r| &r.original)
            );
        }
        for v in &cfg.variants {
            let rows = group(&report.pool, &g, *v);
            if rows.is_empty() {
                continue;
            }
            s += &format!(
                "| {g} | {} | {} | {} |\n",
                v.name(),
                metric_cells(&rows, |r| &r.last),
                stat(&rows, |r| r.stage_seconds.values().sum(), 0),
            );
        }
    }
    s
}

/// Seconds per stage and variant.
fn compute_table(cfg: &AuditConfig, report: &Report) -> String {
    let mut s = String::new();
    s += "\n*compute*: the seconds each step took where it was computed; steps shared through the cache are counted in every variant that uses them.\n\n## Compute per stage (s, mean over seeds)\n\n";
    let stages = crate::pipeline::steps::Stage::ALL.map(|s| s.name());
    s += &format!(
        "| generator | variant | {} |\n|---|---|{}\n",
        stages.join(" | "),
        "---|".repeat(stages.len())
    );
    for g in &cfg.generators {
        let g = g.name();
        for v in &cfg.variants {
            let rows = group(&report.pool, &g, *v);
            if rows.is_empty() {
                continue;
            }
            let cells: Vec<String> = stages
                .iter()
                .map(|st| {
                    let t: f64 = rows
                        .iter()
                        .map(|r| r.stage_seconds.get(*st).copied().unwrap_or(0.0))
                        .sum::<f64>()
                        / rows.len() as f64;
                    format!("{t:.1}")
                })
                .collect();
            s += &format!("| {g} | {} | {} |\n", v.name(), cells.join(" | "));
        }
    }
    s
}

/// What the step cache saved (nothing when no step was shared).
fn cache_table(report: &Report) -> String {
    let mut s = String::new();
    let shared = sharing(&report.results);
    if !shared.is_empty() {
        s += "\n## What the step cache saves\n\nSteps whose inputs are equal (same manifest digest) are computed once and reused by every job that needs them (SPEC.md §20.8). *executions*: steps over all jobs; *distinct*: different steps; compute in seconds if every job computed its own steps, and with each distinct step computed once (what a fresh audit computes; a resumed audit, parallel `--only` workers or a cache from an earlier audit may have computed some twice or none here). The original scenes (one training per seed) are not counted.\n\n| stage | executions | distinct | every job its own (s) | each distinct step once (s) | saved |\n|---|---|---|---|---|---|\n";
        for r in &shared {
            let saved = if r.unshared_seconds > 0.0 {
                format!(
                    "{:.0} %",
                    100.0 * (1.0 - r.shared_seconds / r.unshared_seconds)
                )
            } else {
                "–".into()
            };
            s += &format!(
                "| {} | {} | {} | {:.1} | {:.1} | {saved} |\n",
                r.stage, r.executions, r.distinct, r.unshared_seconds, r.shared_seconds
            );
        }
    }
    s
}

/// Existing and extrapolated PSNR of full / w/o QA-Mask / opacity mask against the
/// ground-truth generator's inconsistency level (mean over seeds), as an SVG.
pub fn plot(cfg: &AuditConfig, results: &[JobResult]) -> String {
    let series = [
        (Variant::Full, "#1f77b4"),
        (Variant::NoQaMask, "#d62728"),
        (Variant::OpacityMask, "#2ca02c"),
    ];
    let truth: Vec<GeneratorKind> = cfg
        .generators
        .iter()
        .copied()
        .filter(|g| g.level().is_some())
        .collect();
    // Mean and std over seeds of one (generator, variant, metric).
    let point = |g: GeneratorKind, v: Variant, m: Metric| {
        let vals: Vec<f64> = group(results, &g.name(), v)
            .iter()
            .map(|r| m.of(&r.last))
            .filter(|x| x.is_finite())
            .collect();
        (!vals.is_empty()).then(|| mean_std(&vals))
    };
    let panels = [Metric::PsnrExisting, Metric::PsnrExtrapolated];
    let mut all = Vec::new();
    for m in panels {
        for (v, _) in series {
            for &g in &truth {
                if let Some((y, sd)) = point(g, v, m) {
                    let sd = if sd.is_nan() { 0.0 } else { sd };
                    all.extend([y - sd, y + sd]);
                }
            }
        }
    }
    let (lo, hi) = if all.is_empty() {
        (0.0, 1.0)
    } else {
        let lo = all.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = all.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        ((lo - 1.0).floor(), (hi + 1.0).ceil())
    };
    let (pw, ph, left, top) = (300.0, 220.0, 60.0, 40.0);
    let x_of = |i: usize| left + 30.0 + i as f64 * (pw - 60.0) / 2.0;
    let y_of = |v: f64| top + ph - (v - lo) / (hi - lo) * ph;
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" font-family=\"sans-serif\" font-size=\"12\">\n",
        2.0 * (pw + left) + 40.0,
        ph + top + 90.0
    );
    for (k, m) in panels.iter().enumerate() {
        let dx = k as f64 * (pw + left + 20.0);
        svg += &format!("<g transform=\"translate({dx},0)\">\n");
        svg += &format!(
            "<text x=\"{}\" y=\"20\" text-anchor=\"middle\">{} (dB)</text>\n",
            left + pw / 2.0,
            m.label()
        );
        svg += &format!(
            "<rect x=\"{left}\" y=\"{top}\" width=\"{pw}\" height=\"{ph}\" fill=\"none\" stroke=\"#888\"/>\n"
        );
        let step = if hi - lo > 10.0 { 2.0 } else { 1.0 };
        let mut t = lo;
        while t <= hi + 1e-9 {
            svg += &format!(
                "<text x=\"{}\" y=\"{}\" text-anchor=\"end\">{t:.0}</text>\n",
                left - 5.0,
                y_of(t) + 4.0
            );
            t += step;
        }
        for (i, l) in Level::ALL.iter().enumerate() {
            svg += &format!(
                "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n",
                x_of(i),
                top + ph + 18.0,
                l.name()
            );
        }
        // Series side by side around each level (offset 8 px), ±1 std as a bar.
        for (j, (v, color)) in series.iter().enumerate() {
            let dx = (j as f64 - 1.0) * 8.0;
            let pts: Vec<(f64, f64, f64)> = truth
                .iter()
                .filter_map(|&g| {
                    let (y, sd) = point(g, *v, *m)?;
                    Some((x_of(g.level()?) + dx, y, if sd.is_nan() { 0.0 } else { sd }))
                })
                .collect();
            if pts.len() > 1 {
                let path: Vec<String> = pts
                    .iter()
                    .map(|(x, y, _)| format!("{x:.1},{:.1}", y_of(*y)))
                    .collect();
                svg += &format!(
                    "<polyline points=\"{}\" fill=\"none\" stroke=\"{color}\" stroke-width=\"2\"/>\n",
                    path.join(" ")
                );
            }
            for (x, y, sd) in pts {
                if sd > 0.0 {
                    svg += &format!(
                        "<line x1=\"{x:.1}\" x2=\"{x:.1}\" y1=\"{:.1}\" y2=\"{:.1}\" stroke=\"{color}\"/>\n",
                        y_of(y - sd),
                        y_of(y + sd)
                    );
                }
                svg += &format!(
                    "<circle cx=\"{x:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"{color}\"/>\n",
                    y_of(y)
                );
            }
        }
        svg += "</g>\n";
    }
    for (i, (v, color)) in series.iter().enumerate() {
        let x = left + i as f64 * 170.0;
        let y = top + ph + 50.0;
        svg += &format!(
            "<rect x=\"{x}\" y=\"{}\" width=\"12\" height=\"12\" fill=\"{color}\"/><text x=\"{}\" y=\"{y}\">{}</text>\n",
            y - 10.0,
            x + 18.0,
            v.name()
        );
    }
    svg += &format!(
        "<text x=\"{left}\" y=\"{}\">x: the ground-truth generator's inconsistency level (SPEC.md §20.6); mean ± 1 std over seeds</text>\n</svg>\n",
        top + ph + 75.0
    );
    svg
}

impl super::Audit<'_> {
    /// Pair every run of the pool with its seed's `full` run (same generator and numerics
    /// revision) where the pair is missing, of another `full` scene or without multi-view
    /// consistency (scored before it was recorded), and both runs'
    /// folders hold what the results name: the final scenes (with the digests recorded)
    /// and the run's [`super::jobs::CLASSES_FILE`] ([`mod@super::pairs`]). Without them (a report from samples
    /// alone, another machine's folders) the pool keeps the pairs it has.
    pub(super) fn pair_up(&self, pool: &mut super::samples::Samples) -> Result<()> {
        use super::jobs::CLASSES_FILE;
        use super::pairs::{Pair, score_pair};
        let full = Variant::Full.name();
        let mut inputs: std::collections::BTreeMap<u32, crate::pipeline::Inputs> =
            Default::default();
        for i in 0..pool.samples.len() {
            let v = &pool.samples[i];
            if v.variant == full || v.final_scene.is_empty() {
                continue;
            }
            let Some(f) = pool.samples.iter().find(|f| {
                f.variant == full
                    && (f.generator.as_str(), f.seed, f.numerics_revision)
                        == (v.generator.as_str(), v.seed, v.numerics_revision)
                    && !f.final_scene.is_empty()
            }) else {
                continue;
            };
            // Scored already (with multi-view consistency: a pair scored before it is
            // scored again where the runs' folders are still there).
            if v.pair.as_ref().is_some_and(|p| {
                p.reference_scene == f.scene_sha256
                    && p.views
                        .iter()
                        .all(|pv| pv.contested.iter().all(|s| s.consistency.is_some()))
            }) {
                continue;
            }
            let (Ok(generator), Ok(variant)) = (
                GeneratorKind::by_name(&v.generator),
                v.variant.parse::<Variant>(),
            ) else {
                continue;
            };
            let folder = |variant| {
                self.dir.join(
                    Job::Run {
                        generator,
                        variant,
                        seed: v.seed,
                    }
                    .folder(),
                )
            };
            let (vdir, fdir) = (folder(variant), folder(Variant::Full));
            let scene = |dir: &std::path::Path, file: &str, sha: &str| {
                let bytes = std::fs::read(dir.join(file)).ok()?;
                (crate::io::sha256_hex(&bytes) == sha).then(|| dir.join(file))
            };
            let (Some(vs), Some(fs), Ok(classes)) = (
                scene(&vdir, &v.final_scene, &v.scene_sha256),
                scene(&fdir, &f.final_scene, &f.scene_sha256),
                std::fs::read(vdir.join(CLASSES_FILE)),
            ) else {
                continue;
            };
            let seed = v.seed;
            let reference_scene = f.scene_sha256.clone();
            let sheet = self
                .dir
                .join(super::pairs::sheet_path(&v.generator, &v.variant, v.seed));
            let seed_inputs = match inputs.entry(seed) {
                std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
                std::collections::btree_map::Entry::Vacant(e) => {
                    let run = self.dir.join(Job::Original { seed }.name());
                    if !self.original_done(&run, seed) {
                        continue;
                    }
                    e.insert(self.seed_inputs(&run)?)
                }
            };
            let (reference, _) = crate::gaussian::ply::read_ply(&fs)?;
            let (run, _) = crate::gaussian::ply::read_ply(&vs)?;
            let views =
                score_pair(seed_inputs, &reference, &run, &classes).map_err(|e| e.at(&vdir))?;
            let made = super::pairs::contact_sheet(seed_inputs, &reference, &run, &classes)
                .map_err(|e| e.at(&vdir))?;
            if let Some(img) = made {
                let parent = sheet.parent().expect("a sheet's folder");
                std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
                crate::io::image::write_png(&sheet, &img)?;
            }
            pool.samples[i].pair = Some(Pair {
                reference: full.into(),
                reference_scene,
                views,
            });
        }
        Ok(())
    }
}
