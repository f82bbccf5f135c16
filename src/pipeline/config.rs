//! Everything that decides an extrapolation run, in one serializable struct (SPEC.md §20.1).
//! Each ablation of the paper is one independent switch.

use super::selection::SelectionRule;
use crate::collide::frustum::Outline;
use crate::error::{Error, Result};
use crate::models::{
    DepthDefault, DepthModel, FixerDefault, FixerModel, InpaintDefault, InpaintModel, Model,
    VideoDefault, VideoDepthDefault, VideoDepthModel, VideoModel,
};
use crate::train::densify::DensifyConfig;
use crate::train::loss::LossWeights;
use crate::warp::align::Space;
use std::fmt;
use std::str::FromStr;

/// Where the per-pixel weights of the generated supervision come from (paper Eq. 7).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskSource {
    /// The QA-Mask of the scene being updated (the paper).
    Qa,
    /// `1 − alpha` of the scene being updated (the baseline of paper Table 3).
    Opacity,
    /// All ones (ablation "w/o QA-Mask").
    None,
}

crate::error::text_enum!(MaskSource, "mask source", { Qa => "qa", Opacity => "opacity", None => "none" });

/// What fills one slot: a model, or the labelled ground-truth generator. In a configuration
/// (`M` a model's name, [`crate::models::Model`]) it is written as the model's name
/// (`telea`, `onnx:CARD.json`, …) or `truth`, parsed once where the configuration is read;
/// the running pipeline holds the models themselves in it (`M` a boxed slot trait).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Slot<M> {
    Model(M),
    /// The ground-truth generator (an upper bound, SPEC.md §20.6).
    Truth,
}

/// A slot's `truth` in a configuration.
pub(super) const TRUTH: &str = "truth";

impl<M> Slot<M> {
    pub fn is_truth(&self) -> bool {
        matches!(self, Slot::Truth)
    }

    /// The model `f` makes of this slot's model; the truth stays the truth.
    pub fn try_map<N>(&self, f: impl FnOnce(&M) -> Result<N>) -> Result<Slot<N>> {
        Ok(match self {
            Slot::Model(m) => Slot::Model(f(m)?),
            Slot::Truth => Slot::Truth,
        })
    }
}

impl<M: FromStr<Err = Error>> FromStr for Slot<M> {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        if s == TRUTH {
            Ok(Slot::Truth)
        } else {
            s.parse().map(Slot::Model)
        }
    }
}

impl<M: fmt::Display> fmt::Display for Slot<M> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Slot::Model(m) => m.fmt(f),
            Slot::Truth => f.write_str(TRUTH),
        }
    }
}

impl<M: fmt::Display> serde::Serialize for Slot<M> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de, M: FromStr<Err = Error>> serde::Deserialize<'de> for Slot<M> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        from_text(d)
    }
}

/// A value written in a configuration as its text (a slot, a preset): the string, parsed
/// by `T`'s `FromStr`, its error the parse error's message.
fn from_text<'de, D: serde::Deserializer<'de>, T: FromStr<Err = Error>>(
    d: D,
) -> std::result::Result<T, D::Error> {
    let text = <String as serde::Deserialize>::deserialize(d)?;
    text.parse()
        .map_err(|e: Error| serde::de::Error::custom(e.message))
}

/// Which generators fill the slots.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SlotNames {
    /// `telea`, `onnx:CARD.json`, or `truth` (the labelled ground-truth generator).
    pub inpaint: Slot<InpaintModel>,
    /// `depth-fill`, `onnx:CARD.json` or `truth`.
    pub depth: Slot<DepthModel>,
    /// `morph` or `truth` (morph between stored truths).
    pub video: Slot<VideoModel>,
    /// `depth-fill`, `onnx:CARD.json` or `truth` (the truth video's own depths).
    pub video_depth: Slot<VideoDepthModel>,
    /// `identity`, `bilateral`, `onnx:CARD.json` or `truth`.
    pub fixer: Slot<FixerModel>,
}

impl Default for SlotNames {
    fn default() -> Self {
        SlotNames {
            inpaint: Slot::Model(Model::Classical(InpaintDefault::Telea)),
            depth: Slot::Model(Model::Classical(DepthDefault::DepthFill)),
            video: Slot::Model(Model::Classical(VideoDefault::Morph)),
            video_depth: Slot::Model(Model::Classical(VideoDepthDefault::DepthFill)),
            fixer: Slot::Model(Model::Classical(FixerDefault::Identity)),
        }
    }
}

