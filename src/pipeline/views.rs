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
use super::generators::{Generators, SlotKind};
use super::poses::{nearest_training, same_pose};
use super::rundir::StepDone;
use super::{Event, Inputs, StageCtx};
use crate::camera::Camera;
use crate::camera::inria::{cameras_json_string, read_cameras_json};
use crate::collide::frustum::{Outline, Polyhedron, depth_range, mean_range, write_obj};
use crate::collide::independent::{closed_tour, select_regions};
use crate::error::{Error, Result};
use crate::io::image::ImageF32;
use crate::io::write_text;
use crate::models::morph::interpolate_camera;
use crate::models::{DepthHint, DepthMap};
use crate::raster::{Outputs, RenderOptions, render};
use crate::warp::align::{Alignment, Frame, Space, least_squares};
use crate::warp::dibr::{WarpOptions, warp};
use glam::DVec3;
use std::collections::BTreeMap;

/// Fewest known-depth pixels a candidate must share with its reference training view.
pub const MIN_ALIGN_PIXELS: usize = 16;

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
    #[serde(skip)]
    pub gap_cameras: Vec<GapCamera>,
}

/// The per-view stage-1 steps of the run `out` (`stage1/<view>` for each independent view
/// of its finished views step, in plan order): what a batch engine fans out after
/// `--until views` (SPEC.md §20.8).
pub fn stage1_steps(out: &std::path::Path) -> Result<Vec<String>> {
    let path = out.join("views").join("plan.json");
    if !path.is_file() {
        return Err(Error::invalid(
            "the views step is not done here (run with --until views first)",
        )
        .at(out));
    }
    let plan: Plan = read_json(&path)?;
    Ok(plan
        .independent
        .iter()
        .map(|n| format!("stage1/{}", super::stem(n)))
        .collect())
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

/// Aligned metric depth from an estimate: `s·R + t`, or its inverse in disparity space;
/// non-positive or non-finite results are 0 (unknown).
pub fn apply_alignment(est: &DepthMap, a: &Alignment, space: Space) -> Vec<f32> {
    est.values
        .iter()
        .map(|&r| {
            let m = a.scale * r as f64 + a.offset;
            let d = match space {
                Space::Depth => m,
                Space::Disparity => 1.0 / m,
            };
            if d.is_finite() && d > 0.0 {
                d as f32
            } else {
                0.0
            }
        })
        .collect()
}

/// The metric depth of a training view: the dataset's, else the scene's expected depth.
pub fn training_depth(inputs: &Inputs, vi: usize) -> Result<Vec<f32>> {
    let v = &inputs.data.views[vi];
    if let Some(d) = &v.depth {
        return Ok(d.clone());
    }
    let r = render(
        &inputs.scene,
        &v.camera,
        &RenderOptions {
            background: inputs.background,
            outputs: Outputs {
                rgb: false,
                alpha: true,
                expected_depth: true,
                ..Outputs::default()
            },
            ..RenderOptions::default()
        },
    )?;
    let a = r.alpha.expect("alpha");
    Ok(r.expected_depth
        .expect("expected depth")
        .iter()
        .zip(&a)
        .map(|(&d, &al)| if al > 0.5 { d } else { 0.0 })
        .collect())
}

/// Warp a metric depth map from one camera to another (nearest, crack closing 1).
pub fn warp_depth(depth: &[f32], from: &Camera, to: &Camera) -> Result<Vec<f32>> {
    let img = ImageF32::new(from.width as usize, from.height as usize, 1, depth.to_vec())?;
    let w = warp(
        &img,
        depth,
        from,
        to,
        &WarpOptions {
            close_cracks: 1,
            ..WarpOptions::default()
        },
    )?;
    Ok(w.depth)
}

/// Render RGB alone (what the fixer reads): the same RGB bits as [`render_rgba`] without
/// the depth accumulation (`raster::plan`'s skips are exact).
pub fn render_rgb(
    scene: &crate::gaussian::Gaussians,
    cam: &Camera,
    background: [f32; 3],
) -> Result<ImageF32> {
    let r = render(
        scene,
        cam,
        &RenderOptions {
            background,
            outputs: Outputs::RGB,
            ..RenderOptions::default()
        },
    )?;
    ImageF32::new(r.width, r.height, 3, r.rgb.expect("rgb"))
}

/// Render RGB, alpha and expected depth.
pub fn render_rgba(
    scene: &crate::gaussian::Gaussians,
    cam: &Camera,
    background: [f32; 3],
) -> Result<(ImageF32, Vec<f32>, Vec<f32>)> {
    let r = render(
        scene,
        cam,
        &RenderOptions {
            background,
            outputs: Outputs {
                rgb: true,
                alpha: true,
                expected_depth: true,
                ..Outputs::default()
            },
            ..RenderOptions::default()
        },
    )?;
    let (w, h) = (r.width, r.height);
    Ok((
        ImageF32::new(w, h, 3, r.rgb.expect("rgb"))?,
        r.alpha.expect("alpha"),
        r.expected_depth.expect("expected depth"),
    ))
}

/// Run detection (or verify it on disk).
pub fn run(ctx: &StageCtx, gens: &Generators) -> Result<Views> {
    let StageCtx {
        config,
        inputs,
        dir,
        on_event,
    } = *ctx;
    let key = serde_json::json!({
        "scene": inputs.scene_sha256,
        "candidates": inputs.candidates_sha256,
        "slots": gens.key(config, &[SlotKind::Inpaint, SlotKind::Depth]),
        "coverage_alpha": config.coverage_alpha,
        "inpaintings": config.inpaintings,
        "align_space": config.align_space,
        "independent_detection": config.independent_detection,

    });
    let step = dir.step("views", key, on_event, |w| {
        let mut records = Vec::new();
        let mut active: Vec<usize> = Vec::new();
        let mut masks: Vec<Vec<bool>> = Vec::new();
        let mut ranges: Vec<[f64; 2]> = Vec::new();
        let mut covered = Vec::new();
        let mut set_aside = Vec::new();
        for (ci, cam) in inputs.candidates.iter().enumerate() {
            let s = stem(&cam.name);
            let (wd, ht) = (cam.width as usize, cam.height as usize);
            // A candidate at a training view's pose has nothing to extrapolate; a second
            // candidate with the same camera would only collide with the first.
            let same_training = inputs
                .data
                .train
                .iter()
                .map(|&t| &inputs.data.views[t].camera)
                .find(|t| same_pose(t, cam));
            let same_candidate = inputs.candidates[..ci]
                .iter()
                .find(|p| {
                    same_pose(p, cam)
                        && (p.width, p.height, p.fx, p.fy, p.cx, p.cy)
                            == (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy)
                });
            let repeat = match (same_training, same_candidate) {
                (Some(t), _) => Some(format!(
                    "has the pose of training view '{}': nothing to extrapolate there",
                    t.name
                )),
                (None, Some(p)) => Some(format!("is the same camera as candidate '{}'", p.name)),
                (None, None) => None,
            };
            if let Some(reason) = repeat {
                set_aside.push(SetAside {
                    name: cam.name.clone(),
                    reason,
                });
                records.push(Candidate {
                    name: cam.name.clone(),
                    masked: 0,
                    nearest_training: None,
                    space: None,
                    alignments: Vec::new(),
                    ranges: Vec::new(),
                    range: None,
                });
                continue;
            }
            let (rgb, alpha, ed) = render_rgba(&inputs.scene, cam, inputs.background)?;
            let mask: Vec<bool> = alpha.iter().map(|&a| a < config.coverage_alpha).collect();
            save_image(w, &format!("{s}/render"), &rgb)?;
            save_mask(w, &format!("{s}/inpaint"), &mask, wd, ht)?;
            let masked = mask.iter().filter(|&&m| m).count();
            let mut rec = Candidate {
                name: cam.name.clone(),
                masked,
                nearest_training: None,
                space: None,
                alignments: Vec::new(),
                ranges: Vec::new(),
                range: None,
            };
            if masked == 0 {
                covered.push(cam.name.clone());
                records.push(rec);
                continue;
            }
            let aside = |rec: Candidate, reason: String, set_aside: &mut Vec<SetAside>| {
                set_aside.push(SetAside {
                    name: rec.name.clone(),
                    reason,
                });
                Candidate {
                    nearest_training: None,
                    space: None,
                    alignments: Vec::new(),
                    ranges: Vec::new(),
                    range: None,
                    ..rec
                }
            };
            if masked == wd * ht
                && let Some(slot) = gens.inpaint_needs_known()
            {
                records.push(aside(
                    rec,
                    format!(
                        "sees nothing of the scene (alpha < {} at every pixel) and the inpaint slot '{slot}' fills only from known pixels",
                        config.coverage_alpha
                    ),
                    &mut set_aside,
                ));
                continue;
            }
            // Eq. 2's target: the depth of the closest training view (by pose distance)
            // that shares at least MIN_ALIGN_PIXELS with the candidate, warped here; where
            // it leaves a hole, the scene's own expected depth where the scene is opaque.
            let need = MIN_ALIGN_PIXELS.max(wd * ht / 100);
            let mut found = None;
            for p in nearest_training(&inputs.data, cam, inputs.data.train.len()) {
                let pcam = &inputs.data.views[p].camera;
                let mut warped = warp_depth(&training_depth(inputs, p)?, pcam, cam)?;
                for (k, d) in warped.iter_mut().enumerate() {
                    if *d <= 0.0 && alpha[k] >= 0.5 {
                        *d = ed[k];
                    }
                }
                if warped.iter().filter(|&&d| d > 0.0).count() >= need {
                    found = Some((pcam, warped));
                    break;
                }
            }
            // Without any reference (the candidate shares no surface with the training
            // views or the scene), a metric estimate is used as it is (identity alignment)
            // and a disparity estimate sets the candidate aside.
            let (reference, warped) = match found {
                Some((pcam, w)) => (Some(pcam.name.clone()), w),
                None => (None, vec![0f32; wd * ht]),
            };
            if reference.is_none()
                && let Some(slot) = gens.depth_needs_known()
            {
                records.push(aside(
                    rec,
                    format!(
                        "no training view shares {need} pixels of known depth with it, nor does the scene cover them, and the depth slot '{slot}' only extends known depth"
                    ),
                    &mut set_aside,
                ));
                continue;
            }
            rec.nearest_training = reference.clone();
            // Eq. 4 over `n` inpaintings only when they can differ: a deterministic slot
            // would give `n` equal ranges (SPEC.md §20.2).
            let n = if gens.inpaintings_differ() {
                config.inpaintings as usize
            } else {
                1
            };
            let mut why = None;
            for j in 0..n {
                let ip = gens.inpaint(cam, &rgb, &mask, &format!("views:{}:{j}", cam.name))?;
                let hint = DepthHint {
                    depth: &warped,
                    mask: None,
                };
                let est = gens.depth(cam, &ip, hint)?;
                let space = config.align_space.unwrap_or(est.kind.space());
                let a = match &reference {
                    Some(r) => match least_squares(
                        &[Frame {
                            estimate: &est.values,
                            depth: &warped,
                        }],
                        space,
                    ) {
                        Ok(a) => a,
                        Err(e) => {
                            why = Some(format!(
                                "its depth cannot be aligned to training view '{r}' ({})",
                                e.message
                            ));
                            break;
                        }
                    },
                    None if space == Space::Depth => Alignment::identity(0),
                    None => {
                        why = Some(format!(
                            "no training view shares {need} pixels of known depth with it, nor does the scene cover them, so its {space:?} estimate cannot be aligned (is the view behind or outside the scene?)"
                        ));
                        break;
                    }
                };
                let d = apply_alignment(&est, &a, space);
                let range = match depth_range(&d, &mask) {
                    Ok(r) => r,
                    Err(e) => {
                        why = Some(format!(
                            "inpainting {j}: {} after alignment, so it has no frustum",
                            e.message
                        ));
                        break;
                    }
                };
                save_image(w, &format!("{s}/inpaint_{j}"), &ip)?;
                save_depth(w, &format!("{s}/inpaint_{j}"), &d, wd, ht)?;
                rec.space = Some(space);
                rec.alignments.push([a.scale, a.offset]);
                rec.ranges.push(range);
            }
            if let Some(reason) = why {
                records.push(aside(rec, reason, &mut set_aside));
                continue;
            }
            let range = mean_range(&rec.ranges)?;
            rec.range = Some(range);
            masks.push(mask);
            ranges.push(range);
            active.push(ci);
            records.push(rec);
        }
        if active.is_empty() {
            let mut why = format!(
                "nothing to extrapolate: of {} candidate views the scene covers {}",
                inputs.candidates.len(),
                covered.len()
            );
            for a in &set_aside {
                why += &format!("; '{}' is set aside: {}", a.name, a.reason);
            }
            return Err(Error::invalid(why));
        }
        let name = |i: usize| inputs.candidates[i].name.clone();
        let cams: Vec<&Camera> = active.iter().map(|&i| &inputs.candidates[i]).collect();
        let (polys, sel) = select_regions(&cams, &masks, &ranges, Outline::BoundingBox, None)?;
        let centers: Vec<DVec3> = cams.iter().map(|c| c.center).collect();
        let (independent, tour) = if config.independent_detection {
            (sel.independent.clone(), sel.trajectory.clone())
        } else {
            let (k, m) = (sel.independent.len(), active.len());
            let even: Vec<usize> = (0..k).map(|j| j * m / k).collect();
            let (t, _) = closed_tour(&even, &centers);
            (even, t)
        };
        let (dependent, gap_cams) = assign_dependents(&active, &independent, &tour, &centers, |i| {
            &inputs.candidates[active[i]]
        })?;
        let mut trajectory = Vec::new();
        for &t in &tour {
            trajectory.push(name(active[t]));
            let mut here: Vec<&Dependent> = dependent
                .iter()
                .filter(|d| d.between[0] == name(active[t]))
                .collect();
            here.sort_by(|a, b| a.t.total_cmp(&b.t));
            trajectory.extend(here.iter().map(|d| d.name.clone()));
        }
        let plan = Plan {
            candidates: records,
            covered,
            set_aside,
            collisions: sel
                .edges
                .iter()
                .map(|&(i, j)| [name(active[i]), name(active[j])])
                .collect(),
            detection: config.independent_detection,
            independent: independent.iter().map(|&i| name(active[i])).collect(),
            tour: tour.iter().map(|&i| name(active[i])).collect(),
            dependent,
            trajectory,
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
    w: &mut crate::pipeline::rundir::StepWriter,
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
                    ssim_sum: 0.0,
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

/// Dependent views by gap, and the cameras made for empty gaps. Indices are into
/// `active` (the candidates with something to inpaint).
fn assign_dependents<'c>(
    active: &[usize],
    independent: &[usize],
    tour: &[usize],
    centers: &[DVec3],
    cam: impl Fn(usize) -> &'c Camera,
) -> Result<(Vec<Dependent>, Vec<GapCamera>)> {
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
    let mut gap_cams = Vec::new();
    for (g, &(a, b)) in gaps.iter().enumerate() {
        if used[g] || a == b {
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
    Ok((dependent, gap_cams))
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
