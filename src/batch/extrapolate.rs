//! One extrapolation on a batch engine (SPEC.md §20.8): the run's plan
//! ([`crate::pipeline::steps::plan`]) in its bound shape — before detection every
//! candidate may be an independent view — grouped into job arrays. A plan wave of several
//! steps is one array, a task per step (`--wave K --task I`: the I-th step of wave K once
//! detection is known; a task past the wave's steps has nothing to do); consecutive waves of
//! one step each run as one job (`--wave A-B`); the last job is the whole run with
//! `--resume` (every earlier step verified), which writes `steps.json`, the timings and the
//! evaluation summary, as a run on one machine does.

use super::cost::{Cost, Request, pipeline_cost_of, request, step_work};
use super::slurm::{ArrayWave, SlurmOptions, shell_quote, write_submission};
use crate::error::{Error, Result};
use crate::pipeline::steps::{Shape, plan};
use crate::pipeline::{Inputs, PipelineConfig, bound_shape};
use std::path::Path;

/// One job array of an extrapolation's submission.
#[derive(Clone, Debug, PartialEq)]
pub struct BatchWave {
    /// `views`, `stage1`, … (the stage of its earliest step in pipeline order),
    /// `<stage>-chain` for several waves run one after another in one job (the stage of the
    /// latest), `finish` for the last job; a repeated name takes its first wave's index.
    pub name: String,
    /// The plan waves it runs (`--wave first-last`); the finish job runs what is left.
    pub waves: std::ops::RangeInclusive<usize>,
    /// Array tasks: the bound plan's steps in the wave when it fans out, else 1.
    pub tasks: usize,
    /// A fan-out (`--task $SLURM_ARRAY_TASK_ID`).
    pub fan_out: bool,
    /// The whole run with `--resume`.
    pub finish: bool,
    /// Expected cost of each task (one entry per step for a fan-out).
    pub costs: Vec<Cost>,
}

/// The job arrays of an extrapolation of `bound` ([`Shape::bound`] of its candidates)
/// under `config`, at `pixels` per image.
pub fn waves(config: &PipelineConfig, bound: &Shape, pixels: f64) -> Vec<BatchWave> {
    let bound = plan(config, bound);
    let cost = |k: usize| -> Vec<Cost> {
        bound[k]
            .steps
            .iter()
            .map(|p| pipeline_cost_of(config.preset, step_work(config, &p.step, pixels), pixels))
            .collect()
    };
    // A job is named by the stage of its earliest step in pipeline order (its latest for
    // a chain, which ends a stage).
    let stage = |k: usize, last: bool| {
        let ranked = bound[k]
            .steps
            .iter()
            .map(|p| (p.step.rank(), p.step.stage()));
        let s = if last { ranked.max() } else { ranked.min() };
        s.map_or("empty", |(_, s)| s.name())
    };
    let mut out: Vec<BatchWave> = Vec::new();
    let mut k = 0;
    while k < bound.len() {
        if bound[k].steps.len() > 1 {
            out.push(BatchWave {
                name: stage(k, false).into(),
                waves: k..=k,
                tasks: bound[k].steps.len(),
                fan_out: true,
                finish: false,
                costs: cost(k),
            });
            k += 1;
            continue;
        }
        let first = k;
        while k < bound.len() && bound[k].steps.len() <= 1 {
            k += 1;
        }
        let costs: Vec<Cost> = (first..k).flat_map(cost).collect();
        let seconds = costs.iter().map(|c| c.seconds).sum();
        let peak = costs.iter().map(|c| c.peak_rss_bytes).fold(0.0, f64::max);
        out.push(BatchWave {
            name: if first == k - 1 {
                stage(first, false).into()
            } else {
                format!("{}-chain", stage(k - 1, true))
            },
            waves: first..=k - 1,
            tasks: 1,
            fan_out: false,
            finish: false,
            costs: vec![Cost {
                seconds,
                peak_rss_bytes: peak,
                measured: false,
            }],
        });
    }
    // The last job runs the whole run: a trailing chain becomes it, else one is added.
    match out.last_mut() {
        Some(w) if !w.fan_out => {
            w.name = "finish".into();
            w.finish = true;
        }
        _ => out.push(BatchWave {
            name: "finish".into(),
            waves: bound.len()..=bound.len(),
            tasks: 1,
            fan_out: false,
            finish: true,
            costs: Vec::new(),
        }),
    }
    // Names are unique (a stage may fan out twice): a repeat takes its first wave's index.
    for i in 0..out.len() {
        if out[..i].iter().any(|w| w.name == out[i].name) {
            out[i].name = format!("{}-{}", out[i].name, out[i].waves.start());
        }
    }
    out
}

