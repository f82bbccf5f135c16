//! `unseen audit` (SPEC.md §21): the paper's claims checked on a dataset with ground truth.
//!
//! Every variant of the paper's ablations (Tables 3 and 4) runs as a whole pipeline from
//! the same original scene, under several generators: the classical slots and the
//! ground-truth generator at controlled inconsistency levels (the x-axis of the paper's
//! mechanism claims: QA-Mask protects existing regions from *inconsistent* generated
//! content; independent views avoid *conflicting* content). Each (generator, variant, seed)
//! is one job with its own run directory; all jobs share one step cache
//! ([`crate::pipeline::RunOptions::cache`]), so a step whose inputs several variants share (the
//! views, the per-view generation, a QA-Mask of a given degree) is computed once.
//!
//! A claim is tested on the paired differences `d = full − variant` of the metric over
//! units (a seed at a numerics revision; [`samples`] pools batches of seeds): *holds* /
//! *contradicted* when significantly above / below its null value (0, or the
//! non-inferiority margin below 0 for "does not hurt") after Holm's correction within the
//! generator family, else *inconclusive* with the minimum detectable effect ([`stats`],
//! SPEC.md §21.2).
//!
//! This module holds the audit's configuration (variants, generators, presets); the
//! rest is in [`jobs`](mod@jobs) (the jobs, the original scene, one job's run and record, sharing),
//! [`verdicts`](mod@verdicts) (claims, paired differences, the decision), [`report`] (`audit.json`,
//! `audit.md`, the plot), [`samples`] (pooling batches), [`stats`] (the tests) and
//! [`cluster`] (the same audit as batch jobs).

use crate::collide::frustum::Outline;
use crate::error::{Error, Result};
use crate::pipeline::Event;
use crate::pipeline::selection::SelectionRule;
use crate::pipeline::{
    Hallucination, Inconsistency, Level, MaskSource, PipelineConfig, Preset, SlotNames,
    Stage2Depth, TruthDepth,
};
use crate::train::trainer::TrainConfig;
use std::path::Path;

pub mod cluster;
pub mod diagnostics;
pub mod dose;
pub mod family;
pub mod jobs;
pub mod pairs;
pub mod report;
pub mod results;
pub mod samples;
pub mod stats;
pub mod verdicts;
pub use jobs::*;
pub use report::*;
pub use samples::Samples;
pub use verdicts::*;

/// One ablation of the paper (or the full method).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Variant {
    Full,
    /// Uniform weights on generated views ("w/o QA-Mask").
    NoQaMask,
    /// `1 − alpha` of the scene being updated instead of the QA-Mask (Table 3's baseline).
    OpacityMask,
    /// The same number of views, evenly spaced along the candidate list ("w/o Idpdt Cam
    /// Detection").
    EvenViews,
    /// A colliding set of the independent set's size with matched coverage (not a paper
    /// ablation: it isolates the price of conflicts from coverage, SPEC.md §20.2).
    ConflictingViews,
    NoDepthSupervision,
    NoPropagation,
    QaSh3,
    QaSh4,
    NoInterpolation,
    /// Stage-2 depth by a least-squares fit to the stage-1 render instead of the paper's
    /// video depth alignment (the labelled deviation `stage2_depth: render_fit`).
    Stage2RenderFit,
    /// The generate–reconstruct–shift cycle the paper replaces (paradigm `cycle`).
    Cycle,
    /// `full` and `even_views` under a choice the paper leaves open (SPEC.md §20.2): the
    /// maximum-cardinality or maximum-coverage independent set, or hull frustums. Pairs of
    /// them test the independent-views claim under that choice (its sensitivity rows).
    FullMaxCardinality,
    EvenViewsMaxCardinality,
    FullMaxCoverage,
    EvenViewsMaxCoverage,
    FullHull,
    EvenViewsHull,
    /// The reconstructions train on the original views alone (`generated_supervision`
    /// off): a control of the fine-tune recipe, not an ablation of the paper (issue #72).
    OriginalsOnly,
}

