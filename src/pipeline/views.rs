//! Independent camera view detection (paper §3.2, SPEC.md §20.2), one step `views/`:
//!
//! 1. per candidate: render the scene; inpainting mask `M` = alpha < `coverage_alpha`;
//!    `n` inpaintings (the inpaint slot, one key each) and their depths `R` (depth slot);
//! 2. the closest training camera `P` ([`super::poses::pose_distance`]); its depth DIBR-warped to
//!    the candidate; least squares `s, t` of `R` against it (Eq. 2) in the alignment
//!    space; `D = (s·R + t)` on `M` (Eq. 3; `1/(s·R + t)` in disparity space);
//! 3. per inpainting the range of `D` on `M`, their mean (Eq. 4), the frustum of `M`'s
//!    bounding box between those depths;
//! 4. GJK collision graph, greedy maximal independent set in candidate order, closed
//!    nearest-neighbour trajectory; without detection (ablation) the same number of
//!    views evenly spaced along the candidate list.
//!
//! Dependent views: every other candidate with something to inpaint, assigned to the
//! trajectory gap whose segment (between the two independent camera centres) is nearest
//! to its centre, ordered along the gap by the segment parameter. A gap with no dependent
//! view gets a camera interpolated half-way ([`crate::models::morph::interpolate_camera`]).

use super::artifacts::{
    load_depth, load_image, load_mask, read_json, save_depth, save_image, save_mask, stem,
};
use super::depth::{MIN_ALIGN_PIXELS, apply_alignment, render_rgba, training_depth, warp_depth};
use super::generators::{Generators, SlotKind};
use super::poses::{nearest_training, same_pose};
use super::rundir::{StepDone, StepWriter};
use super::selection::{
    ConflictMatch, Coverage, SelectionRule, SurfaceCoverage, conflicting_set, independent_set,
};
use super::steps::Step;
use super::{Event, Inputs, Run};
use crate::camera::Camera;
use crate::camera::inria::{cameras_json_string, read_cameras_json};
use crate::collide::frustum::{Outline, Polyhedron, depth_range, mean_range, write_obj};
use crate::collide::independent::{closed_tour, select_regions};
use crate::error::{Error, Result};
use crate::io::image::ImageF32;
use crate::io::write_text;
use crate::models::DepthHint;
use crate::models::morph::interpolate_camera;
use crate::warp::align::{Alignment, Frame, Space, least_squares};
use glam::DVec3;
use std::collections::BTreeMap;

/// One candidate's record.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Candidate {
    pub name: String,
    /// Pixels to inpaint.
    pub masked: usize,
    /// The closest training view and the alignment of each inpainting's depth to its warp.
    pub nearest_training: Option<String>,
    pub space: Option<Space>,
    pub alignments: Vec<[f64; 2]>,
    pub ranges: Vec<[f64; 2]>,
    /// Eq. 4.
    pub range: Option<[f64; 2]>,
}

/// A dependent view: a candidate left out of the independent set, or a camera made for
/// an empty gap.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Dependent {
    pub name: String,
    /// The gap's two independent views.
    pub between: [String; 2],
    /// Position along the gap's segment, `[0, 1]`.
    pub t: f64,
    /// True for an interpolated camera (no candidate in the gap).
    pub interpolated: bool,
}

/// The result of detection (`views/plan.json`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Plan {
    pub candidates: Vec<Candidate>,
    /// Candidates the scene already covers (nothing to inpaint): left out.
    pub covered: Vec<String>,
    /// Candidates the slots cannot extrapolate (a rule of SPEC.md §20.2), with the reason:
    /// left out, as the covered ones.
    #[serde(default)]
    pub set_aside: Vec<SetAside>,
    pub collisions: Vec<[String; 2]>,
    pub detection: bool,
    pub independent: Vec<String>,
    /// The independent views in tour order.
    pub tour: Vec<String>,
    pub dependent: Vec<Dependent>,
    /// The closed trajectory through every independent and dependent view.
    pub trajectory: Vec<String>,
    /// How the stage-1 set was chosen when not by the paper's default (greedy selection,
    /// the independent set itself): absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub choice: Option<Choice>,
    /// Gaps of the tour without a dependent view that got no camera either: the
    /// ground-truth generator cannot make the truth half-way (its camera sees neither
    /// end's surface, e.g. two views facing apart; SPEC.md §20.2).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unmade_gaps: Vec<[String; 2]>,
    #[serde(skip)]
    pub gap_cameras: Vec<GapCamera>,
}

/// The record of a non-default choice of the stage-1 set (SPEC.md §20.2).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Choice {
    pub rule: SelectionRule,
    /// The rule's independent set and its coverage weight ([`Coverage`]: voxels).
    pub independent: Vec<String>,
    pub coverage: usize,
    /// With `conflicting_views`: the colliding set matched to the independent set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub conflicting: Option<ConflictingChoice>,
}