impl SlotNames {
    /// Every slot from the ground-truth generator.
    pub fn truth() -> Self {
        SlotNames {
            inpaint: Slot::Truth,
            depth: Slot::Truth,
            video: Slot::Truth,
            video_depth: Slot::Truth,
            fixer: Slot::Truth,
        }
    }

    /// The rule between slots: `video_depth: truth` is the truth video's own depth, so it
    /// needs `video: truth`.
    pub fn validate(&self) -> Result<()> {
        if self.video_depth.is_truth() && !self.video.is_truth() {
            return Err(Error::invalid(
                "video_depth 'truth' is the truth video's own depth: it needs video 'truth'",
            ));
        }
        Ok(())
    }

    /// True when any slot is the ground-truth generator.
    pub fn uses_truth(&self) -> bool {
        self.inpaint.is_truth()
            || self.depth.is_truth()
            || self.video.is_truth()
            || self.video_depth.is_truth()
            || self.fixer.is_truth()
    }
}

/// The ground-truth generator's controlled inconsistency (SPEC.md §20.6).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Inconsistency {
    /// Per-view colour gain drawn from `1 ± gain` per channel.
    pub gain: f32,
    /// Per-view colour offset drawn from `± offset` per channel.
    pub offset: f32,
    /// Gaussian blur standard deviation in pixels (0 = none).
    pub blur_sigma_px: f32,
    /// Misalignment: the image is resampled at a shift of this length (pixels) in a
    /// per-view random direction.
    pub shift_px: f32,
    /// Hallucinated patches per image: squares of a random flat colour.
    pub patches: u32,
    /// Side of a patch as a fraction of the image's shorter side.
    pub patch_size: f32,
    /// Relative-depth mode ([`TruthDepth::Relative`]): per-frame jitter of a clip's map,
    /// the scale drawn from `1 ± depth_flicker` and the shift from `± depth_flicker · D̄`.
    pub depth_flicker: f32,
    /// Relative-depth mode: the largest `|κ|` of the monotone distortion
    /// `g(x) = x + κ·x(x − 1)/(x + 1)` of the disparity `x = D/D̄` (slope ≥ 1 − |κ|).
    pub depth_distortion: f32,
}

/// The ground-truth generator's hallucination of content no training view saw (SPEC.md
/// §20.6): **a labelled mode, not a model**. Generated content in such pixels differs from
/// call to call (seeded per call) and is consistent within one call's output, so two
/// overlapping independent generations conflict as diffusion outputs do.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Hallucination {
    /// The truth (default).
    #[default]
    None,
    /// Half the truth, half a seeded world-space texture; one painted object.
    Low,
    /// The seeded texture alone; three painted objects.
    High,
    /// A level between, as a whole percentage `p` of the texture (a dose–response sweep,
    /// SPEC.md §21.6): mix `p/100`, `max(0, ⌊4p/100⌋ − 1)` painted objects, so that 50 and
    /// 100 would be `Low` and `High` ([`Hallucination::from_percent`] makes them so).
    Percent(u8),
}

impl Hallucination {
    /// The level of `p` percent (at most 100): `None`, `Low` and `High` at 0, 50 and 100.
    pub fn from_percent(p: u8) -> Hallucination {
        match p.min(100) {
            0 => Hallucination::None,
            50 => Hallucination::Low,
            100 => Hallucination::High,
            p => Hallucination::Percent(p),
        }
    }

    fn percent(self) -> u8 {
        match self {
            Hallucination::None => 0,
            Hallucination::Low => 50,
            Hallucination::High => 100,
            Hallucination::Percent(p) => p,
        }
    }

    /// Weight of the hallucinated colour against the truth.
    pub fn mix(self) -> f32 {
        f32::from(self.percent()) / 100.0
    }

    /// Painted objects (spheres in world space) per call.
    pub fn objects(self) -> usize {
        (4 * usize::from(self.percent()) / 100).saturating_sub(1)
    }
}

/// `x` in [0, `max` / 100] as a whole percentage, if it is one (to 1e-9): a swept level.
pub fn whole_percent(x: f64, max: u8) -> Option<u8> {
    let p = (x * 100.0).round();
    ((0.0..=f64::from(max)).contains(&p) && (x * 100.0 - p).abs() < 1e-9).then_some(p as u8)
}

