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

mod choice;
pub mod classical;
pub mod morph;
#[cfg(feature = "onnx")]
pub mod onnx;
pub mod telea;

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::io::image::ImageF32;
pub use choice::{
    Defaults, DepthDefault, DepthModel, FixerDefault, FixerModel, InpaintDefault, InpaintModel,
    Model, VideoDefault, VideoDepthDefault, VideoDepthModel, VideoModel,
};

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

/// The error of an ONNX model in a build without the `onnx` feature.
#[cfg(not(feature = "onnx"))]
fn without_onnx(card: &std::path::Path) -> Error {
    Error::invalid(
        "this build has no ONNX support (the Python binding and builds without the `onnx` \
         feature); run the model with the `unseen` command line",
    )
    .at(card)
}

/// The ONNX model type `$ty` (a `$slot`) loaded from `$card`, or in a build without the
/// `onnx` feature a clear error (where `$ty` does not exist: the cfg removes it before it
/// is named).
macro_rules! load_onnx {
    ($slot:ty, $ty:path, $card:expr) => {{
        #[cfg(feature = "onnx")]
        let model: Result<Box<$slot>> = Ok(Box::new(<$ty>::load($card)?));
        #[cfg(not(feature = "onnx"))]
        let model: Result<Box<$slot>> = Err(without_onnx($card));
        model
    }};
}

/// The inpainter `m`: Telea (radius 3) or an ONNX model.
pub fn inpainter(m: &InpaintModel) -> Result<Box<dyn Inpainter>> {
    match m {
        Model::Classical(InpaintDefault::Telea) => Ok(Box::new(classical::Telea::default())),
        Model::Onnx(card) => load_onnx!(dyn Inpainter, onnx::OnnxInpainter, card),
    }
}

/// The depth estimator `m`: depth fill or an ONNX model.
pub fn depth_estimator(m: &DepthModel) -> Result<Box<dyn DepthEstimator>> {
    match m {
        Model::Classical(DepthDefault::DepthFill) => Ok(Box::new(classical::DepthFill::default())),
        Model::Onnx(card) => load_onnx!(dyn DepthEstimator, onnx::OnnxDepth, card),
    }
}

/// The video depth estimator `m`: depth fill per frame (needs hints) or an ONNX image
/// model run per frame.
pub fn video_depth_estimator(m: &VideoDepthModel) -> Result<Box<dyn VideoDepthEstimator>> {
    match m {
        Model::Classical(VideoDepthDefault::DepthFill) => {
            Ok(Box::new(classical::DepthFill::default()))
        }
        Model::Onnx(card) => load_onnx!(dyn VideoDepthEstimator, onnx::OnnxDepth, card),
    }
}

/// The artifact fixer `m`: identity, bilateral or an ONNX model.
pub fn artifact_fixer(m: &FixerModel) -> Result<Box<dyn ArtifactFixer>> {
    match m {
        Model::Classical(FixerDefault::Identity) => Ok(Box::new(classical::Identity)),
        Model::Classical(FixerDefault::Bilateral) => Ok(Box::new(classical::Bilateral::default())),
        Model::Onnx(card) => load_onnx!(dyn ArtifactFixer, onnx::OnnxFixer, card),
    }
}

/// The video generator `m`: the morph (the slot takes no ONNX model; parsing refuses one).
pub fn video_generator(m: &VideoModel) -> Result<Box<dyn VideoGenerator>> {
    match m {
        Model::Classical(VideoDefault::Morph) => Ok(Box::new(morph::Morph::default())),
        Model::Onnx(card) => Err(Error::invalid("the video slot takes no ONNX model").at(card)),
    }
}