/// The audit's colliding set ([`conflicting_set`]): both coverages, their relative
/// difference, its overlap, and whether stage 1 uses it (it qualifies: coverage within
/// [`super::selection::CONFLICT_COVERAGE_TOLERANCE`], overlap at least
/// [`super::selection::CONFLICT_MIN_OVERLAP`]; else stage 1 generates the independent set,
/// and the run computes what the independent set computes).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ConflictingChoice {
    pub views: Vec<String>,
    /// The coverage matched on; absent in records of the first rule (a voxel weight, no
    /// longer run), whose `coverage` was that weight.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub matched_on: Option<ConflictMatch>,
    /// [`SurfaceCoverage`] of this set and of the independent set.
    pub coverage: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub independent_coverage: Option<f64>,
    pub coverage_difference: f64,
    /// The share of the sample two of its views generate ([`SurfaceCoverage::overlap`]),
    /// at least [`super::selection::CONFLICT_MIN_OVERLAP`] for the set to qualify.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub overlap: Option<f64>,
    pub used: bool,
}

/// [`Choice`] in candidate indices (into the active candidates).
struct Chosen {
    rule: SelectionRule,
    independent: Vec<usize>,
    coverage: usize,
    conflicting: Option<Conflicting>,
}

/// [`ConflictingChoice`] in candidate indices.
struct Conflicting {
    views: Vec<usize>,
    coverage: f64,
    independent_coverage: f64,
    difference: f64,
    overlap: f64,
    used: bool,
}

impl Chosen {
    /// The set stage 1 generates.
    fn stage1_indices(&self) -> &[usize] {
        match &self.conflicting {
            Some(c) if c.used => &c.views,
            _ => &self.independent,
        }
    }

    fn record(self, name: &dyn Fn(usize) -> String) -> Choice {
        let names = |v: &[usize]| v.iter().map(|&i| name(i)).collect();
        Choice {
            rule: self.rule,
            independent: names(&self.independent),
            coverage: self.coverage,
            conflicting: self.conflicting.map(|c| ConflictingChoice {
                views: names(&c.views),
                matched_on: Some(ConflictMatch::EvaluationCoverage),
                coverage: c.coverage,
                independent_coverage: Some(c.independent_coverage),
                coverage_difference: c.difference,
                overlap: Some(c.overlap),
                used: c.used,
            }),
        }
    }
}

/// The independent set by `config.selection` and, with the audit's colliding set's
/// coverage `surface` (`conflicting_views`), that set.
fn choose(
    config: &super::PipelineConfig,
    n: usize,
    sel: &crate::collide::independent::Selection,
    coverage: &Coverage,
    surface: Option<&SurfaceCoverage>,
) -> Result<Chosen> {
    let independent = independent_set(config.selection, n, &sel.edges, &sel.independent, coverage)?;
    let conflicting = match surface {
        Some(surface) => {
            conflicting_set(n, &sel.edges, &independent, surface)?.map(|(v, d, used)| Conflicting {
                coverage: surface.of(&v),
                independent_coverage: surface.of(&independent),
                overlap: surface.overlap(&v),
                views: v,
                difference: d,
                used,
            })
        }
        None => None,
    };
    Ok(Chosen {
        rule: config.selection,
        coverage: coverage.of(&independent),
        independent,
        conflicting,
    })
}

/// [`SurfaceCoverage`] of the active candidates `cams` with inpainting masks `masks`: on the
/// evaluation views' unseen surface, with the dataset's truth depth at every pose. An error
/// names what is missing where the run has no evaluation views or no truth.
fn surface_coverage(
    inputs: &Inputs,
    cams: &[&Camera],
    masks: &[Vec<bool>],
) -> Result<SurfaceCoverage> {
    let need = "conflicting_views matches the colliding set on the evaluation views' unseen \
                surface: it needs evaluation cameras (--eval) and the dataset's truth depth";
    if inputs.evaluation.is_empty() {
        return Err(Error::invalid(format!(
            "{need}; the run has no evaluation cameras"
        )));
    }
    if cams.len() > crate::collide::independent::EXACT_MAX_VIEWS {
        return Err(Error::invalid(format!(
            "conflicting_views compares every set of candidates: at most {} active candidates, got {}",
            crate::collide::independent::EXACT_MAX_VIEWS,
            cams.len()
        )));
    }
    let truth = super::candidate_truth(inputs)
        .map_err(|e| Error::invalid(format!("{need}: {}", e.message)))?;
    let mut views = Vec::with_capacity(cams.len());
    for (cam, mask) in cams.iter().zip(masks) {
        let t = truth
            .iter()
            .find(|t| t.camera.name == cam.name)
            .ok_or_else(|| Error::invalid(format!("{need}; none at candidate '{}'", cam.name)))?;
        views.push(super::evaluate::Generating {
            camera: cam,
            depth: &t.depth,
            mask,
        });
    }
    let existing = super::evaluate::existing_masks(inputs);
    let mut points = Vec::new();
    super::evaluate::visit_unseen_surface(inputs, &existing, &views, |_, _, hits| {
        points.push(hits.iter().map(|&(k, _)| 1u32 << k).fold(0, |a, b| a | b));
    });
    Ok(SurfaceCoverage::new(points))
}