crate::error::text_enum!(Variant, "variant", {
    Full => "full",
    NoQaMask => "no_qa_mask",
    OpacityMask => "opacity_mask",
    EvenViews => "even_views",
    ConflictingViews => "conflicting_views",
    NoDepthSupervision => "no_depth_supervision",
    NoPropagation => "no_propagation",
    QaSh3 => "qa_sh3",
    QaSh4 => "qa_sh4",
    NoInterpolation => "no_interpolation",
    Stage2RenderFit => "stage2_render_fit",
    Cycle => "cycle",
    FullMaxCardinality => "full_max_cardinality",
    EvenViewsMaxCardinality => "even_views_max_cardinality",
    FullMaxCoverage => "full_max_coverage",
    EvenViewsMaxCoverage => "even_views_max_coverage",
    FullHull => "full_hull",
    EvenViewsHull => "even_views_hull",
    OriginalsOnly => "originals_only",
});

impl Variant {
    /// The variants the presets run: the paper's ablations and the comparisons that
    /// isolate its mechanisms.
    pub const PRESET: [Variant; 12] = [
        Variant::Full,
        Variant::NoQaMask,
        Variant::OpacityMask,
        Variant::EvenViews,
        Variant::ConflictingViews,
        Variant::NoDepthSupervision,
        Variant::NoPropagation,
        Variant::QaSh3,
        Variant::QaSh4,
        Variant::NoInterpolation,
        Variant::Stage2RenderFit,
        Variant::Cycle,
    ];

    /// The sensitivity variants (opt-in: `--variants`).
    pub const SENSITIVITY: [Variant; 6] = [
        Variant::FullMaxCardinality,
        Variant::EvenViewsMaxCardinality,
        Variant::FullMaxCoverage,
        Variant::EvenViewsMaxCoverage,
        Variant::FullHull,
        Variant::EvenViewsHull,
    ];

    /// The controls (opt-in: `--variants`).
    pub const CONTROLS: [Variant; 1] = [Variant::OriginalsOnly];

    /// The variant's switch on top of the preset.
    pub fn apply(self, c: &mut PipelineConfig) {
        match self {
            Variant::Full => {}
            Variant::NoQaMask => c.mask_source = MaskSource::None,
            Variant::OpacityMask => c.mask_source = MaskSource::Opacity,
            Variant::EvenViews => c.independent_detection = false,
            Variant::ConflictingViews => {
                c.conflicting_views =
                    Some(crate::pipeline::selection::ConflictMatch::EvaluationCoverage)
            }
            Variant::NoDepthSupervision => c.depth_supervision = false,
            Variant::NoPropagation => c.propagation = false,
            Variant::QaSh3 => c.qa_sh_degree = 3,
            Variant::QaSh4 => c.qa_sh_degree = 4,
            Variant::NoInterpolation => c.interpolation = false,
            Variant::Stage2RenderFit => c.stage2_depth = Stage2Depth::RenderFit,
            Variant::Cycle => c.paradigm = crate::pipeline::Paradigm::Cycle,
            Variant::FullMaxCardinality => c.selection = SelectionRule::MaxCardinality,
            Variant::EvenViewsMaxCardinality => {
                c.selection = SelectionRule::MaxCardinality;
                c.independent_detection = false;
            }
            Variant::FullMaxCoverage => c.selection = SelectionRule::MaxCoverage,
            Variant::EvenViewsMaxCoverage => {
                c.selection = SelectionRule::MaxCoverage;
                c.independent_detection = false;
            }
            Variant::FullHull => c.frustum_outline = Outline::Hull,
            Variant::EvenViewsHull => {
                c.frustum_outline = Outline::Hull;
                c.independent_detection = false;
            }
            Variant::OriginalsOnly => c.generated_supervision = false,
        }
    }
}

/// Which generators fill the slots of a job.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GeneratorKind {
    /// The deterministic classical slots (Telea, depth-fill, morph).
    Classical,
    /// The labelled ground-truth generator at a named inconsistency level.
    Truth(Level),
    /// The ground-truth generator at a level (low or high) that also hallucinates unseen
    /// content at that level and answers depth in the relative mode (SPEC.md §20.6),
    /// `truth-<level>+hallucinating+relative`: the generator under which the paper's
    /// mechanisms (independent views against conflicting content, Eq. 5's alignment) have
    /// something to do.
    Hallucinating(Level),
    /// The hallucinating generator at the low level with one parameter set to a swept level
    /// (a whole percentage; SPEC.md §21.6): `dose-<param>-<percent>`.
    Dose { param: dose::DoseParam, percent: u8 },
}

