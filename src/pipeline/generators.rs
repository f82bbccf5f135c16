//! Slot wiring (SPEC.md §20.6): the pipeline asks for inpaintings, depths, videos, video
//! depths and fixed renders *at a camera*, and each slot answers either with a model of
//! [`crate::models`] (classical default or ONNX card) or with the labelled **ground-truth
//! generator**.
//!
//! The ground-truth generator is an upper bound and the instrument of the audit, never a
//! default: it holds the truth of the *candidate* views only (the evaluation poses never
//! reach it) and of the trajectory cameras interpolated between two candidates (the `morph`
//! of their truths); any other pose is an error. Its outputs can be degraded by a seeded
//! [`Inconsistency`] — colour gain and offset, blur, sub-pixel misalignment, hallucinated
//! patches — the controlled variable of the paper's mechanism claims. Two labelled modes
//! make it behave like the models the paper uses (SPEC.md §20.6): relative depth
//! ([`RelativeMap`]: disparity up to a seeded affine map, so alignment has work) and
//! hallucination (content no training view saw differs per call, so independent
//! generations conflict).

use super::config::{
    Hallucination, Inconsistency, PipelineConfig, Slot, SlotNames, TRUTH, TruthDepth,
};
use super::inputs::Inputs;
use super::poses::same_pose;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::io::image::ImageF32;
use crate::math::fastexp::exp;
use crate::models::morph::Morph;
use crate::models::{
    self, ArtifactFixer, DepthEstimator, DepthHint, DepthKind, DepthMap, Inpainter, Keyframe,
    Video, VideoDepthEstimator, VideoGenerator,
};
use crate::rng::Uniform;
use crate::rng::stage_seed;
use std::collections::BTreeMap;

/// Truth at one pose: image and camera-z depth.
#[derive(Clone, Debug)]
pub struct Truth {
    pub camera: Camera,
    pub image: ImageF32,
    pub depth: Vec<f32>,
}

/// The ground-truth generator's store.
#[derive(Clone, Debug)]
pub struct GroundTruth {
    poses: BTreeMap<String, Truth>,
    inconsistency: Inconsistency,
    seed: u64,
    depth: TruthDepth,
    hallucination: Hallucination,
    /// The training views' cameras and depths (what was seen), when hallucinating.
    seen: Vec<(Camera, Vec<f32>)>,
}

impl GroundTruth {
    /// The truth of the candidate views (nothing else may be given).
    pub fn new(candidates: Vec<Truth>, inconsistency: Inconsistency, seed: u64) -> Self {
        GroundTruth {
            poses: candidates
                .into_iter()
                .map(|t| (t.camera.name.clone(), t))
                .collect(),
            inconsistency,
            seed,
            depth: TruthDepth::Metric,
            hallucination: Hallucination::None,
            seen: Vec::new(),
        }
    }

    /// The same store hallucinating at `level`; `seen`: the training views' cameras and
    /// depths (a pixel whose surface point none of them sees is unseen).
    pub fn hallucinating(self, level: Hallucination, seen: Vec<(Camera, Vec<f32>)>) -> Self {
        GroundTruth {
            hallucination: level,
            seen,
            ..self
        }
    }

    /// Whether this store hallucinates unseen content.
    pub fn hallucinates(&self) -> bool {
        self.hallucination != Hallucination::None && !self.seen.is_empty()
    }

    /// The pixels of `cam` (truth depth `depth`) that no training view saw.
    pub fn unseen(&self, cam: &Camera, depth: &[f32]) -> Vec<bool> {
        let train: Vec<(&Camera, &[f32])> =
            self.seen.iter().map(|(c, d)| (c, d.as_slice())).collect();
        super::evaluate::existing_pixels(cam, depth, &train)
            .into_iter()
            .map(|e| !e)
            .collect()
    }

    /// Replace the colour of `pixels` of `img` (seen from `cam`, truth depth `depth`) by
    /// this call's hallucinated content (stream `truth-hallucination:<key>`), mixed with
    /// what is there by the level's weight.
    pub fn hallucinate(
        &self,
        cam: &Camera,
        depth: &[f32],
        pixels: &[bool],
        img: &mut ImageF32,
        key: &str,
    ) {
        if self.hallucination == Hallucination::None {
            return;
        }
        let points: Vec<(usize, glam::DVec3)> = pixels
            .iter()
            .enumerate()
            .filter(|&(p, &m)| m && depth[p].is_finite() && depth[p] > 0.0)
            .map(|(p, _)| (p, world_point(cam, p, depth[p])))
            .collect();
        if points.is_empty() {
            return;
        }
        let seed = stage_seed(self.seed, &format!("truth-hallucination:{key}"));
        let content = Content::draw(seed, self.hallucination, cam, &points);
        let m = self.hallucination.mix();
        let c = img.channels;
        for &(p, x) in &points {
            let h = content.colour_at(x);
            for (ch, v) in img.data[p * c..(p + 1) * c].iter_mut().enumerate() {
                *v = (1.0 - m) * *v + m * h[ch.min(2)];
            }
        }
    }