/// A candidate left out of detection, and why (SPEC.md §20.2).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SetAside {
    pub name: String,
    pub reason: String,
}

/// An interpolated camera and the two independent views it lies between.
#[derive(Clone, Debug, PartialEq)]
pub struct GapCamera {
    pub camera: Camera,
    pub between: [String; 2],
}

/// Detection's output, as read back from disk.
pub struct Views {
    pub step: StepDone,
    pub plan: Plan,
    /// Candidate and interpolated cameras by name.
    pub cameras: BTreeMap<String, Camera>,
}

impl Views {
    pub fn camera(&self, name: &str) -> Result<&Camera> {
        self.cameras
            .get(name)
            .ok_or_else(|| Error::invalid(format!("no camera named '{name}' in the plan")))
    }

    /// Inpainting `j` of an independent candidate and its aligned depth.
    pub fn inpainting(&self, name: &str, j: usize) -> Result<(ImageF32, Vec<f32>)> {
        let cam = self.camera(name)?;
        let dir = self.step.dir.join(stem(name));
        Ok((
            load_image(&dir, &format!("inpaint_{j}"))?,
            load_depth(
                &dir,
                &format!("inpaint_{j}"),
                cam.width as usize,
                cam.height as usize,
            )?,
        ))
    }

    /// The inpainting mask of a candidate.
    pub fn mask(&self, name: &str) -> Result<Vec<bool>> {
        load_mask(&self.step.dir.join(stem(name)), "inpaint")
    }
}

impl Run<'_> {
    /// Run detection (or verify it on disk).
    pub fn views(&self) -> Result<Views> {
        let Run {
            config,
            inputs,
            on_event,
            gens,
            ..
        } = *self;
        let mut key = serde_json::json!({
            "scene": inputs.scene_sha256,
            "candidates": inputs.candidates_sha256,
            "slots": gens.key(config, &[SlotKind::Inpaint, SlotKind::Depth]),
            "coverage_alpha": config.coverage_alpha,
            "inpaintings": config.inpaintings,
            "align_space": config.align_space,
            "independent_detection": config.independent_detection,

        });
        // The choices the paper leaves open, named only away from the defaults (so a
        // default run's step keeps its digest).
        if config.selection != SelectionRule::Greedy {
            key["selection"] = config.selection.name().into();
        }
        if config.frustum_outline != Outline::BoundingBox {
            key["frustum_outline"] = config.frustum_outline.name().into();
        }
        if let Some(m) = config.conflicting_views {
            key["conflicting_views"] = m.name().into();
        }
        if config.selection != SelectionRule::Greedy || config.conflicting_views.is_some() {
            // The coverage weight's points.
            key["init_stride"] = config.init_stride.into();
        }
        // Gap cameras need the ground-truth generator's truth where it runs a slot
        // (`makeable` in `write_plan`): named when neither slot above is the truth (a
        // mixed configuration), so an all-truth or all-model run keeps its digest.
        let truth_in_key = [SlotKind::Inpaint, SlotKind::Depth]
            .iter()
            .any(|&k| gens.is_truth(k));
        if gens.truth.is_some() && !truth_in_key {
            key["gap_truth"] = true.into();
        }
        let step = self.step(&Step::Views, key, |w| {
            let mut found = Found::default();
            for index in 0..inputs.candidates.len() {
                let (record, verdict) = assess(self, index, w)?;
                found.add(index, record, verdict);
            }
            if found.active.is_empty() {
                return Err(found.nothing_to_extrapolate(inputs.candidates.len()));
            }
            write_plan(self, found, w)
        })?;
        let views = load(step)?;
        for a in &views.plan.set_aside {
            on_event(Event::Note(format!(
                "warning: candidate '{}' is set aside: {}",
                a.name, a.reason
            )));
        }
        Ok(views)
    }
}

/// What detection concludes of one candidate.
enum Verdict {
    /// The scene covers it: nothing to inpaint.
    Covered,
    /// Left out, for this reason (SPEC.md §20.2).
    SetAside(String),
    /// To extrapolate: its inpainting mask, its depth range (Eq. 4) and the aligned depth
    /// of its first inpainting (what stage 1 unprojects).
    Active {
        mask: Vec<bool>,
        range: [f64; 2],
        depth: Vec<f32>,
    },
}