/// In a configuration: `"none"`, `"low"`, `"high"`, or a level in [0, 1] as a number
/// (whole percentages).
impl serde::Serialize for Hallucination {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            Hallucination::None => s.serialize_str("none"),
            Hallucination::Low => s.serialize_str("low"),
            Hallucination::High => s.serialize_str("high"),
            Hallucination::Percent(p) => s.serialize_f64(f64::from(*p) / 100.0),
        }
    }
}

impl<'de> serde::Deserialize<'de> for Hallucination {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        use serde::de::Error as _;
        #[derive(serde::Deserialize)]
        #[serde(untagged)]
        enum Form {
            Name(String),
            Level(f64),
        }
        match Form::deserialize(d)? {
            Form::Name(n) => match n.as_str() {
                "none" => Ok(Hallucination::None),
                "low" => Ok(Hallucination::Low),
                "high" => Ok(Hallucination::High),
                _ => Err(D::Error::custom(format!(
                    "unknown hallucination '{n}' (none, low, high, or a level in [0, 1])"
                ))),
            },
            Form::Level(x) => whole_percent(x, 100)
                .map(Hallucination::from_percent)
                .ok_or_else(|| {
                    D::Error::custom(format!(
                        "hallucination level {x} is not in [0, 1] with at most two decimals"
                    ))
                }),
        }
    }
}

/// What the ground-truth generator's depth slots return (SPEC.md §20.6).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TruthDepth {
    /// The candidate's metric camera-z depth: alignment (Eq. 2, 5, stage 2) has nothing to
    /// recover.
    #[default]
    Metric,
    /// **Labelled mode, not a model**: what a monocular or video depth model returns —
    /// disparity up to a seeded affine map (one per image; one per clip, with per-frame
    /// flicker), mildly and monotonically distorted, at the inconsistency level's
    /// `depth_flicker` / `depth_distortion`.
    Relative,
}

crate::error::text_enum!(TruthDepth, "truth depth", { Metric => "metric", Relative => "relative" });

/// How stage 2 obtains the depth of an inpainted dependent view (SPEC.md §20.4).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage2Depth {
    /// The paper's DIBR-based video depth alignment ("throughout the process", §3.3): a
    /// clip from the nearest training view to the inpainted dependent view, its video
    /// depth aligned by one RANSAC over all frames against the training view's depth
    /// DIBR-warped to every frame (Eq. 5), the last frame's aligned depth (Eq. 6).
    #[default]
    Video,
    /// **Not in the paper** (the method before numerics revision 6, kept for the
    /// ablation): the depth slot's estimate of the inpainted image, least-squares fitted to
    /// the stage-1 scene's expected depth where its alpha exceeds 0.5.
    RenderFit,
}

/// Where a reconstruction's position learning rate starts (SPEC.md §20.5; issue #72: the
/// paper does not say).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FineTuneRates {
    /// At INRIA's initial rate, its schedule over the fine-tune's own iterations, as a
    /// new training would (the released training code's behaviour when handed a scene).
    #[default]
    Restart,
    /// Where the scene's schedule stopped: after the original training's iterations and
    /// each earlier reconstruction's.
    Continue,
}

impl FineTuneRates {
    fn is_restart(&self) -> bool {
        *self == FineTuneRates::Restart
    }
}

/// Which Gaussians a reconstruction's densification and pruning may touch (SPEC.md §20.5;
/// issue #72: the paper does not say).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DensifyScope {
    /// Every Gaussian, as a training does.
    #[default]
    All,
    /// Only those the pipeline added (the original scene's Gaussians, first in every scene
    /// the pipeline makes under this scope, are left to the gradient step).
    Added,
}

impl DensifyScope {
    fn is_all(&self) -> bool {
        *self == DensifyScope::All
    }
}

/// How the pipeline extrapolates (SPEC.md §20.11).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Paradigm {
    /// The paper's hierarchical two-stage pipeline (§3.3): independent views, stage 1,
    /// dependent views, stage 2, interpolation.
    #[default]
    Hierarchical,
    /// **Not the paper's method**: the generate–reconstruct–shift cycle the paper replaces
    /// (§1) — the trajectory's views one after another, each inpainted from the current
    /// scene's render and reconstructed before the next ([`super::cycle`]).
    Cycle,
}

