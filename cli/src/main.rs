//! The `unseen` command line: one file per command family, each with its `Args` and `run`;
//! errors are one sentence on stderr and a non-zero exit.

mod geometry;
mod models;
mod pipeline;
mod progress;
mod render;
mod train;

use clap::{Parser, Subcommand};
use std::process::ExitCode;
use unseen::error::Result;

#[derive(Parser)]
#[command(
    name = "unseen",
    version,
    about = "Deterministic CPU scene extrapolation with 3D Gaussian Splatting"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The main job on a bundled room: train the original scene on its train half, then
    /// extrapolate it into the held-out half with the quick pipeline; writes
    /// demo-out/report.md.
    Demo(pipeline::DemoArgs),
    /// The paper's pipeline on a trained run: independent views, stage 1, stage 2,
    /// interpolation; a resumable run directory with per-step manifests.
    Extrapolate(pipeline::ExtrapolateArgs),
    /// Compare two extrapolation runs step by step (the GPU port's check); exit 1 on
    /// divergence beyond the tolerance, 2 when the runs cannot be compared.
    Compare(pipeline::CompareArgs),
    /// Check the paper's claims: every ablation under several generators and seeds, with
    /// verdicts per claim (DIR/audit.md)
    Audit(pipeline::AuditArgs),
    /// The results table of audits (their folders' audit.json): per primary claim, its
    /// null and the panel's rows, as markdown (README.md's table).
    AuditTable(pipeline::AuditTableArgs),
    /// Train 3D Gaussians on a dataset (unseen scene, COLMAP or transforms.json directory)
    /// with INRIA's recipe; writes INRIA's output layout into --out.
    Train(train::TrainArgs),
    /// PSNR / SSIM of a run's latest PLY on a split of a dataset; writes RUN/eval.json and
    /// render|ground-truth images into RUN/eval/<split>/.
    Eval(train::EvalArgs),
    /// Quality-Aware Mask of a trained run (paper §3.4): base colour, black targets, only
    /// higher SH fine-tuned on the run's training views; writes the mask scene into --out.
    QaMask(train::QaMaskArgs),
    /// Measure the QA-Mask claim on a dataset with a held-out half: fine-tune QA-Masks of a
    /// run at several SH degrees, score them and the baselines (opacity, scale) against the
    /// true per-pixel error on the held-out views (AUROC, Spearman); writes JSON + table.
    MaskAudit(train::MaskAuditArgs),
    /// Render a 3DGS PLY from cameras in INRIA cameras.json layout.
    Render(render::RenderArgs),
    /// Dump every intermediate (and, for backward, every gradient) of one render as .npy
    /// files with a manifest.json, for comparing a GPU port array by array.
    Oracle(render::OracleArgs),
    /// Forward-warp an image with its depth from one camera to another (DIBR).
    Warp(geometry::WarpArgs),
    /// Do two convex polyhedra intersect? (GJK; exit 0 either way.)
    Collide(geometry::CollideArgs),
    /// Independent views: frustums of the candidates' inpainted regions, their collision
    /// graph, a maximal independent set and its closed trajectory.
    Views(geometry::ViewsArgs),
    /// Inpaint the non-zero pixels of MASK in IMAGE (Telea by default, as cv2.inpaint).
    Inpaint(models::InpaintArgs),
    /// Estimate depth of an image (depth-fill from a known depth, or an ONNX model).
    Depth(models::DepthArgs),
}

/// Run a command; its exit code (every command but `compare` exits 0 when it succeeds).
fn run(cli: Cli) -> Result<ExitCode> {
    let done = match cli.command {
        Command::Compare(a) => return Ok(pipeline::run_compare(&a)),
        Command::Demo(a) => pipeline::run_demo(&a),
        Command::Extrapolate(a) => pipeline::run_extrapolate(&a),
        Command::Audit(a) => pipeline::run_audit(&a),
        Command::AuditTable(a) => pipeline::run_audit_table(&a),
        Command::Train(a) => train::run_train(a),
        Command::Eval(a) => train::run_eval(a),
        Command::QaMask(a) => train::run_qa_mask(a),
        Command::MaskAudit(a) => train::run_mask_audit(a),
        Command::Render(a) => render::run_render_command(a),
        Command::Oracle(a) => render::run_oracle_command(a),
        Command::Warp(a) => geometry::run_warp(&a),
        Command::Collide(a) => geometry::run_collide(&a),
        Command::Views(a) => geometry::run_views(&a),
        Command::Inpaint(a) => models::run_inpaint(&a),
        Command::Depth(a) => models::run_depth(&a),
    };
    done.map(|()| ExitCode::SUCCESS)
}

/// Ctrl-C (SIGINT) and SIGTERM: remove the temporaries being written, keep every finished
/// output, exit with 130 (SPEC.md §10).
fn exit_cleanly_on_interrupt() {
    let installed = ctrlc::set_handler(|| {
        let n = unseen::io::abandon_temporaries();
        eprintln!("interrupted: removed {n} temporary file(s); finished outputs are kept");
        std::process::exit(130);
    });
    if let Err(e) = installed {
        eprintln!("warning: no interrupt handler ({e}); an interrupt may leave .tmp files");
    }
}

fn main() -> ExitCode {
    unseen::sys::init_global_pool();
    unseen::sys::keep_freed_memory();
    exit_cleanly_on_interrupt();
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// A value parser over one of the engine's enums (its `ALL` and `name`, the names its
/// configuration files use): `--help` lists the names, a wrong one is refused by clap.
pub(crate) fn one_of<T: Copy + Send + Sync + 'static>(
    all: &'static [T],
    name: fn(T) -> &'static str,
) -> impl clap::builder::TypedValueParser<Value = T> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(all.iter().map(|&v| name(v))).map(move |s| {
        all.iter()
            .copied()
            .find(|&v| name(v) == s)
            .expect("clap admits only the possible values")
    })
}