/// The candidates as [`assess`] found them, in candidate order.
#[derive(Default)]
struct Found {
    records: Vec<Candidate>,
    covered: Vec<String>,
    set_aside: Vec<SetAside>,
    /// Indices of the active candidates, with their masks, ranges and depths.
    active: Vec<usize>,
    masks: Vec<Vec<bool>>,
    ranges: Vec<[f64; 2]>,
    depths: Vec<Vec<f32>>,
}

impl Found {
    fn add(&mut self, index: usize, record: Candidate, verdict: Verdict) {
        match verdict {
            Verdict::Covered => {
                self.covered.push(record.name.clone());
                self.records.push(record);
            }
            Verdict::SetAside(reason) => {
                self.set_aside.push(SetAside {
                    name: record.name.clone(),
                    reason,
                });
                // A candidate set aside keeps its name and mask size only.
                self.records.push(Candidate {
                    nearest_training: None,
                    space: None,
                    alignments: Vec::new(),
                    ranges: Vec::new(),
                    range: None,
                    ..record
                });
            }
            Verdict::Active { mask, range, depth } => {
                self.masks.push(mask);
                self.ranges.push(range);
                self.depths.push(depth);
                self.active.push(index);
                self.records.push(record);
            }
        }
    }

    /// The error of a run in which no candidate is left to extrapolate.
    fn nothing_to_extrapolate(&self, candidates: usize) -> Error {
        let mut why = format!(
            "nothing to extrapolate: of {candidates} candidate views the scene covers {}",
            self.covered.len()
        );
        for a in &self.set_aside {
            why += &format!("; '{}' is set aside: {}", a.name, a.reason);
        }
        Error::invalid(why)
    }
}

/// Candidate `index`: a repeat of a training view or an earlier candidate, covered
/// by the scene, set aside, or active with its inpaintings' aligned depths (steps 1–3 of
/// the module's list; the renders, masks, inpaintings and depths written to `w`).
fn assess(run: &Run, index: usize, w: &mut StepWriter) -> Result<(Candidate, Verdict)> {
    let Run {
        config,
        inputs,
        gens,
        ..
    } = *run;
    let camera = &inputs.candidates[index];
    let s = stem(&camera.name);
    let (width, height) = (camera.width as usize, camera.height as usize);
    let mut record = Candidate {
        name: camera.name.clone(),
        masked: 0,
        nearest_training: None,
        space: None,
        alignments: Vec::new(),
        ranges: Vec::new(),
        range: None,
    };
    if let Some(reason) = repeat(inputs, index, camera) {
        return Ok((record, Verdict::SetAside(reason)));
    }
    let (rgb, alpha, ed) = render_rgba(&inputs.scene, camera, inputs.background)?;
    let mask: Vec<bool> = alpha.iter().map(|&a| a < config.coverage_alpha).collect();
    save_image(w, &format!("{s}/render"), &rgb)?;
    save_mask(w, &format!("{s}/inpaint"), &mask, width, height)?;
    record.masked = mask.iter().filter(|&&m| m).count();
    if record.masked == 0 {
        return Ok((record, Verdict::Covered));
    }
    if record.masked == width * height
        && let Some(slot) = gens.inpaint_needs_known()
    {
        let reason = format!(
            "sees nothing of the scene (alpha < {} at every pixel) and the inpaint slot '{slot}' fills only from known pixels",
            config.coverage_alpha
        );
        return Ok((record, Verdict::SetAside(reason)));
    }
    let need = MIN_ALIGN_PIXELS.max(width * height / 100);
    let (reference, warped) = match reference_depth(inputs, camera, &alpha, &ed, need)? {
        Some((training, warped)) => (Some(training.name.clone()), warped),
        None => (None, vec![0f32; width * height]),
    };
    if reference.is_none()
        && let Some(slot) = gens.depth_needs_known()
    {
        let reason = format!(
            "no training view shares {need} pixels of known depth with it, nor does the scene cover them, and the depth slot '{slot}' only extends known depth"
        );
        return Ok((record, Verdict::SetAside(reason)));
    }
    record.nearest_training = reference.clone();
    // Eq. 4 over `n` inpaintings only when they can differ: a deterministic slot would
    // give `n` equal ranges (SPEC.md §20.2).
    let n = if gens.inpaintings_differ() {
        config.inpaintings as usize
    } else {
        1
    };
    let mut first = Vec::new();
    for j in 0..n {
        let inpainted = gens.inpaint(camera, &rgb, &mask, &format!("views:{}:{j}", camera.name))?;
        let hint = DepthHint {
            depth: &warped,
            mask: None,
        };
        let estimate = gens.depth(camera, &inpainted, hint)?;
        let space = config.align_space.unwrap_or(estimate.kind.space());
        let alignment = match &reference {
            Some(r) => match least_squares(
                &[Frame {
                    estimate: &estimate.values,
                    depth: &warped,
                }],
                space,
            ) {
                Ok(a) => a,
                Err(e) => {
                    let reason = format!(
                        "its depth cannot be aligned to training view '{r}' ({})",
                        e.message
                    );
                    return Ok((record, Verdict::SetAside(reason)));
                }
            },
            None if space == Space::Depth => Alignment::identity(0),
            None => {
                let reason = format!(
                    "no training view shares {need} pixels of known depth with it, nor does the scene cover them, so its {space:?} estimate cannot be aligned (is the view behind or outside the scene?)"
                );
                return Ok((record, Verdict::SetAside(reason)));
            }
        };
        let depth = apply_alignment(&estimate, &alignment, space);
        let range = match depth_range(&depth, &mask) {
            Ok(r) => r,
            Err(e) => {
                let reason = format!(
                    "inpainting {j}: {} after alignment, so it has no frustum",
                    e.message
                );
                return Ok((record, Verdict::SetAside(reason)));
            }
        };
        save_image(w, &format!("{s}/inpaint_{j}"), &inpainted)?;
        save_depth(w, &format!("{s}/inpaint_{j}"), &depth, width, height)?;
        record.space = Some(space);
        record.alignments.push([alignment.scale, alignment.offset]);
        record.ranges.push(range);
        if j == 0 {
            first = depth;
        }
    }
    let range = mean_range(&record.ranges)?;
    record.range = Some(range);
    let active = Verdict::Active {
        mask,
        range,
        depth: first,
    };
    Ok((record, active))
}

