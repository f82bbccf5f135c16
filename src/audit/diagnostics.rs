//! What one run of the audit did (SPEC.md §21.5), recorded with its sample so that a
//! verdict shows the mechanism it rests on: detection's candidates, collisions and sets;
//! how much of the unseen surface the stage-1 views generated, how much of it two of them
//! generated, and how strongly those generations disagree; the share stage 2 inpainted.
//!
//! The unseen surface is sampled by the evaluation views' *extrapolated* pixels with a
//! truth depth (SPEC.md §20.7): each is a surface point no training view sees. A stage-1
//! view *generated* that point when the point is visible in the view (its truth depth
//! agrees) at a pixel of its inpainting mask
//! ([`crate::pipeline::evaluate::visit_unseen_surface`]). Evaluation poses serve to
//! measure here; the one choice that reads them is the audit's own control,
//! `conflicting_views`, matched on this same coverage (SPEC.md §20.2).

use crate::error::{Error, Result};
use crate::gaussian::Gaussians;
use crate::pipeline::artifacts::{load_image, load_mask};
use crate::pipeline::evaluate::{
    CLASS_CONTESTED, CLASS_OTHER, CLASS_UNCONTESTED, ClassSums, Generating, ScoredView, seen_at,
    visit_unseen_surface,
};
use crate::pipeline::rundir::StepDone;
use crate::pipeline::views::{Plan, SetAside};
use crate::pipeline::{Inputs, Step, candidate_truth, stem};
use crate::raster::RenderOptions;
use std::collections::BTreeMap;
use std::path::Path;

/// One run's diagnostics.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Diagnostics {
    /// Candidate views given; those the scene covers; those set aside, with the reason.
    pub candidates: usize,
    pub covered: usize,
    pub set_aside: Vec<SetAside>,
    /// Colliding pairs among the candidates left (*active*), and all their pairs.
    pub collisions: usize,
    pub pairs: usize,
    /// The stage-1 views in tour order (the independent set, or the variant's set).
    pub stage1_views: Vec<String>,
    /// Of the stage-1 views, pairs whose frustums collide (0 for an independent set).
    pub stage1_collisions: usize,
    /// Dependent views per gap of the closed tour (gap `i` runs from tour view `i` to the
    /// next), and how many of them are made cameras (a gap without a candidate).
    pub dependent_per_gap: Vec<usize>,
    pub interpolated: usize,
    /// Gaps from a view to itself: a one-view tour, whose clips go nowhere.
    pub degenerate_gaps: usize,
    /// Empty gaps that got no camera: the truth half-way cannot be made (`plan.json`'s
    /// `unmade_gaps`; written only when there are some).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub unmade_gaps: usize,
    /// The stage-1 views' generation of the unseen surface (`None` when the run made no
    /// stage-1 views, the dataset has no truth at the candidate poses, or the evaluation
    /// views have no extrapolated pixel with depth).
    pub stage1: Option<Generation>,
    /// Share of the dependent views' pixels stage 2 inpainted (NaN without stage 2).
    #[serde(with = "crate::io::json_float")]
    pub stage2_filled: f64,
    /// How the stage-1 set was chosen when not by the paper's default (`plan.json`'s
    /// `choice`: the rule's set, its coverage weight, the conflicting set's and their
    /// relative difference).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub choice: Option<crate::pipeline::views::Choice>,
    /// Generation fidelity (SPEC.md §21.7): per stage-1 view, the final scene rendered
    /// there against what the view generated, on the pixels it generated; empty when not
    /// measured (no truth at the candidate poses, or a run recorded before).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub fidelity: Vec<FidelityView>,
}

/// A stage-1 view's generation fidelity: [`ClassSums`] of the final scene's render there
/// against the view's generation (as the truth), over the generated pixels whose surface
/// point another stage-1 view generated too (*contested*) and over the rest.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FidelityView {
    pub view: String,
    pub contested: ClassSums,
    pub uncontested: ClassSums,
}

/// The stage-1 views' generation of the unseen surface.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Generation {
    /// Extrapolated evaluation pixels with a truth depth: the sample of the unseen surface.
    pub pixels: u64,
    /// Shares of those points that at least one (*coverage*) and at least two
    /// (*overlap*) stage-1 views generated.
    pub coverage: f64,
    pub overlap: f64,
    /// Mean squared difference (over the three channels, colours in [0, 1]) between two
    /// stage-1 generations of one point, over every point and every pair of views that
    /// generated it; NaN without overlap.
    #[serde(with = "crate::io::json_float")]
    pub conflict: f64,
}