impl GeneratorKind {
    pub fn name(self) -> String {
        match self {
            GeneratorKind::Classical => "classical".into(),
            GeneratorKind::Truth(level) => format!("truth-{}", level.name()),
            GeneratorKind::Hallucinating(level) => {
                format!("truth-{}+hallucinating+relative", level.name())
            }
            GeneratorKind::Dose { param, percent } => format!("dose-{}-{percent}", param.name()),
        }
    }

    /// `classical`, `truth-none`, `truth-low`, `truth-high`,
    /// `truth-low+hallucinating+relative`, `truth-high+hallucinating+relative`.
    pub fn by_name(name: &str) -> Result<GeneratorKind> {
        match name {
            "classical" => Ok(GeneratorKind::Classical),
            "truth-none" => Ok(GeneratorKind::Truth(Level::None)),
            "truth-low" => Ok(GeneratorKind::Truth(Level::Low)),
            "truth-high" => Ok(GeneratorKind::Truth(Level::High)),
            "truth-low+hallucinating+relative" => Ok(GeneratorKind::Hallucinating(Level::Low)),
            "truth-high+hallucinating+relative" => Ok(GeneratorKind::Hallucinating(Level::High)),
            _ => {
                // `dose-<param>-<percent>`, written as `name` writes it.
                let dose = name
                    .strip_prefix("dose-")
                    .and_then(|rest| rest.rsplit_once('-'))
                    .and_then(|(param, percent)| {
                        let param: dose::DoseParam = param.parse().ok()?;
                        Some(GeneratorKind::Dose {
                            param,
                            percent: percent.parse().ok().filter(|&p| p <= param.max_percent())?,
                        })
                    })
                    .filter(|g| g.name() == name);
                dose.ok_or_else(|| {
                    Error::invalid(format!(
                        "unknown generator '{name}' (classical, truth-none, truth-low, truth-high, truth-low+hallucinating+relative, truth-high+hallucinating+relative, dose-<hallucination|photometric|depth_distortion>-<0..100>, dose-ghosting-<0..200>)"
                    ))
                })
            }
        }
    }

    fn apply(self, c: &mut PipelineConfig) {
        match self {
            GeneratorKind::Classical => {
                c.slots = SlotNames::default();
                c.inconsistency = Inconsistency::NONE;
            }
            GeneratorKind::Truth(level) => {
                c.slots = SlotNames::truth();
                c.inconsistency = Inconsistency::at(level);
            }
            GeneratorKind::Hallucinating(level) => {
                c.slots = SlotNames::truth();
                c.inconsistency = Inconsistency::at(level);
                c.hallucination = Hallucination::at(level);
                c.truth_depth = TruthDepth::Relative;
            }
            GeneratorKind::Dose {
                param: dose::DoseParam::Ghosting,
                percent,
            } => {
                // The hallucination grid's level none (so that the views are chosen as in
                // the claims' runs), every call shifted as a whole.
                GeneratorKind::Hallucinating(Level::Low).apply(c);
                c.hallucination = Hallucination::None;
                c.inconsistency.shift_px = f32::from(percent) / 100.0 * dose::GHOST_MAX_PX;
            }
            GeneratorKind::Dose { param, percent } => {
                GeneratorKind::Hallucinating(Level::Low).apply(c);
                let t = f32::from(percent) / 100.0;
                let high = Inconsistency::HIGH;
                match param {
                    dose::DoseParam::Hallucination => {
                        c.hallucination = Hallucination::from_percent(percent);
                    }
                    dose::DoseParam::Photometric => {
                        let i = &mut c.inconsistency;
                        i.gain = t * high.gain;
                        i.offset = t * high.offset;
                        i.blur_sigma_px = t * high.blur_sigma_px;
                        i.shift_px = t * high.shift_px;
                        // Whole patches: the nearest to t × high's.
                        i.patches = (u32::from(percent) * high.patches + 50) / 100;
                        i.patch_size = high.patch_size;
                    }
                    dose::DoseParam::DepthDistortion => {
                        c.inconsistency.depth_flicker = t * high.depth_flicker;
                        c.inconsistency.depth_distortion = t * high.depth_distortion;
                    }
                    dose::DoseParam::Ghosting => unreachable!("matched above"),
                }
            }
        }
    }