/// Why candidate `index` has nothing of its own to extrapolate, if so: it has a training
/// view's pose, or it is the same camera as an earlier candidate (which it would only
/// collide with).
fn repeat(inputs: &Inputs, index: usize, camera: &Camera) -> Option<String> {
    let training = inputs
        .data
        .train
        .iter()
        .map(|&t| &inputs.data.views[t].camera)
        .find(|t| same_pose(t, camera));
    if let Some(t) = training {
        return Some(format!(
            "has the pose of training view '{}': nothing to extrapolate there",
            t.name
        ));
    }
    let intrinsics = |c: &Camera| (c.width, c.height, c.fx, c.fy, c.cx, c.cy);
    inputs.candidates[..index]
        .iter()
        .find(|p| same_pose(p, camera) && intrinsics(p) == intrinsics(camera))
        .map(|p| format!("is the same camera as candidate '{}'", p.name))
}

/// Eq. 2's target for `camera`: the depth of the closest training view (by pose distance)
/// that shares at least `need` known pixels with it, warped here; where the warp leaves a
/// hole, the scene's own expected depth `ed` where the scene is opaque (`alpha` ≥ 0.5).
/// `None` when no training view shares enough (the candidate shares no surface with the
/// training views or the scene).
fn reference_depth<'i>(
    inputs: &'i Inputs,
    camera: &Camera,
    alpha: &[f32],
    ed: &[f32],
    need: usize,
) -> Result<Option<(&'i Camera, Vec<f32>)>> {
    for p in nearest_training(&inputs.data, camera, inputs.data.train.len()) {
        let training = &inputs.data.views[p].camera;
        let mut warped = warp_depth(&training_depth(inputs, p)?, training, camera)?;
        for (k, d) in warped.iter_mut().enumerate() {
            if *d <= 0.0 && alpha[k] >= 0.5 {
                *d = ed[k];
            }
        }
        if warped.iter().filter(|&&d| d > 0.0).count() >= need {
            return Ok(Some((training, warped)));
        }
    }
    Ok(None)
}

