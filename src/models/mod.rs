//! Model slots (SPEC.md §19): the generative and estimation models the pipeline calls, as
//! traits, each with a deterministic classical default so the pipeline runs with no
//! weights, and a generic ONNX adapter ([`onnx`], the only module importing tract) for
//! real models.
//!
//! | slot | trait | defaults | ONNX |
//! |---|---|---|---|
//! | inpainting | [`Inpainter`] | `telea` | `onnx:CARD.json` |
//! | depth | [`DepthEstimator`] | `depth-fill` | `onnx:CARD.json` |
//! | video depth | [`VideoDepthEstimator`] | `depth-fill` per frame | `onnx:CARD.json` per frame |
//! | video | [`VideoGenerator`] | `morph` | — |
//! | artifact removal | [`ArtifactFixer`] | `identity`, `bilateral` | `onnx:CARD.json` |
//!
//! Images are [`ImageF32`] in `[0, 1]` (any channel count unless a slot says otherwise);
//! masks are row-major `bool`, true = to be generated.

pub mod classical;
pub mod morph;
#[cfg(feature = "onnx")]
pub mod onnx;
pub mod telea;

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::io::image::ImageF32;
use std::path::Path;

/// What a depth map holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DepthKind {
    /// Camera depth (metric or relative): larger is farther.
    Depth,
    /// Inverse depth up to scale and shift: larger is nearer (Depth Anything).
    Disparity,
}

impl DepthKind {
    /// The alignment space that makes this map linear in the target (SPEC.md §17).
    pub fn space(self) -> crate::warp::align::Space {
        match self {
            DepthKind::Depth => crate::warp::align::Space::Depth,
            DepthKind::Disparity => crate::warp::align::Space::Disparity,
        }
    }
}

/// An estimated depth map.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthMap {
    pub width: usize,
    pub height: usize,
    pub kind: DepthKind,
    pub values: Vec<f32>,
}

/// Known depth that an estimator may use (the warped metric depth of the paper's step 2):
/// values ≤ 0 or not finite are unknown, as are the pixels under `mask`.
#[derive(Clone, Copy, Debug)]
pub struct DepthHint<'a> {
    pub depth: &'a [f32],
    pub mask: Option<&'a [bool]>,
}

/// Image + mask → image with the masked region generated.
pub trait Inpainter: Send + Sync {
    fn name(&self) -> &str;
    /// What identifies this model's behaviour in a cache key: its name, and for learned
    /// models the hashes of their files.
    fn fingerprint(&self) -> String {
        self.name().to_string()
    }
    fn inpaint(&self, image: &ImageF32, mask: &[bool]) -> Result<ImageF32>;
    /// Inpaint with a seed (a diffusion model's noise); deterministic models ignore it.
    fn inpaint_seeded(&self, image: &ImageF32, mask: &[bool], seed: u64) -> Result<ImageF32> {
        let _ = seed;
        self.inpaint(image, mask)
    }
    /// Whether different seeds can give different inpaintings (the `n` of paper Eq. 4 is
    /// worth computing only then).
    fn stochastic(&self) -> bool {
        false
    }
    /// Whether the model fills only from known pixels (a classical inpainter cannot fill an
    /// image of which nothing is known; a generative model can).
    fn needs_known_pixels(&self) -> bool {
        false
    }
}

/// Image → relative depth or disparity. `hint` is what the caller knows; learned models
/// ignore it, the classical default needs it.
pub trait DepthEstimator: Send + Sync {
    fn name(&self) -> &str;
    /// What identifies this model's behaviour in a cache key: its name, and for learned
    /// models the hashes of their files.
    fn fingerprint(&self) -> String {
        self.name().to_string()
    }
    fn estimate(&self, image: &ImageF32, hint: Option<DepthHint>) -> Result<DepthMap>;
    /// Whether the model only extends the hint's known depth (it cannot estimate depth
    /// where the hint knows none; a learned model can).
    fn needs_known_depth(&self) -> bool {
        false
    }
}

/// Frames → per-frame relative depth (one scale for the clip when the model is
/// consistent; the pipeline aligns all frames with one RANSAC, §17).
pub trait VideoDepthEstimator: Send + Sync {
    fn name(&self) -> &str;
    /// What identifies this model's behaviour in a cache key: its name, and for learned
    /// models the hashes of their files.
    fn fingerprint(&self) -> String {
        self.name().to_string()
    }
    fn estimate(&self, frames: &[ImageF32], hints: Option<&[DepthHint]>) -> Result<Vec<DepthMap>>;
}

/// One end of a generated clip.
#[derive(Clone, Copy, Debug)]
pub struct Keyframe<'a> {
    pub image: &'a ImageF32,
    pub camera: &'a Camera,
    /// Camera-z depth of `image`, when known.
    pub depth: Option<&'a [f32]>,
}

/// A generated clip: `frames[0]` and `frames[n − 1]` are the given end frames.
#[derive(Clone, Debug, PartialEq)]
pub struct Video {
    pub frames: Vec<ImageF32>,
    pub cameras: Vec<Camera>,
    /// Per-frame camera-z depth, when the generator knows it.
    pub depths: Option<Vec<Vec<f32>>>,
    /// Per-frame pixels the generator invented (no end frame saw them), when it knows.
    pub invented: Option<Vec<Vec<bool>>>,
}

