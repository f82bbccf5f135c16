//! What a batch job is expected to cost (SPEC.md §21.4): the calibration of seconds and
//! memory per training iteration-pixel, a whole pipeline run's work, and the resource
//! request (`--time`, `--mem`) a wave of jobs asks for.

use crate::pipeline::PipelineConfig;
use crate::pipeline::steps::{Scope, Selection, Shape, Step, plan};

/// Seconds per training iteration per pixel on 2 threads, measured on the demo (lounge,
/// quick preset, 80×60, 2-vCPU Xeon, Sapphire Rapids class): the original scene's 1 500
/// iterations took 17.0 s (46 k Gaussians) — 2.4 µs; the pipeline's reconstructions and
/// QA-Mask fine-tunes (1 600 + 900 iterations) 71.6 s — 6.0 µs (more Gaussians per pixel).
pub const ORIGINAL_SECONDS_PER_ITERATION_PIXEL: f64 = 2.4e-6;
pub const PIPELINE_SECONDS_PER_ITERATION_PIXEL: f64 = 6.0e-6;
/// Peak resident memory per training pixel, same runs: 134 MB (original) and 324 MB
/// (pipeline) at 4 800 pixels, over a fixed 50 MB.
pub const ORIGINAL_BYTES_PER_PIXEL: f64 = 28_000.0;
pub const PIPELINE_BYTES_PER_PIXEL: f64 = 68_000.0;
pub const BASE_BYTES: f64 = 50e6;

/// What a job is expected to cost on 2 threads.
#[derive(Clone, Debug, PartialEq)]
pub struct Cost {
    pub seconds: f64,
    pub peak_rss_bytes: f64,
    /// From this audit's own finished jobs of the same kind, not the calibration above.
    pub measured: bool,
}

/// The training iteration-pixels of one step: a reconstruction's iterations, a QA-Mask's
/// fine-tune; the other steps (detection, generation, warping, evaluation) are small
/// beside them. A cycle step's share of the iterations depends on the trajectory detection
/// finds: bounded by the whole total (and, after the first, the QA-Mask it fine-tunes).
pub fn step_work(pc: &PipelineConfig, step: &Step, pixels: f64) -> f64 {
    let iterations = match step {
        Step::Stage1Recon => u64::from(pc.stage1.iterations),
        Step::Stage2Recon => u64::from(pc.stage2.iterations),
        Step::Interpolation => u64::from(pc.interpolate.iterations),
        Step::QaMask(_) => u64::from(pc.qa_iterations),
        Step::Cycle(k) => {
            let qa = *k > 0 && pc.mask_source == crate::pipeline::MaskSource::Qa;
            crate::pipeline::cycle::total_iterations(pc)
                + u64::from(pc.qa_iterations) * u64::from(qa)
        }
        _ => 0,
    };
    iterations as f64 * pixels
}

/// The training iteration-pixels of a whole pipeline run: the sum over its plan's steps
/// (three reconstructions and three QA-Mask fine-tunes; two of each without
/// interpolation, no QA-Mask without it).
pub fn pipeline_work(pc: &PipelineConfig, pixels: f64) -> f64 {
    scoped_work(pc, &Scope::All, pixels)
}

/// The training iteration-pixels of the steps `scope` computes in a pipeline run (e.g. the
/// audit's shared job, `Scope::Before(stage1/recon)`: the original scene's QA-Mask).
pub fn scoped_work(pc: &PipelineConfig, scope: &Scope, pixels: f64) -> f64 {
    let waves = plan(pc, &Shape::bound(vec![String::new()], false));
    let Ok(selection) = Selection::new(scope, &waves) else {
        return 0.0;
    };
    waves
        .iter()
        .flat_map(|w| &w.steps)
        .filter(|p| selection.computes(&p.step))
        .map(|p| step_work(pc, &p.step, pixels))
        .sum()
}

/// Work in training iteration-pixels at the pipeline's calibration, as a [`Cost`].
pub fn pipeline_cost_of(work: f64, pixels: f64) -> Cost {
    Cost {
        seconds: PIPELINE_SECONDS_PER_ITERATION_PIXEL * work,
        peak_rss_bytes: BASE_BYTES + PIPELINE_BYTES_PER_PIXEL * pixels,
        measured: false,
    }
}

/// A whole pipeline run's expected [`Cost`] by the calibration.
pub fn pipeline_cost(pc: &PipelineConfig, pixels: f64) -> Cost {
    pipeline_cost_of(pipeline_work(pc, pixels), pixels)
}

/// Resource requests over an estimate: a job's `--time` is [`TIME_FACTOR`] times its
/// expected seconds (other CPUs, a loaded node, a slower file system; a job over its time
/// is killed and must run again), at least [`MIN_TIME_SECONDS`]; its `--mem` is
/// [`MEMORY_FACTOR`] times its expected peak, at least [`MIN_MEMORY_BYTES`].
pub const TIME_FACTOR: f64 = 3.0;
pub const MIN_TIME_SECONDS: f64 = 600.0;
pub const MEMORY_FACTOR: f64 = 2.0;
pub const MIN_MEMORY_BYTES: f64 = 1e9;

/// The resource request of a wave: the largest of its jobs'.
#[derive(Clone, Debug, PartialEq)]
pub struct Request {
    pub cpus: u32,
    pub memory_mb: u64,
    pub time_minutes: u64,
}

/// [`Request`] of a wave's costs.
pub fn request(costs: &[Cost], cpus: u32) -> Request {
    let seconds = costs.iter().map(|c| c.seconds).fold(0.0, f64::max);
    let bytes = costs.iter().map(|c| c.peak_rss_bytes).fold(0.0, f64::max);
    let time = (seconds * TIME_FACTOR).max(MIN_TIME_SECONDS);
    let mem = (bytes * MEMORY_FACTOR).max(MIN_MEMORY_BYTES);
    Request {
        cpus,
        memory_mb: (mem / 1e6).ceil() as u64,
        time_minutes: (time / 60.0).ceil() as u64,
    }
}

/// The smallest request ([`MIN_TIME_SECONDS`], [`MIN_MEMORY_BYTES`]) on `cpus` CPUs.
pub fn least_request(cpus: u32) -> Request {
    request(&[], cpus)
}