    /// The same store answering depth in `mode`.
    pub fn with_depth(self, mode: TruthDepth) -> Self {
        GroundTruth {
            depth: mode,
            ..self
        }
    }

    /// The relative-depth map of the call `key` on metric depth `frames`.
    pub fn relative_map(&self, key: &str, frames: &[&[f32]]) -> RelativeMap {
        let seed = stage_seed(self.seed, &format!("truth-depth:{key}"));
        let first = frames.first().copied().unwrap_or(&[]);
        RelativeMap::draw(&self.inconsistency, seed, frames.len(), first)
    }

    /// Metric depth `frames` as the depth slots return them: unchanged (metric mode), or as
    /// disparity through the seeded [`RelativeMap`] of `key` (one map for all the frames).
    pub fn answer_depth(&self, frames: &[&[f32]], key: &str) -> (DepthKind, Vec<Vec<f32>>) {
        match self.depth {
            TruthDepth::Metric => (
                DepthKind::Depth,
                frames.iter().map(|f| f.to_vec()).collect(),
            ),
            TruthDepth::Relative => {
                let map = self.relative_map(key, frames);
                let maps = frames
                    .iter()
                    .enumerate()
                    .map(|(k, f)| map.apply(k, f))
                    .collect();
                (DepthKind::Disparity, maps)
            }
        }
    }

    /// Add the truth of `cam` (between candidates `a` and `b`, at the middle of the
    /// trajectory gap): the middle frame of the `morph` of their truths.
    pub fn add_between(&mut self, cam: &Camera, a: &str, b: &str) -> Result<()> {
        let v = self.morph(a, b, 3)?;
        let depth = v.depths.expect("morph gives depths").swap_remove(1);
        let t = Truth {
            camera: cam.clone(),
            image: v.frames[1].clone(),
            depth,
        };
        self.poses.insert(cam.name.clone(), t);
        Ok(())
    }

    /// Whether [`Self::add_between`] can make the truth of a camera half-way between
    /// candidates `a` and `b`: false when the morph cannot be made (the middle camera sees
    /// neither end's surface), where the pipeline makes no camera for the gap.
    pub fn can_make_between(&self, a: &str, b: &str) -> Result<bool> {
        match self.morph(a, b, 3) {
            Ok(_) => Ok(true),
            Err(e) if crate::models::morph::cannot_make_clip(&e) => Ok(false),
            Err(e) => Err(e),
        }
    }

    /// The `n` frames of the `morph` from the truth at `a` to the truth at `b` (both ends
    /// included), with their depths.
    fn morph(&self, a: &str, b: &str, n: usize) -> Result<Video> {
        fn key(t: &Truth) -> Keyframe<'_> {
            Keyframe {
                image: &t.image,
                camera: &t.camera,
                depth: Some(&t.depth),
            }
        }
        Morph::default().generate(key(self.get(a)?), key(self.get(b)?), n)
    }

    pub fn get(&self, name: &str) -> Result<&Truth> {
        self.poses.get(name).ok_or_else(|| {
            Error::invalid(format!(
                "the ground-truth generator has no truth at '{name}' (only candidate poses and the trajectory cameras between them)"
            ))
        })
    }

    /// `img` degraded by the inconsistency, seeded by `key`.
    pub fn degrade(&self, img: &ImageF32, key: &str) -> ImageF32 {
        degrade(
            img,
            &self.inconsistency,
            stage_seed(self.seed, &format!("truth:{key}")),
        )
    }
}