/// Start and end frames (with cameras and depths when known) → `n` frames.
pub trait VideoGenerator: Send + Sync {
    fn name(&self) -> &str;
    /// What identifies this model's behaviour in a cache key: its name, and for learned
    /// models the hashes of their files.
    fn fingerprint(&self) -> String {
        self.name().to_string()
    }
    fn generate(&self, start: Keyframe, end: Keyframe, n: usize) -> Result<Video>;
}

/// A render (and optionally a reference view) → the render with artifacts removed.
pub trait ArtifactFixer: Send + Sync {
    fn name(&self) -> &str;
    /// What identifies this model's behaviour in a cache key: its name, and for learned
    /// models the hashes of their files.
    fn fingerprint(&self) -> String {
        self.name().to_string()
    }
    fn fix(&self, render: &ImageF32, reference: Option<&ImageF32>) -> Result<ImageF32>;
}

/// `onnx:CARD.json` → the card path.
fn onnx_card(name: &str) -> Option<&Path> {
    name.strip_prefix("onnx:").map(Path::new)
}

/// The error of an `onnx:` slot in a build without the `onnx` feature.
#[cfg(not(feature = "onnx"))]
fn without_onnx(card: &Path) -> Error {
    Error::invalid(
        "this build has no ONNX support (the Python binding and builds without the `onnx` \
         feature); run the model with the `unseen` command line",
    )
    .at(card)
}

/// A classical default of a slot: its name and how to make it.
type Classical<'a, T> = (&'a str, fn() -> Box<T>);

/// The model called `name` for `slot`: an `onnx:CARD.json` card, loaded by `onnx`, or one
/// of the `classical` defaults by name; any other name is an error listing the known ones.
fn pick<T: ?Sized>(
    slot: &str,
    name: &str,
    classical: &[Classical<T>],
    onnx: impl FnOnce(&Path) -> Result<Box<T>>,
) -> Result<Box<T>> {
    if let Some(card) = onnx_card(name) {
        return onnx(card);
    }
    match classical.iter().find(|(n, _)| *n == name) {
        Some((_, make)) => Ok(make()),
        None => {
            let known: Vec<&str> = classical.iter().map(|(n, _)| *n).collect();
            Err(Error::invalid(format!(
                "unknown {slot} '{name}' (known: {}, or onnx:CARD.json)",
                known.join(", ")
            )))
        }
    }
}

/// The loader of an ONNX model type `$ty` (a `$slot`) for [`pick`]: a clear error in a build without
/// the `onnx` feature (where `$ty` does not exist: the cfg removes it before it is named).
macro_rules! onnx_model {
    ($slot:ty, $ty:path) => {{
        #[cfg(feature = "onnx")]
        let load = |card: &Path| -> Result<Box<$slot>> { Ok(Box::new(<$ty>::load(card)?)) };
        #[cfg(not(feature = "onnx"))]
        let load = |card: &Path| -> Result<Box<$slot>> { Err(without_onnx(card)) };
        load
    }};
}

/// The inpainter called `name`: `telea` (radius 3) or `onnx:CARD.json`.
pub fn inpainter(name: &str) -> Result<Box<dyn Inpainter>> {
    let telea: fn() -> Box<dyn Inpainter> = || Box::new(classical::Telea::default());
    pick(
        "inpainter",
        name,
        &[("telea", telea)],
        onnx_model!(dyn Inpainter, onnx::OnnxInpainter),
    )
}

/// The depth estimator called `name`: `depth-fill` or `onnx:CARD.json`.
pub fn depth_estimator(name: &str) -> Result<Box<dyn DepthEstimator>> {
    let fill: fn() -> Box<dyn DepthEstimator> = || Box::new(classical::DepthFill::default());
    pick(
        "depth estimator",
        name,
        &[("depth-fill", fill)],
        onnx_model!(dyn DepthEstimator, onnx::OnnxDepth),
    )
}

/// The video depth estimator called `name`: `depth-fill` (per frame, needs hints) or
/// `onnx:CARD.json` (an image model run per frame).
pub fn video_depth_estimator(name: &str) -> Result<Box<dyn VideoDepthEstimator>> {
    let fill: fn() -> Box<dyn VideoDepthEstimator> = || Box::new(classical::DepthFill::default());
    pick(
        "video depth estimator",
        name,
        &[("depth-fill", fill)],
        onnx_model!(dyn VideoDepthEstimator, onnx::OnnxDepth),
    )
}

/// The artifact fixer called `name`: `identity`, `bilateral` or `onnx:CARD.json`.
pub fn artifact_fixer(name: &str) -> Result<Box<dyn ArtifactFixer>> {
    let identity: fn() -> Box<dyn ArtifactFixer> = || Box::new(classical::Identity);
    let bilateral: fn() -> Box<dyn ArtifactFixer> = || Box::new(classical::Bilateral::default());
    pick(
        "artifact fixer",
        name,
        &[("identity", identity), ("bilateral", bilateral)],
        onnx_model!(dyn ArtifactFixer, onnx::OnnxFixer),
    )
}

/// The video generator called `name`: `morph`.
pub fn video_generator(name: &str) -> Result<Box<dyn VideoGenerator>> {
    match name {
        "morph" => Ok(Box::new(morph::Morph::default())),
        _ => Err(Error::invalid(format!(
            "unknown video generator '{name}' (known: morph)"
        ))),
    }
}