    /// The family of Holm's correction: `classical` or `truth` (every level).
    pub fn family(self) -> &'static str {
        match self {
            GeneratorKind::Classical => "classical",
            GeneratorKind::Truth(_) | GeneratorKind::Hallucinating(_) => "truth",
            GeneratorKind::Dose { param, .. } => param.family(),
        }
    }

    /// Position on the inconsistency axis (classical: none).
    fn level(self) -> Option<usize> {
        match self {
            GeneratorKind::Classical
            | GeneratorKind::Hallucinating(_)
            | GeneratorKind::Dose { .. } => None,
            GeneratorKind::Truth(l) => Some(l as usize),
        }
    }
}

impl std::fmt::Display for GeneratorKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name())
    }
}

/// A generator written as its name (the audit's records; read back by
/// [`GeneratorKind::by_name`] at the edges: the CLI, the samples).
fn generator_name<S: serde::Serializer>(
    g: &GeneratorKind,
    s: S,
) -> std::result::Result<S::Ok, S::Error> {
    s.serialize_str(&g.name())
}

/// One audit: its configuration, the dataset, the output folder and where progress goes —
/// what every job, the merge, the estimate and the report read. The audit's operations are
/// its methods (`run`, `report`, `run_job`, `run_job_with_receipt`, `collect`, `estimate`,
/// `emit_slurm`).
#[derive(Clone)]
pub struct Audit<'a> {
    pub cfg: &'a AuditConfig,
    pub dataset: &'a Path,
    pub dir: &'a Path,
    /// `cfg`'s candidate family, resolved against the dataset.
    pub candidates: family::Candidates,
    pub on_event: &'a (dyn Fn(Event) + Sync),
}