/// Apply `inc` to `img` (channels 1 or 3), deterministically from `seed`: shift
/// (bilinear, clamped to the border), blur (separable Gaussian, radius ⌈3σ⌉, clamped),
/// gain and offset per channel, then the patches; values clamped to `[0, 1]`.
pub fn degrade(img: &ImageF32, inc: &Inconsistency, seed: u64) -> ImageF32 {
    if inc.is_none() {
        return img.clone();
    }
    let mut u = Uniform::new(seed);
    let (w, h, c) = (img.width, img.height, img.channels);
    let mut data = img.data.clone();
    if inc.shift_px > 0.0 {
        // A direction without platform trigonometry: a point drawn in the square, rejected
        // outside the unit disc (or too near its centre), normalized.
        let (ux, uy) = loop {
            let (x, y) = (u.range(-1.0, 1.0), u.range(-1.0, 1.0));
            let r2 = x * x + y * y;
            if r2 <= 1.0 && r2 > 1e-4 {
                let inv = 1.0 / r2.sqrt();
                break (x * inv, y * inv);
            }
        };
        let (dx, dy) = (inc.shift_px * ux, inc.shift_px * uy);
        let src = data.clone();
        let at = |x: isize, y: isize, ch: usize| {
            let xx = x.clamp(0, w as isize - 1) as usize;
            let yy = y.clamp(0, h as isize - 1) as usize;
            src[(yy * w + xx) * c + ch]
        };
        for y in 0..h {
            for x in 0..w {
                let (sx, sy) = (x as f32 + dx, y as f32 + dy);
                let (x0, y0) = (sx.floor(), sy.floor());
                let (fx, fy) = (sx - x0, sy - y0);
                let (x0, y0) = (x0 as isize, y0 as isize);
                for ch in 0..c {
                    let top = at(x0, y0, ch) * (1.0 - fx) + at(x0 + 1, y0, ch) * fx;
                    let bot = at(x0, y0 + 1, ch) * (1.0 - fx) + at(x0 + 1, y0 + 1, ch) * fx;
                    data[(y * w + x) * c + ch] = top * (1.0 - fy) + bot * fy;
                }
            }
        }
    }
    if inc.blur_sigma_px > 0.0 {
        let s = inc.blur_sigma_px;
        let r = (3.0 * s).ceil() as isize;
        let k: Vec<f32> = (-r..=r)
            .map(|i| exp(-((i * i) as f32) / (2.0 * s * s)))
            .collect();
        let sum: f32 = k.iter().sum();
        let k: Vec<f32> = k.iter().map(|v| v / sum).collect();
        for horizontal in [true, false] {
            let src = data.clone();
            for y in 0..h as isize {
                for x in 0..w as isize {
                    for ch in 0..c {
                        let mut acc = 0f32;
                        for (t, &kv) in k.iter().enumerate() {
                            let o = t as isize - r;
                            let (xx, yy) = if horizontal {
                                ((x + o).clamp(0, w as isize - 1), y)
                            } else {
                                (x, (y + o).clamp(0, h as isize - 1))
                            };
                            acc += kv * src[(yy as usize * w + xx as usize) * c + ch];
                        }
                        data[(y as usize * w + x as usize) * c + ch] = acc;
                    }
                }
            }
        }
    }
    let gains: Vec<f32> = (0..c).map(|_| 1.0 + u.range(-inc.gain, inc.gain)).collect();
    let offsets: Vec<f32> = (0..c).map(|_| u.range(-inc.offset, inc.offset)).collect();
    for px in data.chunks_exact_mut(c) {
        for ch in 0..c {
            px[ch] = px[ch] * gains[ch] + offsets[ch];
        }
    }
    let side = ((w.min(h) as f32 * inc.patch_size).round() as usize).max(1);
    for _ in 0..inc.patches {
        let x0 = u.below((w.saturating_sub(side) + 1) as u32) as usize;
        let y0 = u.below((h.saturating_sub(side) + 1) as u32) as usize;
        let colour: Vec<f32> = (0..c).map(|_| u.unit()).collect();
        for y in y0..(y0 + side).min(h) {
            for x in x0..(x0 + side).min(w) {
                data[(y * w + x) * c..(y * w + x + 1) * c].copy_from_slice(&colour);
            }
        }
    }
    for v in &mut data {
        *v = v.clamp(0.0, 1.0);
    }
    ImageF32 {
        width: w,
        height: h,
        channels: c,
        data,
    }
}

/// The relative-depth mode's map of one call (SPEC.md §20.6): metric depth `d` becomes
/// `R_k = a_k · D̄ · g(D/D̄) + b_k` for frame `k`, with `D = 1/d` (0 where `d` is unknown),
/// `D̄` the mean disparity of frame 0's known pixels, `g(x) = x + κ·x(x − 1)/(x + 1)`
/// (monotone: slope ≥ 1 − |κ|; the identity at κ = 0), `a_k = a·(1 + ε_k)` and
/// `b_k = b + a·D̄·δ_k`. No transcendental function, so the bits are the same on every
/// platform.
#[derive(Clone, Debug, PartialEq)]
pub struct RelativeMap {
    /// `a`: drawn as `1 + 4u` or `1/(1 + 4u)` with equal odds (in `[0.2, 5]`).
    pub scale: f64,
    /// `b = a·D̄·β`, `β` drawn from `[−0.2, 0.5]`.
    pub shift: f64,
    /// `D̄`.
    pub mean_disparity: f64,
    /// `κ`, drawn from `± depth_distortion`.
    pub kappa: f64,
    /// `(ε_k, δ_k)` per frame, drawn from `± depth_flicker`.
    pub flicker: Vec<(f64, f64)>,
}