/// The diagnostics of a finished run: its steps (by name) and its inputs (with truth); and
/// each evaluation pixel's class (`CLASS_*` of [`crate::pipeline::evaluate`]), per view in
/// evaluation order, where the run generated part of the unseen surface.
pub fn diagnose(
    inputs: &Inputs,
    steps: &[StepDone],
    scene: Option<&Gaussians>,
) -> Result<(Diagnostics, Option<Vec<Vec<u8>>>)> {
    let dirs: BTreeMap<&str, &Path> = steps
        .iter()
        .map(|s| (s.name.as_str(), s.dir.as_path()))
        .collect();
    let dir_of = |step: &Step| dirs.get(step.to_string().as_str()).copied();
    let views = dir_of(&Step::Views)
        .ok_or_else(|| Error::invalid("the run has no views step to diagnose"))?;
    let plan: Plan = crate::pipeline::artifacts::read_json(&views.join("plan.json"))?;
    let active = plan.candidates.len() - plan.covered.len() - plan.set_aside.len();
    let collide = |a: &str, b: &str| {
        plan.collisions
            .iter()
            .any(|[x, y]| (x == a && y == b) || (x == b && y == a))
    };
    let tour = &plan.tour;
    let mut stage1_collisions = 0;
    for (i, a) in tour.iter().enumerate() {
        stage1_collisions += tour[i + 1..].iter().filter(|b| collide(a, b)).count();
    }
    let gap = |i: usize| [tour[i].clone(), tour[(i + 1) % tour.len()].clone()];
    let dependent_per_gap = (0..tour.len())
        .map(|i| {
            let g = gap(i);
            plan.dependent.iter().filter(|d| d.between == g).count()
        })
        .collect();
    let degenerate_gaps = (0..tour.len()).filter(|&i| gap(i)[0] == gap(i)[1]).count();

    // The stage-1 views' masks and generations, with their truth depths (none to measure
    // with when the dataset has no truth at the candidate poses).
    let truth = candidate_truth(inputs).unwrap_or_default();
    let mut stage1 = Vec::new();
    for name in tour {
        let Some(dir) = dir_of(&Step::Independent(stem(name))) else {
            continue;
        };
        if truth.is_empty() {
            break;
        }
        let t = truth
            .iter()
            .find(|t| &t.camera.name == name)
            .ok_or_else(|| Error::invalid(format!("no candidate named '{name}'")))?;
        let (mask, image) = (load_mask(dir, "inpaint")?, load_image(dir, "inpaint")?);
        let size = t.depth.len();
        if mask.len() != size || image.width * image.height != size || image.channels < 3 {
            return Err(Error::invalid(format!(
                "the inpainting of '{name}' does not have the view's size"
            ))
            .at(dir));
        }
        stage1.push((t, mask, image));
    }
    let fidelity = match scene {
        Some(scene) => fidelity(inputs, scene, &stage1)?,
        None => Vec::new(),
    };
    let (generation, classes) = match dir_of(&Step::EvalMasks) {
        Some(masks) if !stage1.is_empty() => generation(inputs, masks, &stage1)?.unzip(),
        _ => (None, None),
    };

    let stage2_filled = match dir_of(&Step::Dependent) {
        Some(dir) => {
            let (mut filled, mut all) = (0usize, 0usize);
            for d in &plan.dependent {
                let m = load_mask(&dir.join(stem(&d.name)), "inpaint")?;
                filled += m.iter().filter(|&&b| b).count();
                all += m.len();
            }
            filled as f64 / all.max(1) as f64
        }
        None => f64::NAN,
    };
    let diagnostics = Diagnostics {
        candidates: plan.candidates.len(),
        covered: plan.covered.len(),
        set_aside: plan.set_aside.clone(),
        collisions: plan.collisions.len(),
        pairs: active * active.saturating_sub(1) / 2,
        stage1_views: tour.clone(),
        stage1_collisions,
        dependent_per_gap,
        interpolated: plan.dependent.iter().filter(|d| d.interpolated).count(),
        degenerate_gaps,
        unmade_gaps: plan.unmade_gaps.len(),
        stage1: generation,
        stage2_filled,
        choice: plan.choice.clone(),
        fidelity,
    };
    Ok((diagnostics, classes))
}