impl<'a> Audit<'a> {
    /// The audit of `cfg` on `dataset` into `dir`, without progress events: an error when
    /// the dataset has no candidate family of `cfg`'s name.
    pub fn new(cfg: &'a AuditConfig, dataset: &'a Path, dir: &'a Path) -> Result<Audit<'a>> {
        Ok(Audit {
            cfg,
            dataset,
            dir,
            candidates: family::Candidates::resolve(dataset, cfg.candidates.as_deref())?,
            on_event: &|_| {},
        })
    }

    /// The same audit, its progress sent to `on_event`.
    pub fn with_events(self, on_event: &'a (dyn Fn(Event) + Sync)) -> Audit<'a> {
        Audit { on_event, ..self }
    }
}

/// What an audit runs.
#[derive(Clone, Debug)]
pub struct AuditConfig {
    /// The pipeline configuration every job starts from (a preset), before its
    /// generator, variant and seed are applied.
    pub base: PipelineConfig,
    pub variants: Vec<Variant>,
    pub generators: Vec<GeneratorKind>,
    /// The seeds of this batch (original scene and pipeline alike); batches of other
    /// seeds pool in the report ([`samples`]).
    pub seeds: std::ops::Range<u32>,
    /// Training of the original scene on the dataset's training half.
    pub train_iterations: u32,
    pub train_resolution: u32,
    /// The planned sample per claim (seeds; SPEC.md §21.2): verdicts on the first
    /// `planned_seeds` seeds, interim looks before ([`stats::PLANNED_SEEDS`] in both
    /// presets).
    pub planned_seeds: usize,
    /// The candidate family the pipeline is given (SPEC.md §20.7): `None` for the dataset's
    /// bundled `candidates.json`, else `families/<name>.json` in the dataset.
    pub candidates: Option<String>,
}

impl AuditConfig {
    /// One seed, every variant, the classical slots and the ground-truth generator at the
    /// low inconsistency level; the original scene as the demo trains it.
    pub fn quick() -> AuditConfig {
        AuditConfig {
            base: PipelineConfig::quick(),
            variants: Variant::PRESET.to_vec(),
            generators: vec![GeneratorKind::Classical, GeneratorKind::Truth(Level::Low)],
            seeds: 0..1,
            train_iterations: 1500,
            train_resolution: 2,
            planned_seeds: stats::PLANNED_SEEDS,
            candidates: None,
        }
    }

    /// Three seeds, every variant, the classical slots and the ground-truth generator at
    /// every level, the paper's pipeline settings and INRIA's 30 000 training iterations.
    pub fn paper() -> AuditConfig {
        AuditConfig {
            base: PipelineConfig::paper(),
            variants: Variant::PRESET.to_vec(),
            generators: vec![
                GeneratorKind::Classical,
                GeneratorKind::Truth(Level::None),
                GeneratorKind::Truth(Level::Low),
                GeneratorKind::Truth(Level::High),
            ],
            seeds: 0..3,
            train_iterations: 30_000,
            train_resolution: 1,
            planned_seeds: stats::PLANNED_SEEDS,
            candidates: None,
        }
    }

    /// The grid of `preset` (above) on the pipeline preset of the same name.
    pub fn preset(preset: Preset) -> AuditConfig {
        match preset {
            Preset::Quick => Self::quick(),
            Preset::Paper => Self::paper(),
        }
    }

    pub fn validate(&self) -> Result<()> {
        if self.variants.is_empty() || self.generators.is_empty() || self.seeds.is_empty() {
            return Err(Error::invalid(
                "an audit needs at least one variant, one generator and one seed",
            ));
        }
        let dup_v =
            (1..self.variants.len()).any(|i| self.variants[..i].contains(&self.variants[i]));
        let dup_g =
            (1..self.generators.len()).any(|i| self.generators[..i].contains(&self.generators[i]));
        if dup_v || dup_g {
            return Err(Error::invalid(
                "a variant or generator is listed twice (each is one set of jobs)",
            ));
        }
        if self.planned_seeds < 2 {
            return Err(Error::invalid(
                "the planned sample needs at least 2 seeds (one seed has no spread to judge)",
            ));
        }
        if !self.variants.contains(&Variant::Full) {
            return Err(Error::invalid(
                "every claim compares against the full method: include the variant 'full'",
            ));
        }
        if let Some(f) = &self.candidates {
            family::check_family_name(f)?;
        }
        Ok(())
    }

    /// [`config_digest`] of a job's configuration.
    pub fn config_digest(&self, generator: GeneratorKind, variant: Variant) -> Result<String> {
        Ok(config_digest(&self.pipeline_config(generator, variant, 0)?))
    }

    /// The pipeline configuration of one job.
    pub fn pipeline_config(
        &self,
        generator: GeneratorKind,
        variant: Variant,
        seed: u32,
    ) -> Result<PipelineConfig> {
        let mut c = self.base.clone();
        c.seed = seed as u64;
        generator.apply(&mut c);
        variant.apply(&mut c);
        Ok(c)
    }

    fn train_config(&self, seed: u32) -> TrainConfig {
        TrainConfig {
            iterations: self.train_iterations,
            resolution: self.train_resolution,
            seed: seed as u64,
            save_iterations: vec![],
            ..TrainConfig::default()
        }
    }
}

/// SHA-256 of a pipeline configuration's JSON with its seed set to 0 and the attribution
/// off (a record beside the same computation: samples with and without it pool): what one
/// (generator, variant) cell runs for every seed.
pub fn config_digest(c: &PipelineConfig) -> String {
    let c = PipelineConfig {
        seed: 0,
        attribution: false,
        ..c.clone()
    };
    crate::io::sha256_hex(&serde_json::to_vec(&c).expect("serializes"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The attribution (SPEC.md §20.5) is a record beside the same computation: samples
    /// made with it pool with those made without it.
    #[test]
    fn the_attribution_leaves_the_digest() {
        let quick = PipelineConfig::quick();
        let on = PipelineConfig {
            attribution: true,
            ..quick.clone()
        };
        assert_ne!(
            serde_json::to_string(&on).unwrap(),
            serde_json::to_string(&quick).unwrap()
        );
        assert_eq!(config_digest(&on), config_digest(&quick));
    }
}