impl RelativeMap {
    /// The map for `frames` frames whose first has metric depth `first` (its `D̄`).
    pub fn draw(inc: &Inconsistency, seed: u64, frames: usize, first: &[f32]) -> RelativeMap {
        let mut u = Uniform::new(seed);
        let up = u.unit_f64() < 0.5;
        let m = 1.0 + 4.0 * u.unit_f64();
        let scale = if up { m } else { 1.0 / m };
        let beta = -0.2 + 0.7 * u.unit_f64();
        let (mut sum, mut n) = (0f64, 0usize);
        for &d in first {
            if d.is_finite() && d > 0.0 {
                sum += 1.0 / d as f64;
                n += 1;
            }
        }
        let mean_disparity = if n > 0 { sum / n as f64 } else { 1.0 };
        let sym = |u: &mut Uniform, r: f32| (2.0 * u.unit_f64() - 1.0) * r as f64;
        let kappa = sym(&mut u, inc.depth_distortion);
        let flicker = (0..frames)
            .map(|_| {
                let e = sym(&mut u, inc.depth_flicker);
                (e, sym(&mut u, inc.depth_flicker))
            })
            .collect();
        RelativeMap {
            scale,
            shift: scale * mean_disparity * beta,
            mean_disparity,
            kappa,
            flicker,
        }
    }

    /// Frame `k`'s relative map of metric depth `depth`.
    pub fn apply(&self, k: usize, depth: &[f32]) -> Vec<f32> {
        let (e, dl) = self.flicker[k];
        let a = self.scale * (1.0 + e);
        let b = self.shift + self.scale * self.mean_disparity * dl;
        depth
            .iter()
            .map(|&d| {
                let x = if d.is_finite() && d > 0.0 {
                    1.0 / d as f64 / self.mean_disparity
                } else {
                    0.0
                };
                let g = x + self.kappa * x * (x - 1.0) / (x + 1.0);
                (a * self.mean_disparity * g + b) as f32
            })
            .collect()
    }
}

/// The world point of pixel `p` of `cam` at camera depth `z` (pixel centre).
fn world_point(cam: &Camera, p: usize, z: f32) -> glam::DVec3 {
    let w = cam.width as usize;
    let (x, y, z) = ((p % w) as f64 + 0.5, (p / w) as f64 + 0.5, z as f64);
    let pc = glam::DVec3::new((x - cam.cx) / cam.fx * z, (y - cam.cy) / cam.fy * z, z);
    cam.world_from_camera_rotation * pc + cam.center
}

/// One call's hallucinated content, a function of the world point (so one call's clip or
/// image is consistent with itself): stripes of two seeded colours along a seeded
/// direction (frequency 1–4 cycles per metre, seeded phase), and painted spheres placed
/// at seeded unseen points of the call's view, of radius 4–12 % of their distance to the
/// camera and a seeded colour. No transcendental function.
struct Content {
    colours: [[f32; 3]; 2],
    direction: glam::DVec3,
    frequency: f64,
    phase: f64,
    objects: Vec<(glam::DVec3, f64, [f32; 3])>,
}

impl Content {
    fn draw(
        seed: u64,
        level: Hallucination,
        cam: &Camera,
        points: &[(usize, glam::DVec3)],
    ) -> Content {
        let mut u = Uniform::new(seed);
        let colour = |u: &mut Uniform| [u.unit(), u.unit(), u.unit()];
        let colours = [colour(&mut u), colour(&mut u)];
        let direction = loop {
            let v = glam::DVec3::new(
                2.0 * u.unit_f64() - 1.0,
                2.0 * u.unit_f64() - 1.0,
                2.0 * u.unit_f64() - 1.0,
            );
            let l2 = v.length_squared();
            if l2 <= 1.0 && l2 > 1e-4 {
                break v / l2.sqrt();
            }
        };
        let frequency = 1.0 + 3.0 * u.unit_f64();
        let phase = u.unit_f64();
        let objects = (0..level.objects())
            .map(|_| {
                let (_, c) = points[u.below(points.len() as u32) as usize];
                let r = (0.04 + 0.08 * u.unit_f64()) * (c - cam.center).length();
                (c, r, colour(&mut u))
            })
            .collect();
        Content {
            colours,
            direction,
            frequency,
            phase,
            objects,
        }
    }