/// A stage-1 view of a finished run: its truth (camera and depth), its inpainting mask and
/// its generation.
type Stage1View<'a> = (
    &'a crate::pipeline::generators::Truth,
    Vec<bool>,
    crate::io::image::ImageF32,
);

/// The final scene's [`FidelityView`] at each stage-1 view `(truth, mask, generation)`: a
/// generated pixel is contested when its surface point (from the view's truth depth) is
/// seen by another stage-1 view ([`seen_at`]) at a pixel of its mask.
fn fidelity(
    inputs: &Inputs,
    scene: &Gaussians,
    stage1: &[Stage1View],
) -> Result<Vec<FidelityView>> {
    let opts = RenderOptions {
        background: inputs.background,
        ..RenderOptions::default()
    };
    let mut out = Vec::with_capacity(stage1.len());
    for (k, (t, mask, image)) in stage1.iter().enumerate() {
        let rgb: Vec<f32> = match image.channels {
            3 => image.data.clone(),
            c => image
                .data
                .chunks_exact(c)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect(),
        };
        let scored = ScoredView::against(scene, &t.camera, &rgb, &opts)?;
        let mut view = FidelityView {
            view: t.camera.name.clone(),
            contested: ClassSums::default(),
            uncontested: ClassSums::default(),
        };
        let w = t.camera.width as usize;
        for (p, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
            let z = t.depth[p] as f64;
            let contested = z.is_finite()
                && z > 0.0
                && stage1.iter().enumerate().any(|(j, (o, om, _))| {
                    j != k
                        && seen_at(&o.camera, &o.depth, t.camera.pixel_point(p % w, p / w, z))
                            .is_some_and(|q| om[q])
                });
            let sums = if contested {
                &mut view.contested
            } else {
                &mut view.uncontested
            };
            sums.add(&scored, p);
        }
        out.push(view);
    }
    Ok(out)
}

/// [`Generation`] of the stage-1 views `(truth, mask, inpainting)` on the sample of the
/// unseen surface ([`visit_unseen_surface`]; the evaluation views' existing-pixel masks in
/// `masks`), and each evaluation pixel's class (`CLASS_*`), per view in evaluation order.
fn generation(
    inputs: &Inputs,
    masks: &Path,
    stage1: &[Stage1View],
) -> Result<Option<(Generation, Vec<Vec<u8>>)>> {
    let existing = inputs
        .evaluation
        .iter()
        .map(|&i| load_mask(masks, &stem(&inputs.data.views[i].camera.name)))
        .collect::<Result<Vec<_>>>()?;
    let views: Vec<Generating> = stage1
        .iter()
        .map(|(t, mask, _)| Generating {
            camera: &t.camera,
            depth: &t.depth,
            mask,
        })
        .collect();
    let (mut pixels, mut once, mut twice) = (0u64, 0u64, 0u64);
    let (mut sq, mut pairs) = (0f64, 0u64);
    let mut classes: Vec<Vec<u8>> = existing
        .iter()
        .map(|m| vec![CLASS_OTHER; m.len()])
        .collect();
    visit_unseen_surface(inputs, &existing, &views, |e, p, hits| {
        classes[e][p] = if hits.len() >= 2 {
            CLASS_CONTESTED
        } else {
            CLASS_UNCONTESTED
        };
        pixels += 1;
        once += u64::from(!hits.is_empty());
        twice += u64::from(hits.len() >= 2);
        for (a, &(ka, qa)) in hits.iter().enumerate() {
            for &(kb, qb) in &hits[a + 1..] {
                let (ia, ib) = (&stage1[ka].2, &stage1[kb].2);
                let d: f64 = (0..3)
                    .map(|c| {
                        let e =
                            (ia.data[qa * ia.channels + c] - ib.data[qb * ib.channels + c]) as f64;
                        e * e
                    })
                    .sum();
                sq += d / 3.0;
                pairs += 1;
            }
        }
    });
    if pixels == 0 {
        return Ok(None);
    }
    Ok(Some((
        Generation {
            pixels,
            coverage: once as f64 / pixels as f64,
            overlap: twice as f64 / pixels as f64,
            conflict: if pairs == 0 {
                f64::NAN
            } else {
                sq / pairs as f64
            },
        },
        classes,
    )))
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}