/// Write the Slurm submission folder `out` of one extrapolation ([`write_submission`]):
/// the resolved configuration (`pipeline-config.json`, passed to every job with
/// `--config`) and one job array per [`BatchWave`]. `command` is the run's command line
/// without `--config` (binary first, paths absolute); each job adds its scope and
/// `--threads`. Returns the waves with their requests.
pub fn emit_slurm(
    config: &PipelineConfig,
    inputs: &Inputs,
    command: &[String],
    out: &Path,
    opts: &SlurmOptions,
) -> Result<Vec<(BatchWave, Request)>> {
    if out.is_file() {
        return Err(Error::invalid("the submission path is a file").at(out));
    }
    crate::io::create_dir_all(out)?;
    let config_path = out.join("pipeline-config.json");
    let text = serde_json::to_string_pretty(config).expect("serializes") + "\n";
    crate::io::write_text(&config_path, &text)?;
    let mut cmd: Vec<String> = command.iter().map(|a| shell_quote(a)).collect();
    cmd.extend([
        "--config".into(),
        shell_quote(&config_path.display().to_string()),
    ]);
    let cmd = cmd.join(" ");
    let cpus = opts.cpus.unwrap_or(2).max(1);
    let threads = format!("--threads \"${{SLURM_CPUS_PER_TASK:-{cpus}}}\"");
    let mut emitted = Vec::new();
    let mut arrays = Vec::new();
    let shape = bound_shape(inputs);
    // The pipeline runs at the candidates' resolution.
    let pixels = inputs
        .candidates
        .first()
        .map_or(0.0, |c| f64::from(c.width) * f64::from(c.height));
    for w in waves(config, &shape, pixels) {
        let (a, b) = (w.waves.start(), w.waves.end());
        let scope = if w.finish {
            String::new()
        } else if w.fan_out {
            format!(" --wave {a} --task \"$SLURM_ARRAY_TASK_ID\"")
        } else if a == b {
            format!(" --wave {a}")
        } else {
            format!(" --wave {a}-{b}")
        };
        let req = request(&w.costs, cpus);
        arrays.push(ArrayWave {
            name: w.name.clone(),
            tasks: w.tasks,
            request: req.clone(),
            body: format!("exec {cmd} --resume{scope} {threads}\n"),
        });
        emitted.push((w, req));
    }
    write_submission(out, &arrays, None, opts)?;
    Ok(emitted)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::{MaskSource, Preset};

    fn jobs(config: &PipelineConfig, evaluation: bool) -> Vec<(String, usize, usize, usize)> {
        let shape = Shape::bound(vec!["a".into(), "b".into(), "c".into()], evaluation);
        waves(config, &shape, 100.0)
            .into_iter()
            .map(|w| (w.name, *w.waves.start(), *w.waves.end(), w.tasks))
            .collect()
    }

    /// The quick preset with evaluation: a fan-out where a plan wave has several steps
    /// (detection beside the original's QA-Mask and the evaluation masks; the independent
    /// views beside the original's evaluation; each later stage's first steps beside the
    /// scene's QA-Mask and evaluation), chains between them, the whole run last.
    #[test]
    fn the_batch_waves_follow_the_plan() {
        let quick = PipelineConfig::preset(Preset::Quick);
        let j = |n: &str, a, b, t| (n.to_string(), a, b, t);
        assert_eq!(
            jobs(&quick, true),
            [
                j("views", 0, 0, 3),
                j("stage1", 1, 1, 4),
                j("stage1-chain", 2, 3, 1),
                j("stage2", 4, 4, 3),
                j("stage2-chain", 5, 6, 1),
                j("interpolate", 7, 7, 3),
                j("finish", 8, 9, 1),
            ]
        );
        // Without the QA-Mask or evaluation, detection is alone: one chain up to the
        // fan-out of the independent views.
        let plain = PipelineConfig {
            mask_source: MaskSource::Opacity,
            interpolation: false,
            ..quick
        };
        assert_eq!(
            jobs(&plain, false),
            [
                j("views", 0, 0, 1),
                j("stage1", 1, 1, 3),
                j("finish", 2, 6, 1),
            ]
        );
    }

    /// Under every switch that adds or removes steps, the jobs run every plan wave once,
    /// in order, and only waves of several steps fan out.
    #[test]
    fn the_jobs_run_every_wave_once() {
        for mask_source in MaskSource::ALL {
            for b in 0..8 {
                let config = PipelineConfig {
                    mask_source,
                    propagation: b & 1 != 0,
                    interpolation: b & 2 != 0,
                    ..PipelineConfig::preset(Preset::Quick)
                };
                let shape = Shape::bound(vec!["a".into(), "b".into()], b & 4 != 0);
                let bound = plan(&config, &shape);
                let mut next = 0;
                for w in waves(&config, &shape, 1.0) {
                    assert_eq!(*w.waves.start(), next, "{w:?}");
                    next = w.waves.end() + 1;
                    assert_eq!(w.fan_out, w.tasks > 1);
                    if w.fan_out {
                        assert_eq!(w.tasks, bound[*w.waves.start()].steps.len());
                    }
                }
                assert!(next >= bound.len());
            }
        }
    }
}
