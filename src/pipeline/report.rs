//! `report.md` of a run (the demo's page): the plan, per-stage pictures, the metric table
//! and the time of every step.

use super::Outcome;
use super::artifacts::{read_json, stem};
use super::config::PipelineConfig;
use super::steps::Step;
use super::views::Plan;
use crate::error::Result;
use std::path::Path;

/// The report of the run in `run` (links relative to the report's folder, the run's
/// parent); `wall` is this invocation's time.
pub fn markdown(config: &PipelineConfig, run: &Path, out: &Outcome, wall: f64) -> Result<String> {
    let prefix = run
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let plan: Plan = read_json(&Step::Views.dir(run).join("plan.json"))?;
    let cycle = config.paradigm == super::Paradigm::Cycle;
    let mut md = String::from("# unseen: scene extrapolation\n\n");
    if cycle {
        md += "**The cycle paradigm — not the paper's method**: the generate–reconstruct–shift \
               cycle the paper's hierarchical pipeline replaces (§1), one trajectory view after \
               another (SPEC.md §20.11); stages 1, 2 and the interpolation did not run.\n\n";
    }
    md += &configuration(config, &prefix);
    if let Some(m) = &out.metrics {
        md += &metrics_section(m);
    }
    md += &views_section(&plan, run, &prefix);
    if cycle {
        md += &cycle_table(&plan, run, &prefix);
    } else {
        md += &stages_table(config, &plan, run, &prefix);
    }
    md += &tail(run, out, wall, &prefix);
    Ok(md)
}

/// What ran: the preset, the slots and the switches, the labelled deviations in bold.
fn configuration(config: &PipelineConfig, prefix: &str) -> String {
    let mut md = String::new();
    md += &format!(
        "Preset `{}`, slots: inpaint `{}`, depth `{}`, video `{}`, video depth `{}`, fixer `{}`{}; \
         mask `{}`, depth supervision {}{}, DIBR propagation {}, stage-2 depth {}, independent \
         view detection {}, interpolation {}. The whole configuration is `{prefix}/config.json`.\n\n",
        config.preset,
        config.slots.inpaint,
        config.slots.depth,
        config.slots.video,
        config.slots.video_depth,
        config.slots.fixer,
        if config.slots.uses_truth() {
            format!(
                " (**ground-truth generator**: an upper bound, inconsistency {}{}{})",
                config.inconsistency.name(),
                match config.truth_depth {
                    super::TruthDepth::Metric => "",
                    super::TruthDepth::Relative =>
                        ", **relative depth**: disparity under a seeded affine map per image and clip",
                },
                match config.hallucination {
                    super::Hallucination::None => "",
                    super::Hallucination::Low =>
                        ", **hallucinating** (low): unseen content differs per call",
                    super::Hallucination::High =>
                        ", **hallucinating** (high): unseen content differs per call",
                    super::Hallucination::Percent(_) =>
                        ", **hallucinating** (a swept level): unseen content differs per call",
                }
            )
        } else {
            " (the classical defaults unless named otherwise; `--generator truth` gives the \
             ground-truth upper bound)"
                .to_string()
        },
        serde_json::to_value(config.mask_source)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_default(),
        config.depth_supervision,
        if config.supervises_original_depth() {
            " (**also on the original views' dataset depth: not in the paper**)"
        } else {
            ""
        },
        config.propagation,
        match config.stage2_depth {
            super::Stage2Depth::Video => "by video depth alignment",
            super::Stage2Depth::RenderFit =>
                "by a fit to the stage-1 render (**not in the paper**)",
        },
        config.independent_detection,
        config.interpolation,
    );
    md
}

/// The metrics table on the evaluation poses and the training half's test views.
fn metrics_section(m: &super::evaluate::Summary) -> String {
    format!(
        "## Metrics\n\nOn {} evaluation poses never given to the pipeline ({:.1} % of their \
             pixels show surfaces a training camera saw: *existing*; the rest *extrapolated*), \
             and on the training half's test views:\n\n{}\n",
        m.evaluation_views,
        100.0 * m.existing_fraction,
        m.table()
    )
}