/// Step 4 of the module's list on the active candidates of `found`: the collision graph,
/// the independent set and its tour, the dependent views and the gap cameras; writes
/// `plan.json`, `cameras.json` and the frustum pictures.
fn write_plan(run: &Run, found: Found, w: &mut StepWriter) -> Result<()> {
    let Run {
        config,
        inputs,
        gens,
        ..
    } = *run;
    let active = &found.active;
    let name = |i: usize| inputs.candidates[active[i]].name.clone();
    let cams: Vec<&Camera> = active.iter().map(|&i| &inputs.candidates[i]).collect();
    let (polys, sel) = select_regions(
        &cams,
        &found.masks,
        &found.ranges,
        config.frustum_outline,
        None,
    )?;
    let centers: Vec<DVec3> = cams.iter().map(|c| c.center).collect();
    // The paper's choice (greedy, stage 1 on the independent set) needs no coverage and
    // records none, so its plan keeps its bytes.
    let choice = (config.selection != SelectionRule::Greedy || config.conflicting_views.is_some())
        .then(|| {
            let coverage = Coverage::new(
                &cams,
                &found.masks,
                &found.depths,
                config.init_stride as usize,
            );
            let surface = match config.conflicting_views {
                Some(ConflictMatch::EvaluationCoverage) => {
                    Some(surface_coverage(inputs, &cams, &found.masks)?)
                }
                None => None,
            };
            choose(config, active.len(), &sel, &coverage, surface.as_ref())
        })
        .transpose()?;
    // The set stage 1 generates: the chosen one, or as many views evenly spaced.
    let chosen = choice
        .as_ref()
        .map_or(&sel.independent[..], |c| c.stage1_indices());
    let independent: Vec<usize> = if config.independent_detection {
        chosen.to_vec()
    } else {
        let (k, m) = (chosen.len(), active.len());
        (0..k).map(|j| j * m / k).collect()
    };
    let (tour, _) = closed_tour(&independent, &centers);
    // A gap camera needs a truth where the generator is the dataset's truth.
    let makeable = |a: &Camera, b: &Camera| {
        gens.truth
            .as_ref()
            .map_or(Ok(true), |gt| gt.can_make_between(&a.name, &b.name))
    };
    let Gaps {
        dependent,
        cameras: gap_cams,
        unmade: unmade_gaps,
    } = assign_dependents(
        active,
        &independent,
        &tour,
        &centers,
        |i| &inputs.candidates[active[i]],
        makeable,
    )?;
    let mut trajectory = Vec::new();
    for &t in &tour {
        trajectory.push(name(t));
        let mut here: Vec<&Dependent> = dependent
            .iter()
            .filter(|d| d.between[0] == name(t))
            .collect();
        here.sort_by(|a, b| a.t.total_cmp(&b.t));
        trajectory.extend(here.iter().map(|d| d.name.clone()));
    }
    let plan = Plan {
        candidates: found.records,
        covered: found.covered,
        set_aside: found.set_aside,
        collisions: sel.edges.iter().map(|&(i, j)| [name(i), name(j)]).collect(),
        detection: config.independent_detection,
        independent: independent.iter().map(|&i| name(i)).collect(),
        tour: tour.iter().map(|&i| name(i)).collect(),
        dependent,
        trajectory,
        choice: choice.map(|c| c.record(&name)),
        unmade_gaps,
        gap_cameras: Vec::new(),
    };
    w.json("plan.json", &plan)?;
    let mut all: Vec<Camera> = inputs.candidates.clone();
    all.extend(gap_cams.iter().map(|g| g.camera.clone()));
    let text = cameras_json_string(&all);
    w.put("cameras.json", |p| write_text(p, &text))?;
    w.put("frustums.obj", |p| write_obj(p, &polys))?;
    let svg = frustums_svg(&polys, &plan, &cams, &inputs.data.train_cameras());
    w.put("frustums.svg", |p| write_text(p, &svg))?;
    if let Some(gt) = gens.truth.as_ref().filter(|g| g.hallucinates()) {
        conflict_picture(gens, gt, &plan, inputs, w)?;
    }
    Ok(())
}

/// The hallucinating generator's conflict, for people (SPEC.md §20.6): two independent
/// generations of the first independent view (else candidate) of which at least 10 % of
/// the pixels no training view saw — the whole image generated, keys `conflict:<view>:a`
/// and `:b` — as `conflict_a` / `conflict_b`, and in `conflict.json` their PSNR over the
/// unseen pixels.
fn conflict_picture(
    gens: &Generators,
    gt: &super::generators::GroundTruth,
    plan: &Plan,
    inputs: &Inputs,
    w: &mut StepWriter,
) -> Result<()> {
    let order = plan
        .independent
        .iter()
        .chain(plan.candidates.iter().map(|c| &c.name));
    for name in order {
        let Some(cam) = inputs.candidates.iter().find(|c| &c.name == name) else {
            continue;
        };
        let t = gt.get(name)?;
        let unseen = gt.unseen(cam, &t.depth);
        let n = unseen.iter().filter(|&&u| u).count();
        if n * 10 < unseen.len() {
            continue;
        }
        let all = vec![true; unseen.len()];
        let a = gens.inpaint(cam, &t.image, &all, &format!("conflict:{name}:a"))?;
        let b = gens.inpaint(cam, &t.image, &all, &format!("conflict:{name}:b"))?;
        let sums: Vec<crate::pipeline::evaluate::ClassSums> = unseen
            .iter()
            .enumerate()
            .filter(|(_, u)| **u)
            .map(|(p, _)| {
                let se = (0..3)
                    .map(|c| {
                        let d = (a.data[p * 3 + c] - b.data[p * 3 + c]) as f64;
                        d * d
                    })
                    .sum();
                crate::pipeline::evaluate::ClassSums {
                    pixels: 1,
                    squared_error: se,
                    ..Default::default()
                }
            })
            .collect();
        save_image(w, "conflict_a", &a)?;
        save_image(w, "conflict_b", &b)?;
        w.json(
            "conflict.json",
            &serde_json::json!({
                "view": name,
                "unseen_pixels": n,
                "psnr_db": crate::pipeline::evaluate::ClassSums::psnr(&sums),
            }),
        )?;
        return Ok(());
    }
    Ok(())
}