    fn colour_at(&self, x: glam::DVec3) -> [f32; 3] {
        for &(c, r, col) in &self.objects {
            if (x - c).length_squared() <= r * r {
                return col;
            }
        }
        let t = self.frequency * self.direction.dot(x) + self.phase;
        self.colours[usize::from(t - t.floor() >= 0.5)]
    }
}

/// One of the five slots, as a step's key names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlotKind {
    Inpaint,
    Depth,
    Video,
    VideoDepth,
    Fixer,
}

impl SlotKind {
    pub const ALL: [SlotKind; 5] = [
        SlotKind::Inpaint,
        SlotKind::Depth,
        SlotKind::Video,
        SlotKind::VideoDepth,
        SlotKind::Fixer,
    ];

    /// The slot's name in a step's key (and in the configuration).
    pub fn name(self) -> &'static str {
        match self {
            SlotKind::Inpaint => "inpaint",
            SlotKind::Depth => "depth",
            SlotKind::Video => "video",
            SlotKind::VideoDepth => "video_depth",
            SlotKind::Fixer => "fixer",
        }
    }
}

/// The five slots of the pipeline.
pub struct Generators {
    inpaint: Slot<Box<dyn Inpainter>>,
    depth: Slot<Box<dyn DepthEstimator>>,
    video: Slot<Box<dyn VideoGenerator>>,
    video_depth: Slot<Box<dyn VideoDepthEstimator>>,
    fixer: Slot<Box<dyn ArtifactFixer>>,
    pub truth: Option<GroundTruth>,
    /// The run's seed (inpainting seeds are drawn from it by key).
    seed: u64,
}

impl Generators {
    /// Build the slots; `truth` must be given when any slot is the ground-truth generator.
    pub fn new(names: &SlotNames, truth: Option<GroundTruth>, seed: u64) -> Result<Generators> {
        if names.uses_truth() && truth.is_none() {
            return Err(Error::invalid(
                "the ground-truth generator needs a dataset with the candidate views' images and depths",
            ));
        }
        names.validate()?;
        Ok(Generators {
            inpaint: names.inpaint.try_map(models::inpainter)?,
            depth: names.depth.try_map(models::depth_estimator)?,
            video: names.video.try_map(models::video_generator)?,
            video_depth: names.video_depth.try_map(models::video_depth_estimator)?,
            fixer: names.fixer.try_map(models::artifact_fixer)?,
            truth,
            seed,
        })
    }

    /// What identifies the behaviour of slot `kind`: its model's fingerprint (a learned
    /// model's card and weight hashes), or `truth`.
    fn fingerprint(&self, kind: SlotKind) -> String {
        fn of<T: ?Sized>(s: &Slot<Box<T>>, f: impl Fn(&T) -> String) -> String {
            match s {
                Slot::Model(m) => f(m),
                Slot::Truth => TRUTH.into(),
            }
        }
        match kind {
            SlotKind::Inpaint => of(&self.inpaint, |m| m.fingerprint()),
            SlotKind::Depth => of(&self.depth, |m| m.fingerprint()),
            SlotKind::Video => of(&self.video, |m| m.fingerprint()),
            SlotKind::VideoDepth => of(&self.video_depth, |m| m.fingerprint()),
            SlotKind::Fixer => of(&self.fixer, |m| m.fingerprint()),
        }
    }

    /// Whether slot `kind` is the ground-truth generator.
    pub(crate) fn is_truth(&self, kind: SlotKind) -> bool {
        match kind {
            SlotKind::Inpaint => self.inpaint.is_truth(),
            SlotKind::Depth => self.depth.is_truth(),
            SlotKind::Video => self.video.is_truth(),
            SlotKind::VideoDepth => self.video_depth.is_truth(),
            SlotKind::Fixer => self.fixer.is_truth(),
        }
    }