crate::error::text_enum!(Paradigm, "paradigm", { Hierarchical => "hierarchical", Cycle => "cycle" });

impl Paradigm {
    /// The default: left out of a written configuration, so adding the field changed no
    /// existing `config.json` or configuration digest.
    pub fn is_hierarchical(&self) -> bool {
        *self == Paradigm::Hierarchical
    }
}

/// A level of the ground-truth generator's labelled deviations from the truth: its
/// inconsistency ([`Inconsistency::at`]) and its hallucination ([`Hallucination::at`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    None,
    Low,
    High,
}

crate::error::text_enum!(Level, "level", { None => "none", Low => "low", High => "high" });

impl Hallucination {
    /// The hallucination of a level.
    pub fn at(level: Level) -> Hallucination {
        match level {
            Level::None => Hallucination::None,
            Level::Low => Hallucination::Low,
            Level::High => Hallucination::High,
        }
    }
}

impl Default for Inconsistency {
    fn default() -> Self {
        Inconsistency::NONE
    }
}

impl Inconsistency {
    pub const NONE: Inconsistency = Inconsistency {
        gain: 0.0,
        offset: 0.0,
        blur_sigma_px: 0.0,
        shift_px: 0.0,
        patches: 0,
        patch_size: 0.0,
        depth_flicker: 0.0,
        depth_distortion: 0.0,
    };
    pub const LOW: Inconsistency = Inconsistency {
        gain: 0.03,
        offset: 0.01,
        blur_sigma_px: 0.5,
        shift_px: 0.25,
        patches: 0,
        patch_size: 0.0,
        depth_flicker: 0.01,
        depth_distortion: 0.05,
    };
    pub const HIGH: Inconsistency = Inconsistency {
        gain: 0.10,
        offset: 0.03,
        blur_sigma_px: 1.0,
        shift_px: 1.0,
        patches: 2,
        patch_size: 0.1,
        depth_flicker: 0.03,
        depth_distortion: 0.15,
    };

    /// The deviations of a level.
    pub fn at(level: Level) -> Inconsistency {
        match level {
            Level::None => Self::NONE,
            Level::Low => Self::LOW,
            Level::High => Self::HIGH,
        }
    }

    /// `none`, `low`, `high`, or `custom`.
    pub fn name(&self) -> &'static str {
        if *self == Self::NONE {
            "none"
        } else if *self == Self::LOW {
            "low"
        } else if *self == Self::HIGH {
            "high"
        } else {
            "custom"
        }
    }

    pub fn is_none(&self) -> bool {
        *self == Self::NONE
    }
}

/// One reconstruction (stage 1, stage 2, interpolation).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReconConfig {
    pub iterations: u32,
    /// Densification during the fine-tune; `None` keeps the Gaussian count.
    pub densify: Option<DensifyConfig>,
}

impl Default for ReconConfig {
    fn default() -> Self {
        ReconConfig {
            iterations: 30_000,
            densify: Some(DensifyConfig::default()),
        }
    }
}

/// A named set of settings: the paper's, or the demo's quick ones.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// Minutes on 2 cores at the bundled rooms' size ([`PipelineConfig::quick`]).
    Quick,
    /// The paper's settings ([`PipelineConfig::paper`]).
    Paper,
}

crate::error::text_enum!(Preset, "preset", { Quick => "quick", Paper => "paper" });

impl serde::Serialize for Preset {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> serde::Deserialize<'de> for Preset {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        from_text(d)
    }
}

