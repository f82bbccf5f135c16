//! Progress display: bars on a terminal, a log line now and then otherwise.

use indicatif::{ProgressBar, ProgressStyle};
use std::path::Path;
use std::sync::Mutex;
use std::time::Instant;
use unseen::error::Result;
use unseen::pipeline::Event;
use unseen::train::run::{Checkpointing, Init, train_run_resuming};
use unseen::train::trainer::{Progress, TrainConfig};

pub fn train_with_bar(
    dataset: &Path,
    out: &Path,
    cfg: &TrainConfig,
    init: Option<&Init<'_>>,
    checkpoints: Checkpointing,
) -> Result<unseen::train::run::RunSummary> {
    let bar = ProgressBar::new(cfg.iterations as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{bar:30} {pos}/{len} {msg} [{elapsed_precise}<{eta_precise}, {per_sec}]",
        )
        .expect("valid template"),
    );
    let t0 = Instant::now();
    let mut on_progress = |p: &Progress| {
        // Without a terminal the bar is hidden: a log line every 1000 iterations instead.
        if bar.is_hidden() && (p.iteration.is_multiple_of(1000) || p.iteration == p.iterations) {
            eprintln!(
                "iteration {}/{}: loss {:.4}, PSNR {:.2} dB, {} Gaussians, {:.1} s",
                p.iteration,
                p.iterations,
                p.loss_ema,
                p.psnr_ema,
                p.gaussians,
                t0.elapsed().as_secs_f64()
            );
        }
        if p.checkpointed && bar.is_hidden() {
            eprintln!("checkpoint at iteration {}", p.iteration);
        }
        if p.iteration.is_multiple_of(10) || p.iteration == p.iterations {
            bar.set_position(p.iteration as u64);
            bar.set_message(format!(
                "loss {:.4} PSNR {:.2} dB, {} Gaussians",
                p.loss_ema, p.psnr_ema, p.gaussians
            ));
        }
    };
    let s = train_run_resuming(
        dataset,
        out,
        cfg,
        init,
        checkpoints,
        &mut |it| eprintln!("resuming from the checkpoint at iteration {it}"),
        &mut on_progress,
    );
    bar.finish_and_clear();
    s
}

/// Draw pipeline events: one bar for the current iteration-driven step, a line per step.
pub fn drawer() -> impl Fn(Event) + Sync {
    let bar = Mutex::new(None::<(String, ProgressBar)>);
    let t0 = Instant::now();
    move |e: Event| {
        let mut b = bar.lock().expect("bar lock");
        match e {
            Event::Stage { name } => eprintln!("== {name}"),
            Event::StepStarted { step } => eprintln!("   {step} ..."),
            Event::StepFinished { step, seconds } => {
                if let Some((_, pb)) = b.take() {
                    pb.finish_and_clear();
                }
                eprintln!(
                    "   {step} done in {seconds:.1} s ({:.0} s total)",
                    t0.elapsed().as_secs_f64()
                );
            }
            Event::StepSkipped { step } => eprintln!("   {step}: verified, skipped"),
            Event::StepCached { step } => eprintln!("   {step}: from the step cache"),
            Event::Iterations {
                step,
                done,
                total,
                loss,
            } => {
                if b.as_ref().is_none_or(|(s, _)| *s != step) {
                    if let Some((_, pb)) = b.take() {
                        pb.finish_and_clear();
                    }
                    let pb = ProgressBar::new(total as u64);
                    pb.set_style(
                        ProgressStyle::with_template("   {bar:30} {pos}/{len} {msg}")
                            .expect("template"),
                    );
                    *b = Some((step.clone(), pb));
                }
                let (_, pb) = b.as_ref().expect("set");
                pb.set_position(done as u64);
                pb.set_message(format!("{step} loss {loss:.4}"));
                if pb.is_hidden() && (done % 500 == 0 || done == total) {
                    eprintln!("   {step}: {done}/{total}, loss {loss:.4}");
                }
            }
            Event::Note(s) => eprintln!("   {s}"),
        }
    }
}