    /// The part of a step's key that names the slots it calls: each slot's fingerprint
    /// and, when one is the ground-truth generator, its inconsistency and seed. Variants
    /// that differ only in slots a step does not call share that step.
    pub fn key(&self, config: &PipelineConfig, used: &[SlotKind]) -> serde_json::Value {
        let mut m = serde_json::Map::new();
        for &u in used {
            m.insert(u.name().into(), self.fingerprint(u).into());
        }
        if used.iter().any(|&u| self.is_truth(u)) {
            m.insert(
                "truth".into(),
                serde_json::json!({
                    "inconsistency": config.inconsistency,
                    "seed": config.seed,
                    "depth": config.truth_depth,
                    "hallucination": config.hallucination,
                }),
            );
        }
        serde_json::Value::Object(m)
    }

    /// Whether inpaintings with different keys can differ (a stochastic model, or the
    /// ground-truth generator with an inconsistency).
    pub fn inpaintings_differ(&self) -> bool {
        match &self.inpaint {
            Slot::Model(m) => m.stochastic(),
            Slot::Truth => !self.gt().inconsistency.is_none(),
        }
    }

    fn gt(&self) -> &GroundTruth {
        self.truth.as_ref().expect("checked in new")
    }

    /// The inpaint slot's model when it fills only from known pixels (Telea): its name.
    pub fn inpaint_needs_known(&self) -> Option<&str> {
        match &self.inpaint {
            Slot::Model(m) if m.needs_known_pixels() => Some(m.name()),
            _ => None,
        }
    }

    /// The depth slot's model when it only extends known depth (depth-fill): its name.
    pub fn depth_needs_known(&self) -> Option<&str> {
        match &self.depth {
            Slot::Model(m) if m.needs_known_depth() => Some(m.name()),
            _ => None,
        }
    }

    /// Inpaint `mask` of `image` seen from `cam`; `key` names this inpainting (its seed).
    pub fn inpaint(
        &self,
        cam: &Camera,
        image: &ImageF32,
        mask: &[bool],
        key: &str,
    ) -> Result<ImageF32> {
        let named =
            |e: Error| Error::invalid(format!("view '{}': inpainting: {}", cam.name, e.message));
        let out = match &self.inpaint {
            Slot::Model(m) => m
                .inpaint_seeded(image, mask, stage_seed(self.seed, key))
                .map_err(named)?,
            Slot::Truth => {
                let gt = self.gt();
                let t = gt.get(&cam.name)?;
                let mut g = gt.degrade(&t.image, key);
                if gt.hallucinates() {
                    let unseen: Vec<bool> = gt
                        .unseen(cam, &t.depth)
                        .iter()
                        .zip(mask)
                        .map(|(&u, &m)| u && m)
                        .collect();
                    gt.hallucinate(cam, &t.depth, &unseen, &mut g, key);
                }
                let mut out = image.clone();
                for (p, &m) in mask.iter().enumerate() {
                    if m {
                        let c = out.channels;
                        out.data[p * c..(p + 1) * c].copy_from_slice(&g.data[p * c..(p + 1) * c]);
                    }
                }
                out
            }
        };
        check_image(&out, image, "inpainting", &cam.name)?;
        Ok(out)
    }

    /// Depth of `image` at `cam` (`hint`: the known metric depth).
    pub fn depth(&self, cam: &Camera, image: &ImageF32, hint: DepthHint) -> Result<DepthMap> {
        let d = match &self.depth {
            Slot::Model(m) => m.estimate(image, Some(hint)).map_err(|e| {
                Error::invalid(format!("view '{}': depth: {}", cam.name, e.message))
            })?,
            Slot::Truth => {
                // One map per image: a model's scale and shift follow its input, so two
                // inpaintings of one view get two maps.
                let key = image_key(cam, image);
                let (kind, mut maps) = self
                    .gt()
                    .answer_depth(&[&self.gt().get(&cam.name)?.depth], &key);
                DepthMap {
                    width: image.width,
                    height: image.height,
                    kind,
                    values: maps.swap_remove(0),
                }
            }
        };
        check_depth(&d, image, &cam.name)?;
        Ok(d)
    }