/// The whole pipeline.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PipelineConfig {
    /// The preset the fields started from (informative: the fields are what counts).
    pub preset: Preset,
    /// Seed of every random choice; each stage draws from `stage_seed(seed, name)`.
    pub seed: u64,
    /// The paper's hierarchical pipeline (default; not written when default) or the
    /// generate–reconstruct–shift cycle it replaces (comparison baseline).
    #[serde(skip_serializing_if = "Paradigm::is_hierarchical")]
    pub paradigm: Paradigm,
    pub slots: SlotNames,
    /// Degradation of the ground-truth generator (ignored by the other slots).
    pub inconsistency: Inconsistency,
    /// The ground-truth generator's depth: metric (default) or the labelled relative mode.
    pub truth_depth: TruthDepth,
    /// The ground-truth generator's hallucination of unseen content (labelled mode).
    pub hallucination: Hallucination,

    // ---- independent view detection (§3.2)
    /// A candidate pixel is to be inpainted when the scene's alpha there is below this.
    pub coverage_alpha: f32,
    /// Inpaintings per candidate (`n` of Eq. 4).
    pub inpaintings: u32,
    /// Off: the same number of views, evenly spaced along the candidate list (ablation).
    pub independent_detection: bool,
    /// Which independent set detection keeps (the paper leaves it open; SPEC.md §20.2).
    /// The three fields below are written only away from their defaults, so that
    /// configurations written before them keep their bytes and digests.
    #[serde(skip_serializing_if = "SelectionRule::is_default")]
    pub selection: SelectionRule,
    /// The image-plane outline of an inpainted region's frustum: its bounding box (the
    /// paper's) or its convex hull.
    #[serde(skip_serializing_if = "is_bounding_box")]
    pub frustum_outline: Outline,
    /// **An audit comparison, not the paper's method**: stage 1 generates a set of the
    /// independent set's size in which some pair collides and whose coverage, measured as
    /// named, matches the independent set's within
    /// [`super::selection::CONFLICT_COVERAGE_TOLERANCE`] (SPEC.md §20.2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub conflicting_views: Option<super::selection::ConflictMatch>,

    // ---- stage 1 (§3.3.1)
    /// Training views per independent view that start a video (paper: 3).
    pub video_sources: u32,
    /// Frames per generated clip, both end frames included.
    pub video_frames: u32,
    /// Alignment space of estimated depth (Eq. 2, 5; SPEC.md §20.3): `None` = the
    /// estimator's own kind (depth maps in depth, disparity maps in disparity).
    pub align_space: Option<Space>,
    pub ransac_threshold: f64,
    pub ransac_iterations: u32,
    /// Every `k`-th pixel (in x and y) of an inpainted region becomes a new point.
    pub init_stride: u32,
    /// DIBR propagation of inpainted independent views to the dependent views (ablation).
    pub propagation: bool,

    // ---- stage 2 (§3.3.2)
    /// Depth of the inpainted dependent views: video depth alignment (paper) or the
    /// labelled deviation `render_fit` (ablation).
    pub stage2_depth: Stage2Depth,

    // ---- losses (Eq. 7)
    pub mask_source: MaskSource,
    /// λ1, λ2, λ3 of Eq. 7 (the depth weight is used only with `depth_supervision`).
    pub loss: LossWeights,
    /// The depth term of Eq. 7 on the generated views (their aligned depth priors), as the
    /// paper.
    pub depth_supervision: bool,
    /// **Not in the paper** (off by default): with `depth_supervision`, also supervise the
    /// original training views with the dataset's depth. The paper's depth priors come
    /// from the generated views only; on a dataset with ground-truth depth this term
    /// would credit "depth supervision" with data the paper's method never sees.
    pub original_view_depth: bool,
    /// QA-Mask fine-tune (§3.4) of the scene each reconstruction starts from.
    pub qa_sh_degree: u32,
    pub qa_iterations: u32,

    // ---- reconstructions
    pub stage1: ReconConfig,
    pub stage2: ReconConfig,
    /// Interpolation by video reuse and the fixer (§3.3.3); off skips the stage.
    pub interpolation: bool,
    pub interpolate: ReconConfig,
    /// **A choice the paper leaves open** (issue #72): where each reconstruction's position
    /// learning rate starts. Written only away from the default.
    #[serde(skip_serializing_if = "FineTuneRates::is_restart")]
    pub fine_tune_rates: FineTuneRates,
    /// **A choice the paper leaves open** (issue #72): the share of each reconstruction's
    /// iterations on the original training views; `None` (default) draws every view, original
    /// or generated, alike from one stack.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub original_share: Option<f32>,
    /// **A choice the paper leaves open** (issue #72): which Gaussians a reconstruction's
    /// densification and pruning may touch. Written only away from the default.
    #[serde(skip_serializing_if = "DensifyScope::is_all")]
    pub densify_scope: DensifyScope,
    /// **A control, not the paper's method** (issue #72): off, every reconstruction trains
    /// on the original training views alone (the generated views are made and dropped), so
    /// that what the fine-tune recipe does to original areas can be told from what generated
    /// content does. Written only when off.
    #[serde(skip_serializing_if = "is_true")]
    pub generated_supervision: bool,
    /// **A record, not a computation** (issue #72; off by default): every reconstruction
    /// splits its Adam steps between the original and the generated views' gradients and
    /// records the split in its `supervision.json` (SPEC.md §20.5). No bit of any scene
    /// changes; a reconstruction takes ≈ 1.25× as long. Written only when on.
    #[serde(default, skip_serializing_if = "is_false")]
    pub attribution: bool,
    /// The fixer's targets are remade from the scene being trained every this many
    /// iterations of the interpolation (paper: "on the fly"); 0 = once, from the stage-2
    /// scene.
    pub fixer_every: u32,
}