/// Independent view detection: its counts, the frustums, the views set aside, the first
/// candidates' renders and inpaintings, and a pair of conflicting generations.
fn views_section(plan: &Plan, run: &Path, prefix: &str) -> String {
    let mut md = String::new();
    md += &format!(
        "## Independent views (§3.2)\n\n{} candidates, {} already covered, {} frustum \
         collisions; independent: {}; closed trajectory: {}. Frustums of the inpainted \
         regions: `{prefix}/{views}/frustums.obj` (open it in a mesh viewer); from above (independent \
         views filled, training cameras grey, the trajectory red):\n\n\
         ![frustums from above]({prefix}/{views}/frustums.svg)\n\n",
        plan.candidates.len(),
        plan.covered.len(),
        plan.collisions.len(),
        plan.independent.join(", "),
        plan.trajectory.join(" → "),
        views = Step::Views,
    );
    if !plan.set_aside.is_empty() {
        md += "**Set aside** (left out of detection, as the covered ones; SPEC.md §20.2):\n\n";
        for a in &plan.set_aside {
            md += &format!("- {}: {}\n", a.name, a.reason);
        }
        md += "\n";
    }
    md += "| candidate | render | inpainting mask | inpainting |\n|---|---|---|---|\n";
    for c in plan.candidates.iter().filter(|c| c.masked > 0).take(6) {
        let s = stem(&c.name);
        md += &format!(
            "| {0} | ![]({1}/{2}/{s}/render.png) | ![]({1}/{2}/{s}/inpaint.mask.png) | ![]({1}/{2}/{s}/inpaint_0.png) |\n",
            c.name,
            prefix,
            Step::Views
        );
    }
    if let Ok(c) = read_json::<serde_json::Value>(&Step::Views.dir(run).join("conflict.json")) {
        md += &format!(
            "\n**Conflicting generations** (the hallucinating ground-truth generator): two \
             independent generations of {}; on its {} pixels no training view saw they differ \
             by {:.1} dB PSNR — what independent view detection keeps apart.\n\n\
             | generation a | generation b |\n|---|---|\n\
             | ![]({prefix}/{views}/conflict_a.png) | ![]({prefix}/{views}/conflict_b.png) |\n",
            c["view"].as_str().unwrap_or("?"),
            c["unseen_pixels"],
            c["psnr_db"].as_f64().unwrap_or(f64::NAN),
            views = Step::Views,
        );
    }
    md
}

/// The cycle paradigm's views in trajectory order: what each generated, its iterations,
/// its image and weights.
fn cycle_table(plan: &Plan, run: &Path, prefix: &str) -> String {
    let mut md = String::from(
        "\n## The cycle (not the paper's method)\n\n| k | view | masked pixels | new points | iterations | image | weights |\n|---|---|---|---|---|---|---|\n",
    );
    for (k, name) in plan.trajectory.iter().enumerate() {
        let step = Step::Cycle(k);
        let Ok(r) = read_json::<serde_json::Value>(&step.dir(run).join("cycle.json")) else {
            continue;
        };
        let s = stem(name);
        let img = if r["generated"].as_bool().unwrap_or(false) {
            "inpaint"
        } else {
            "render"
        };
        md += &format!(
            "| {k} | {name} | {} | {} | {} | ![]({prefix}/{step}/{img}.png) | ![]({prefix}/{step}/weights/{s}.png) |\n",
            r["masked"],
            r.get("new_points").unwrap_or(&serde_json::json!(0)),
            r["iterations"],
        );
    }
    md
}