    /// A clip of `n` frames from `start` to `end`.
    pub fn video(&self, start: Keyframe, end: Keyframe, n: usize) -> Result<Video> {
        let (a, b) = (start.image, end.image);
        if (a.width, a.height, a.channels) != (b.width, b.height, b.channels) {
            return Err(Error::degenerate(format!(
                "{}: '{}' is {}x{}, '{}' {}x{}",
                crate::models::morph::END_SIZES_DIFFER,
                start.camera.name,
                a.width,
                a.height,
                end.camera.name,
                b.width,
                b.height
            )));
        }
        let v = match &self.video {
            Slot::Model(m) => m.generate(start, end, n)?,
            Slot::Truth => {
                // Start: a training view or a trajectory keyframe; its truth is its image
                // when it is a training view, the stored truth otherwise.
                let gt = self.gt();
                // Hallucinating: the clip follows its keyframes' content (a video model
                // conditioned on them), so an inpainted keyframe's hallucination carries
                // into the clip; the geometry is still the truth's.
                let key = |k: &Keyframe| -> Result<(ImageF32, Vec<f32>)> {
                    match gt.get(&k.camera.name) {
                        Ok(t) if gt.hallucinates() => Ok((k.image.clone(), t.depth.clone())),
                        Ok(t) => Ok((t.image.clone(), t.depth.clone())),
                        Err(e) => match k.depth {
                            Some(d) => Ok((k.image.clone(), d.to_vec())),
                            None => Err(e),
                        },
                    }
                };
                let (ia, da) = key(&start)?;
                let (ib, db) = key(&end)?;
                let mut v = Morph::default().generate(
                    Keyframe {
                        image: &ia,
                        camera: start.camera,
                        depth: Some(&da),
                    },
                    Keyframe {
                        image: &ib,
                        camera: end.camera,
                        depth: Some(&db),
                    },
                    n,
                )?;
                let last = v.frames.len() - 1;
                for (k, f) in v.frames.iter_mut().enumerate() {
                    if k == 0 {
                        *f = start.image.clone();
                    } else if k == last {
                        *f = end.image.clone();
                    } else {
                        *f = gt.degrade(f, &v.cameras[k].name);
                    }
                }
                v
            }
        };
        if v.frames.len() != n || v.cameras.len() != n {
            return Err(Error::invalid(format!(
                "the video slot returned {} frames for {n}",
                v.frames.len()
            )));
        }
        for f in &v.frames {
            check_image(f, start.image, "video frame", &start.camera.name)?;
        }
        Ok(v)
    }

    /// Per-frame depth of a clip (`hints`: the known metric depth of each frame).
    pub fn video_depth(&self, video: &Video, hints: &[DepthHint]) -> Result<Vec<DepthMap>> {
        let maps = match &self.video_depth {
            Slot::Model(m) => m.estimate(&video.frames, Some(hints))?,
            Slot::Truth => {
                let depths = video.depths.as_ref().ok_or_else(|| {
                    Error::invalid("the truth video has no depths (video slot is not 'truth')")
                })?;
                // One map per clip (its end cameras name it), jittered per frame.
                let key = clip_key(video);
                let frames: Vec<&[f32]> = depths.iter().map(Vec::as_slice).collect();
                let (kind, maps) = self.gt().answer_depth(&frames, &key);
                maps.into_iter()
                    .zip(&video.frames)
                    .map(|(values, f)| DepthMap {
                        width: f.width,
                        height: f.height,
                        kind,
                        values,
                    })
                    .collect()
            }
        };
        if maps.len() != video.frames.len() {
            return Err(Error::invalid(format!(
                "the video depth slot returned {} maps for {} frames",
                maps.len(),
                video.frames.len()
            )));
        }
        for (m, f) in maps.iter().zip(&video.frames) {
            check_depth(m, f, "video frame")?;
        }
        Ok(maps)
    }

    /// The fixer's output for a render at `cam`; `truth_between`: the two trajectory
    /// keyframes the pose lies between and its frame `k` of `n` (for the truth slot).
    pub fn fix(
        &self,
        cam: &Camera,
        render: &ImageF32,
        between: Option<(&Camera, &Camera, usize, usize)>,
    ) -> Result<ImageF32> {
        let out = match &self.fixer {
            Slot::Model(m) => m.fix(render, None).map_err(|e| {
                Error::invalid(format!("view '{}': fixer: {}", cam.name, e.message))
            })?,
            Slot::Truth => {
                let gt = self.gt();
                let (img, depth) = match gt.get(&cam.name) {
                    Ok(t) => (t.image.clone(), t.depth.clone()),
                    Err(e) => {
                        let Some((a, b, k, n)) = between else {
                            return Err(e);
                        };
                        let v = gt.morph(&a.name, &b.name, n)?;
                        let d = v.depths.as_ref().map_or_else(Vec::new, |d| d[k].clone());
                        (v.frames[k].clone(), d)
                    }
                };
                let mut out = gt.degrade(&img, &format!("fix:{}", cam.name));
                if gt.hallucinates() && depth.len() == (cam.width * cam.height) as usize {
                    // A fixer cannot know content no training view saw: there it keeps
                    // the render (no truth leaks into hallucinated regions).
                    let c = out.channels;
                    for (p, u) in gt.unseen(cam, &depth).into_iter().enumerate() {
                        if u {
                            out.data[p * c..(p + 1) * c]
                                .copy_from_slice(&render.data[p * c..(p + 1) * c]);
                        }
                    }
                }
                out
            }
        };
        check_image(&out, render, "fixer output", &cam.name)?;
        Ok(out)
    }
}