fn is_true(b: &bool) -> bool {
    *b
}

fn is_false(b: &bool) -> bool {
    !*b
}

fn is_bounding_box(o: &Outline) -> bool {
    *o == Outline::BoundingBox
}

impl Default for PipelineConfig {
    fn default() -> Self {
        PipelineConfig::paper()
    }
}

impl PipelineConfig {
    /// The paper's settings (§4 "Implementation details"): 30 000 iterations per stage,
    /// QA-Mask SH 5 with 20 000 iterations, λ = 0.7 / 0.2 / 0.1.
    pub fn paper() -> Self {
        PipelineConfig {
            preset: Preset::Paper,
            seed: 0,
            paradigm: Paradigm::Hierarchical,
            slots: SlotNames::default(),
            inconsistency: Inconsistency::NONE,
            truth_depth: TruthDepth::Metric,
            hallucination: Hallucination::None,
            coverage_alpha: 0.5,
            inpaintings: 3,
            independent_detection: true,
            selection: SelectionRule::Greedy,
            frustum_outline: Outline::BoundingBox,
            conflicting_views: None,
            video_sources: 3,
            video_frames: 16,
            align_space: None,
            ransac_threshold: 0.05,
            ransac_iterations: 1000,
            init_stride: 2,
            propagation: true,
            stage2_depth: Stage2Depth::Video,
            mask_source: MaskSource::Qa,
            loss: LossWeights::PAPER,
            depth_supervision: true,
            original_view_depth: false,
            qa_sh_degree: 5,
            qa_iterations: 20_000,
            stage1: ReconConfig::default(),
            stage2: ReconConfig::default(),
            interpolation: true,
            interpolate: ReconConfig::default(),
            fine_tune_rates: FineTuneRates::Restart,
            original_share: None,
            densify_scope: DensifyScope::All,
            generated_supervision: true,
            attribution: false,
            fixer_every: 3000,
        }
    }

    /// The demo's settings: the whole pipeline on a bundled room in minutes on 2 cores.
    pub fn quick() -> Self {
        let recon = |iterations| ReconConfig {
            iterations,
            densify: Some(DensifyConfig {
                from_iter: 100,
                interval: 100,
                until_iter: iterations.saturating_sub(100),
                opacity_reset_interval: 0,
                ..DensifyConfig::default()
            }),
        };
        PipelineConfig {
            preset: Preset::Quick,
            inpaintings: 1,
            video_frames: 5,
            qa_iterations: 300,
            stage1: recon(600),
            stage2: recon(600),
            interpolate: recon(400),
            fixer_every: 100,
            ..PipelineConfig::paper()
        }
    }

    /// The settings of `preset`.
    pub fn preset(preset: Preset) -> Self {
        match preset {
            Preset::Quick => Self::quick(),
            Preset::Paper => Self::paper(),
        }
    }

    /// The `preset` with `overrides` (a JSON object, possibly partial: its members
    /// replace the preset's, objects merged member by member) applied; `source` names the
    /// overrides in errors (a file, or a caller's argument). Not yet validated: callers
    /// apply their own settings first, then [`PipelineConfig::validate`].
    pub fn with_overrides(
        preset: Preset,
        overrides: serde_json::Value,
        source: &std::path::Path,
    ) -> Result<Self> {
        fn merge(base: &mut serde_json::Value, over: serde_json::Value) {
            match (base, over) {
                (serde_json::Value::Object(b), serde_json::Value::Object(o)) => {
                    for (k, v) in o {
                        merge(b.entry(k).or_insert(serde_json::Value::Null), v);
                    }
                }
                (b, o) => *b = o,
            }
        }
        if !overrides.is_object() {
            return Err(Error::parse(
                source,
                "a pipeline config must be a JSON object",
            ));
        }
        let mut v = serde_json::to_value(Self::preset(preset)).expect("serializes");
        merge(&mut v, overrides);
        serde_json::from_value(v)
            .map_err(|e| Error::parse(source, format!("invalid pipeline config: {e}")))
    }