/// Read a finished `views/` step.
pub fn load(step: StepDone) -> Result<Views> {
    let mut plan: Plan = read_json(&step.dir.join("plan.json"))?;
    let cams = read_cameras_json(&step.dir.join("cameras.json"))?;
    let cameras: BTreeMap<String, Camera> = cams.into_iter().map(|c| (c.name.clone(), c)).collect();
    plan.gap_cameras = plan
        .dependent
        .iter()
        .filter(|d| d.interpolated)
        .map(|d| {
            Ok(GapCamera {
                camera: cameras
                    .get(&d.name)
                    .cloned()
                    .ok_or_else(|| Error::invalid(format!("no camera '{}'", d.name)))?,
                between: d.between.clone(),
            })
        })
        .collect::<Result<_>>()?;
    Ok(Views {
        step,
        plan,
        cameras,
    })
}

/// What [`assign_dependents`] makes of the tour's gaps.
#[derive(Debug)]
struct Gaps {
    /// The dependent views, each with its gap.
    dependent: Vec<Dependent>,
    /// A camera half-way along each gap without a dependent view...
    cameras: Vec<GapCamera>,
    /// ...but for those gaps where `makeable` refuses one.
    unmade: Vec<[String; 2]>,
}

/// Dependent views by gap, the cameras made for empty gaps and the empty gaps for which
/// `makeable` refuses a camera. Indices are into `active` (the candidates with something
/// to inpaint).
fn assign_dependents<'c>(
    active: &[usize],
    independent: &[usize],
    tour: &[usize],
    centers: &[DVec3],
    cam: impl Fn(usize) -> &'c Camera,
    makeable: impl Fn(&Camera, &Camera) -> Result<bool>,
) -> Result<Gaps> {
    let m = tour.len();
    // Gaps: consecutive tour pairs, closed; two views have one gap, one view a
    // degenerate gap to itself.
    let gaps: Vec<(usize, usize)> = match m {
        0 => Vec::new(),
        1 => vec![(tour[0], tour[0])],
        2 => vec![(tour[0], tour[1])],
        _ => (0..m).map(|k| (tour[k], tour[(k + 1) % m])).collect(),
    };
    let mut dependent = Vec::new();
    let mut used = vec![false; gaps.len()];
    for i in 0..active.len() {
        if independent.contains(&i) {
            continue;
        }
        let p = centers[i];
        let mut best = (f64::INFINITY, 0usize, 0.0f64);
        for (g, &(a, b)) in gaps.iter().enumerate() {
            let (ca, cb) = (centers[a], centers[b]);
            let ab = cb - ca;
            let l2 = ab.length_squared();
            let t = if l2 > 0.0 {
                ((p - ca).dot(ab) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let d = (ca + ab * t - p).length();
            if d < best.0 {
                best = (d, g, t);
            }
        }
        let (_, g, t) = best;
        used[g] = true;
        let (a, b) = gaps[g];
        dependent.push(Dependent {
            name: cam(i).name.clone(),
            between: [cam(a).name.clone(), cam(b).name.clone()],
            t,
            interpolated: false,
        });
    }
    let (mut gap_cams, mut unmade) = (Vec::new(), Vec::new());
    for (g, &(a, b)) in gaps.iter().enumerate() {
        if used[g] || a == b {
            continue;
        }
        if !makeable(cam(a), cam(b))? {
            unmade.push([cam(a).name.clone(), cam(b).name.clone()]);
            continue;
        }
        let name = format!("gap_{}_{}", cam(a).name, cam(b).name);
        // A camera has one size: between views of different sizes the gap camera takes
        // the first view's size and intrinsics, its pose still half-way.
        let (ca, cb) = (cam(a), cam(b));
        let b_as_a = Camera {
            width: ca.width,
            height: ca.height,
            fx: ca.fx,
            fy: ca.fy,
            cx: ca.cx,
            cy: ca.cy,
            ..cb.clone()
        };
        let c = interpolate_camera(ca, &b_as_a, 0.5, name.clone())?;
        dependent.push(Dependent {
            name,
            between: [cam(a).name.clone(), cam(b).name.clone()],
            t: 0.5,
            interpolated: true,
        });
        gap_cams.push(GapCamera {
            camera: c,
            between: [cam(a).name.clone(), cam(b).name.clone()],
        });
    }
    Ok(Gaps {
        dependent,
        cameras: gap_cams,
        unmade,
    })
}

/// A top-down picture (world x to the right, z down the page; y is up in the bundled
/// rooms) of the frustums — independent views filled, the others outlined — the training
/// cameras (grey dots) and the closed trajectory (the line through the camera centres).
fn frustums_svg(polys: &[Polyhedron], plan: &Plan, cams: &[&Camera], train: &[Camera]) -> String {
    let pts2 =
        |p: &Polyhedron| -> Vec<[f64; 2]> { p.vertices.iter().map(|v| [v.x, v.z]).collect() };
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    let mut grow = |q: [f64; 2]| {
        for k in 0..2 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    };
    polys.iter().flat_map(pts2).for_each(&mut grow);
    train.iter().for_each(|c| grow([c.center.x, c.center.z]));
    let size = 640.0;
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-9);
    let margin = 20.0;
    let map = |q: [f64; 2]| -> (f64, f64) {
        (
            margin + (q[0] - lo[0]) / span * (size - 2.0 * margin),
            margin + (q[1] - lo[1]) / span * (size - 2.0 * margin),
        )
    };
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{size}\" height=\"{size}\" viewBox=\"0 0 {size} {size}\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
    );
    for p in polys {
        let hull = hull2(&pts2(p));
        let d: Vec<String> = hull
            .iter()
            .map(|&q| {
                let (x, y) = map(q);
                format!("{x:.1},{y:.1}")
            })
            .collect();
        let independent = plan.independent.contains(&p.name);
        svg += &format!(
            "<polygon points=\"{}\" fill=\"{}\" fill-opacity=\"0.25\" stroke=\"{}\" stroke-width=\"1\"><title>{}</title></polygon>\n",
            d.join(" "),
            if independent { "#1f77b4" } else { "none" },
            if independent { "#1f77b4" } else { "#999999" },
            p.name
        );
    }
    for c in train {
        let (x, y) = map([c.center.x, c.center.z]);
        svg += &format!("<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"2\" fill=\"#bbbbbb\"/>\n");
    }
    let centre = |name: &str| {
        cams.iter()
            .find(|c| c.name == name)
            .map(|c| [c.center.x, c.center.z])
    };
    let tour: Vec<String> = plan
        .trajectory
        .iter()
        .chain(plan.trajectory.first())
        .filter_map(|n| centre(n))
        .map(|q| {
            let (x, y) = map(q);
            format!("{x:.1},{y:.1}")
        })
        .collect();
    svg += &format!(
        "<polyline points=\"{}\" fill=\"none\" stroke=\"#d62728\" stroke-width=\"1.5\"/>\n",
        tour.join(" ")
    );
    for n in &plan.trajectory {
        if let Some(q) = centre(n) {
            let (x, y) = map(q);
            svg += &format!(
                "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"3\" fill=\"#d62728\"/><text x=\"{:.1}\" y=\"{:.1}\" font-size=\"9\" font-family=\"sans-serif\">{n}</text>\n",
                x + 4.0,
                y - 4.0
            );
        }
    }
    svg + "</svg>\n"
}