/// A slot's image must have the input's size and finite values.
fn check_image(out: &ImageF32, like: &ImageF32, what: &str, view: &str) -> Result<()> {
    if (out.width, out.height, out.channels) != (like.width, like.height, like.channels) {
        return Err(Error::invalid(format!(
            "view '{view}': the {what} is {}x{}x{} but {}x{}x{} was expected",
            out.width, out.height, out.channels, like.width, like.height, like.channels
        )));
    }
    if out.data.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid(format!(
            "view '{view}': the {what} holds NaN or infinite values"
        )));
    }
    Ok(())
}

fn check_depth(d: &DepthMap, like: &ImageF32, view: &str) -> Result<()> {
    if (d.width, d.height) != (like.width, like.height) || d.values.len() != d.width * d.height {
        return Err(Error::invalid(format!(
            "view '{view}': the depth slot returned a {}x{} map for a {}x{} image",
            d.width, d.height, like.width, like.height
        )));
    }
    Ok(())
}

/// The relative-depth key of a single-image depth call: the view and the image's content,
/// so two inpaintings of one view get two maps (a model's scale follows its input).
pub fn image_key(cam: &Camera, image: &ImageF32) -> String {
    let bytes: Vec<u8> = image.data.iter().flat_map(|v| v.to_le_bytes()).collect();
    format!("{}:{}", cam.name, crate::io::sha256_hex(&bytes))
}

/// The relative-depth key of a clip: its end cameras.
pub fn clip_key(video: &Video) -> String {
    match (video.cameras.first(), video.cameras.last()) {
        (Some(a), Some(b)) => format!("clip:{}->{}", a.name, b.name),
        _ => "clip".to_string(),
    }
}

/// The truth of the candidate views, from the dataset (for the ground-truth generator).
pub fn candidate_truth(inputs: &Inputs) -> Result<Vec<Truth>> {
    inputs
        .candidates
        .iter()
        .map(|c| {
            let v = inputs
                .data
                .views
                .iter()
                .find(|v| v.camera.name == c.name)
                .ok_or_else(|| {
                    Error::invalid(format!(
                        "the ground-truth generator needs candidate '{}' in the dataset",
                        c.name
                    ))
                })?;
            if (v.camera.width, v.camera.height) != (c.width, c.height) || !same_pose(&v.camera, c) {
                return Err(Error::invalid(format!(
                    "candidate '{}' differs in size or pose from the dataset's view of that name: the ground-truth generator cannot use its truth",
                    c.name
                ))
                .at(&inputs.data.root));
            }
            let depth = v.depth.clone().ok_or_else(|| {
                Error::invalid(format!(
                    "the ground-truth generator needs the depth of candidate '{}'",
                    c.name
                ))
                .at(&inputs.data.root.join("depth").join(format!("{}.exr", c.name)))
            })?;
            Ok(Truth {
                camera: c.clone(),
                image: v.image.clone(),
                depth,
            })
        })
        .collect()
}

/// The training views' cameras and depths, from which the hallucinating ground-truth
/// generator tells seen content from unseen (empty when it does not hallucinate).
pub fn training_truth(inputs: &Inputs, config: &PipelineConfig) -> Result<Vec<(Camera, Vec<f32>)>> {
    if config.hallucination == Hallucination::None {
        return Ok(Vec::new());
    }
    inputs
        .data
        .train
        .iter()
        .map(|&i| {
            let v = &inputs.data.views[i];
            let d = v.depth.clone().ok_or_else(|| {
                Error::invalid(format!(
                    "the hallucinating ground-truth generator needs the depth of training view '{}' (to tell what the training views saw)",
                    v.camera.name
                ))
                .at(&inputs.data.root)
            })?;
            Ok((v.camera.clone(), d))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A step's key names each slot as the configuration's field of that slot does.
    #[test]
    fn slot_kinds_are_named_as_the_configuration_fields() {
        let fields = serde_json::to_value(SlotNames::default()).unwrap();
        let fields: Vec<&String> = fields.as_object().unwrap().keys().collect();
        let mut kinds: Vec<&str> = SlotKind::ALL.iter().map(|k| k.name()).collect();
        kinds.sort_unstable();
        assert_eq!(fields, kinds, "(the object's keys come sorted)");
    }
}