/// The hierarchical pipeline's trajectory views, DIBR propagation and dependent depths.
fn stages_table(config: &PipelineConfig, plan: &Plan, run: &Path, prefix: &str) -> String {
    let mut md = String::new();
    md += "\n## Stage 1 and 2 (§3.3)\n\n| view | kind | image | weights (QA-Mask heat map) |\n|---|---|---|---|\n";
    for name in plan.trajectory.iter().take(8) {
        let s = stem(name);
        let independent = plan.independent.contains(name);
        let (img, recon) = if independent {
            (
                format!("{prefix}/{}/inpaint.png", Step::Independent(s.clone())),
                Step::Stage1Recon,
            )
        } else {
            (
                format!("{prefix}/{}/{s}/inpaint.png", Step::Dependent),
                Step::Stage2Recon,
            )
        };
        md += &format!(
            "| {name} | {} | ![]({img}) | ![]({prefix}/{recon}/weights/{s}.png) |\n",
            if independent {
                "independent"
            } else {
                "dependent"
            }
        );
    }
    let propagated = Step::Propagate.dir(run);
    let shown: Vec<&super::views::Dependent> = plan
        .dependent
        .iter()
        .filter(|d| propagated.join(stem(&d.name)).is_dir())
        .take(4)
        .collect();
    if !shown.is_empty() {
        md += "\n### DIBR propagation and the stage-2 gap\n\n| dependent view | between | warped inpaintings | covered | stage-1 render | gap inpainted |\n|---|---|---|---|---|---|\n";
        for d in shown {
            let s = stem(&d.name);
            md += &format!(
                "| {} | {} – {} | ![]({prefix}/{p}/{s}/warped.png) | ![]({prefix}/{p}/{s}/covered.mask.png) | ![]({prefix}/{q}/{s}/render.png) | ![]({prefix}/{q}/{s}/inpaint.mask.png) |\n",
                d.name,
                d.between[0],
                d.between[1],
                p = Step::Propagate,
                q = Step::Dependent,
            );
        }
        md += "\n";
    }
    if let Ok(d) = read_json::<serde_json::Value>(&Step::Dependent.dir(run).join("dependent.json"))
    {
        let views = d["views"].as_array().cloned().unwrap_or_default();
        if !views.is_empty() {
            md += &format!(
                "### Depth of the dependent views (§3.3.2)\n\n{}\n\n\
                 | dependent view | method | from | space | scale | offset | inliers / valid |\n|---|---|---|---|---|---|---|\n",
                match config.stage2_depth {
                    super::Stage2Depth::Video =>
                        "DIBR-based video depth alignment: a clip from the nearest training view, \
                         its video depth fitted by one RANSAC against that view's depth warped to \
                         every frame; a view whose clip cannot be made or aligned keeps the fit to \
                         the stage-1 render (`render_fit`, with the reason in `dependent.json`).",
                    super::Stage2Depth::RenderFit =>
                        "**Not in the paper** (`stage2_depth: render_fit`): the depth slot's \
                         estimate fitted by least squares to the stage-1 render's depth.",
                }
            );
            for v in views.iter().take(8) {
                let method = v["method"].as_str().unwrap_or("?");
                let a = if method == "video" {
                    &v["alignment"]
                } else {
                    &v["render_fit"]["alignment"]
                };
                let space = if method == "video" {
                    &v["space"]
                } else {
                    &v["render_fit"]["space"]
                };
                md += &format!(
                    "| {} | {}{} | {} | {} | {:.4} | {:.4} | {} / {} |\n",
                    v["view"].as_str().unwrap_or("?"),
                    method,
                    if v.get("video_failed").is_some() {
                        " (video failed)"
                    } else {
                        ""
                    },
                    v["source"].as_str().unwrap_or("—"),
                    space.as_str().unwrap_or("?"),
                    a["scale"].as_f64().unwrap_or(f64::NAN),
                    a["offset"].as_f64().unwrap_or(f64::NAN),
                    a["inliers"],
                    a["valid"],
                );
            }
            md += "\n";
        }
    }
    md
}

/// The evaluation's pictures, the cost of every step and this invocation's time.
fn tail(run: &Path, out: &Outcome, wall: f64, prefix: &str) -> String {
    let mut md = String::new();
    if let Some(m) = &out.metrics {
        md += "## Evaluation views (render | truth)\n\n";
        for r in &m.rows {
            md += &format!("**{}**\n\n", r.scene);
            // A row of a scene this version does not make has no pictures to show.
            let Ok(scene) = r.scene.parse() else {
                continue;
            };
            let step = Step::Eval(scene);
            let dir = step.dir(run);
            let mut pngs: Vec<String> = std::fs::read_dir(&dir)
                .map(|d| {
                    d.flatten()
                        .map(|e| e.file_name().to_string_lossy().into_owned())
                        .filter(|n| n.ends_with(".png"))
                        .collect()
                })
                .unwrap_or_default();
            pngs.sort();
            for p in pngs.iter().take(2) {
                md += &format!("![]({prefix}/{step}/{p}) ");
            }
            md += "\n\n";
        }
    }
    let timings: std::collections::BTreeMap<String, crate::io::Cost> =
        read_json(&run.join("timings.json")).unwrap_or_default();
    md += "## Cost per step (2 cores)\n\n| step | seconds | peak memory |\n|---|---|---|\n";
    // In run order (`steps.json`).
    let order: Vec<String> = read_json(&run.join("steps.json")).unwrap_or_default();
    for (k, v) in order.iter().filter_map(|k| timings.get(k).map(|v| (k, v))) {
        md += &format!(
            "| {k} | {:.1} | {} |\n",
            v.seconds,
            v.peak_rss_bytes
                .map_or("—".to_string(), |b| format!("{:.0} MB", b as f64 / 1e6))
        );
    }
    md += &format!("\nThis invocation: {wall:.1} s.\n");
    md
}