    pub fn validate(&self) -> Result<()> {
        self.slots.validate()?;
        let bad = |m: String| Err(Error::invalid(m));
        if !(self.coverage_alpha > 0.0 && self.coverage_alpha <= 1.0) {
            return bad(format!(
                "coverage_alpha must be in (0, 1], got {}",
                self.coverage_alpha
            ));
        }
        if self.conflicting_views.is_some() && !self.independent_detection {
            return bad(
                "conflicting_views replaces the independent set: it needs independent_detection"
                    .into(),
            );
        }
        if self.inpaintings == 0 || self.video_sources == 0 {
            return bad("inpaintings and video_sources must be at least 1".into());
        }
        if self.video_frames < 2 {
            return bad(format!(
                "video_frames must be at least 2 (the end frames), got {}",
                self.video_frames
            ));
        }
        if self.init_stride == 0 {
            return bad("init_stride must be at least 1".into());
        }
        if !(self.ransac_threshold > 0.0 && self.ransac_threshold.is_finite()) {
            return bad("ransac_threshold must be positive".into());
        }
        if self.qa_sh_degree == 0 || self.qa_sh_degree > crate::math::sh::MAX_SH_DEGREE {
            return bad(format!(
                "qa_sh_degree must be 1..=5, got {}",
                self.qa_sh_degree
            ));
        }
        for (n, v) in [
            ("l1", self.loss.l1),
            ("l2", self.loss.l2),
            ("dssim", self.loss.dssim),
            ("depth", self.loss.depth),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(format!("loss weight {n} = {v} must be finite and >= 0"));
            }
        }
        if let Some(share) = self.original_share
            && !(share > 0.0 && share < 1.0)
        {
            return bad(format!("original_share must be in (0, 1), got {share}"));
        }
        let i = &self.inconsistency;
        if ![i.gain, i.offset, i.blur_sigma_px, i.shift_px, i.patch_size]
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0)
            || i.patch_size > 1.0
            || i.blur_sigma_px > 8.0
        {
            return bad(
                "inconsistency values must be finite, >= 0, blur <= 8 px, patch_size <= 1".into(),
            );
        }
        Ok(())
    }

    /// Steps into the position schedule at which a reconstruction of a scene trained
    /// `scene_iterations` starts, after `trained_before` iterations of the pipeline's earlier
    /// reconstructions: 0 unless `fine_tune_rates` continues, then their sum.
    pub fn position_offset(&self, scene_iterations: u32, trained_before: u32) -> u32 {
        match self.fine_tune_rates {
            FineTuneRates::Restart => 0,
            FineTuneRates::Continue => scene_iterations.saturating_add(trained_before),
        }
    }

    /// Whether the original training views' dataset depth is supervised (the non-paper
    /// switch, and only with depth supervision on).
    pub fn supervises_original_depth(&self) -> bool {
        self.depth_supervision && self.original_view_depth
    }

    /// The loss of every reconstruction: Eq. 7's weights, the depth term only with depth
    /// supervision.
    pub fn recon_loss(&self) -> LossWeights {
        LossWeights {
            depth: if self.depth_supervision {
                self.loss.depth
            } else {
                0.0
            },
            ..self.loss
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// Slots and presets are written as the same text they were read from: what
    /// `config.json`, step keys and the audit's config digests hash.
    #[test]
    fn slots_and_presets_are_written_as_their_names() {
        let slots = SlotNames {
            inpaint: Slot::Model(Model::Onnx(PathBuf::from("./cards//lama.json"))),
            depth: Slot::Truth,
            video: Slot::Model(Model::Classical(VideoDefault::Morph)),
            video_depth: Slot::Model(Model::Classical(VideoDepthDefault::DepthFill)),
            fixer: Slot::Model(Model::Classical(FixerDefault::Bilateral)),
        };
        let text = serde_json::to_string(&slots).unwrap();
        assert_eq!(
            text,
            r#"{"inpaint":"onnx:./cards//lama.json","depth":"truth","video":"morph","video_depth":"depth-fill","fixer":"bilateral"}"#
        );
        assert_eq!(serde_json::from_str::<SlotNames>(&text).unwrap(), slots);
        assert_eq!(serde_json::to_string(&Preset::Paper).unwrap(), r#""paper""#);
        assert_eq!(
            serde_json::from_str::<Preset>(r#""quick""#).unwrap(),
            Preset::Quick
        );
        let e = serde_json::from_str::<Preset>(r#""custom""#).unwrap_err();
        assert!(
            e.to_string()
                .contains("unknown preset 'custom' (quick, paper)"),
            "{e}"
        );
        let e = serde_json::from_str::<SlotNames>(r#"{"video_depth":"midas"}"#).unwrap_err();
        assert!(
            e.to_string()
                .contains("unknown video depth estimator 'midas'"),
            "{e}"
        );
        // A missing slot is its default.
        let partial: SlotNames = serde_json::from_str(r#"{"fixer":"truth"}"#).unwrap();
        assert_eq!(
            partial,
            SlotNames {
                fixer: Slot::Truth,
                ..SlotNames::default()
            }
        );
        // The rule between slots.
        let e = SlotNames {
            video_depth: Slot::Truth,
            ..SlotNames::default()
        }
        .validate()
        .unwrap_err();
        assert!(e.message.contains("it needs video 'truth'"), "{e}");
    }

    /// The paradigm (SPEC.md §20.11): lower case in a configuration, the default left out
    /// of a written one (no existing `config.json` or digest changed), an unknown value an
    /// error naming the file.
    #[test]
    fn the_paradigm_is_read_lower_case_and_left_out_when_default() {
        let file = std::path::Path::new("over.json");
        let quick = PipelineConfig::quick();
        assert_eq!(quick.paradigm, Paradigm::Hierarchical);
        assert!(!serde_json::to_string(&quick).unwrap().contains("paradigm"));
        let c = PipelineConfig::with_overrides(
            Preset::Quick,
            serde_json::json!({"paradigm": "cycle"}),
            file,
        )
        .unwrap();
        assert_eq!(c.paradigm, Paradigm::Cycle);
        let text = serde_json::to_string(&c).unwrap();
        assert!(text.contains(r#""paradigm":"cycle""#), "{text}");
        assert_eq!(serde_json::from_str::<PipelineConfig>(&text).unwrap(), c);
        let e = PipelineConfig::with_overrides(
            Preset::Quick,
            serde_json::json!({"paradigm": "spiral"}),
            file,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("over.json") && e.contains("spiral"), "{e}");
        assert_eq!("cycle".parse::<Paradigm>().unwrap(), Paradigm::Cycle);
    }

    /// The fine-tune switches and the attribution (issue #72; SPEC.md §20.5): left out of a
    /// written default configuration, read by name, a continued schedule's offset per reconstruction, a
    /// share outside (0, 1) refused.
    #[test]
    fn the_fine_tune_switches_are_left_out_when_default_and_offset_the_schedule() {
        let file = std::path::Path::new("over.json");
        let quick = PipelineConfig::quick();
        let text = serde_json::to_string(&quick).unwrap();
        assert!(!text.contains("fine_tune_rates") && !text.contains("original_share"));
        assert!(!text.contains("attribution"));
        assert_eq!(quick.position_offset(1500, 600), 0);
        // The attribution is read by name (its digest: `the_attribution_leaves_the_digest`).
        let on = PipelineConfig::with_overrides(
            Preset::Quick,
            serde_json::json!({"attribution": true}),
            file,
        )
        .unwrap();
        assert!(on.attribution && serde_json::to_string(&on).unwrap().contains("attribution"));
        let c = PipelineConfig::with_overrides(
            Preset::Quick,
            serde_json::json!({"fine_tune_rates": "continue", "original_share": 0.5}),
            file,
        )
        .unwrap();
        c.validate().unwrap();
        assert_eq!(c.fine_tune_rates, FineTuneRates::Continue);
        assert_eq!(c.position_offset(1500, 0), 1500);
        assert_eq!(c.position_offset(1500, 1200), 2700);
        assert_eq!(c.position_offset(u32::MAX, 1), u32::MAX);
        let text = serde_json::to_string(&c).unwrap();
        assert_eq!(serde_json::from_str::<PipelineConfig>(&text).unwrap(), c);
        for bad in [0.0, 1.0, f32::NAN] {
            let c = PipelineConfig {
                original_share: Some(bad),
                ..PipelineConfig::quick()
            };
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains("original_share"), "{e}");
        }
    }
}