/// Convex hull of 2D points (monotone chain), counter-clockwise.
fn hull2(pts: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p = pts.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    crate::math::hull::monotone_chain(&p)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Four views on a ring, two of them independent: the gaps without a dependent view
    /// get a camera half-way unless `makeable` refuses it, which the plan then lists as
    /// unmade (the ground-truth generator cannot make the truth of a camera that sees
    /// neither end, e.g. between views facing apart).
    #[test]
    fn an_empty_gap_gets_a_camera_unless_its_truth_cannot_be_made() {
        let cams: Vec<Camera> = (0..4)
            .map(|k| {
                let a = std::f64::consts::FRAC_PI_2 * k as f64;
                let eye = DVec3::new(a.cos(), 1.0, a.sin());
                let out = DVec3::new(2.0 * a.cos(), 1.0, 2.0 * a.sin());
                Camera::look_at(format!("v{k}"), 16, 12, 1.2, eye, out, DVec3::Y).unwrap()
            })
            .collect();
        let centers: Vec<DVec3> = cams.iter().map(|c| c.center).collect();
        let active = [0, 1, 2, 3];
        // v0 and v2 independent; v1 lies on both gaps (it takes the first), v3 too.
        let run = |refuse: &str| {
            assign_dependents(
                &active,
                &[0, 2],
                &[0, 2],
                &centers,
                |i| &cams[i],
                |a, b| Ok(!(a.name == refuse || b.name == refuse)),
            )
            .unwrap()
        };
        let g = run("none");
        assert_eq!(g.dependent.len(), 2, "{g:?}");
        assert!(g.cameras.is_empty() && g.unmade.is_empty());
        // Only v0 and v2 active and independent: one gap (two views), empty.
        let two = |refuse: &str| {
            assign_dependents(
                &[0, 2],
                &[0, 1],
                &[0, 1],
                &centers,
                |i| &cams[2 * i],
                |a, b| Ok(!(a.name == refuse || b.name == refuse)),
            )
            .unwrap()
        };
        let g = two("none");
        assert_eq!((g.dependent.len(), g.cameras.len()), (1, 1));
        assert!(g.dependent[0].interpolated && g.unmade.is_empty());
        assert_eq!(g.cameras[0].camera.name, "gap_v0_v2");
        let g = two("v2");
        assert!(g.dependent.is_empty() && g.cameras.is_empty(), "{g:?}");
        assert_eq!(g.unmade, [["v0".to_string(), "v2".to_string()]]);
    }
}
