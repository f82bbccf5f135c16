//! From the jobs' results to the claims' verdicts: the metric of each claim, the paired
//! differences per unit (seed at a numerics revision), and the decision rule of [`super::stats`]
//! (SPEC.md §21.2).

use super::diagnostics::FidelityView;
use super::jobs::JobResult;
use super::pairs::PairView;
use super::stats;
use super::{AuditConfig, GeneratorKind, Variant};
use crate::pipeline::evaluate::{ClassSums, Row, ViewRecord};

/// The metric a claim compares (on the evaluation poses, final scene of each variant).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Metric {
    PsnrAll,
    PsnrExisting,
    PsnrExtrapolated,
    /// Mean PSNR over the training half's test views (the original areas).
    PsnrTrainHalf,
    /// A measure of the panel on the variant run's pixel classes, both runs scored there
    /// (the variant's [`JobResult::pair`], SPEC.md §21.7).
    Classes(Measure, Region),
    /// Generation fidelity (SPEC.md §21.7): PSNR of each run's final scene against its own
    /// stage-1 generations on the pixels they generated ([`FidelityView`]).
    Fidelity,
}

/// A measure of the panel (SPEC.md §21.7), pooled over a set of views' [`ClassSums`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Measure {
    Psnr,
    Ssim,
    Gmsd,
    /// The render's gradient energy over the truth's.
    Detail,
    /// Multi-view consistency: PSNR of the nearest other evaluation view's render, warped
    /// here with its depth, against this view's render, where both see one surface.
    Consistency,
}

impl Measure {
    pub const ALL: [Measure; 5] = [
        Measure::Psnr,
        Measure::Ssim,
        Measure::Gmsd,
        Measure::Detail,
        Measure::Consistency,
    ];

    /// The measure over a set of views' sums of one class.
    pub fn pooled<'a>(self, sums: impl IntoIterator<Item = &'a ClassSums>) -> f64 {
        match self {
            Measure::Psnr => ClassSums::psnr(sums),
            Measure::Ssim => ClassSums::ssim(sums),
            Measure::Gmsd => ClassSums::gmsd(sums),
            Measure::Detail => ClassSums::detail_ratio(sums),
            Measure::Consistency => ClassSums::consistency_psnr(sums),
        }
    }

    /// How much better `full` is than `variant` (positive: the full method better): the
    /// difference for PSNR, SSIM and consistency (a PSNR), its negative for GMSD (a deviation: lower is
    /// better), and for the detail ratio how much closer to 1 it is in log
    /// (`|ln r_variant| − |ln r_full|`: averaging shows below 1, noise above).
    pub fn better(self, full: f64, variant: f64) -> f64 {
        match self {
            Measure::Psnr | Measure::Ssim | Measure::Consistency => full - variant,
            Measure::Gmsd => variant - full,
            Measure::Detail => variant.ln().abs() - full.ln().abs(),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Measure::Psnr => "psnr",
            Measure::Ssim => "ssim",
            Measure::Gmsd => "gmsd",
            Measure::Detail => "detail",
            Measure::Consistency => "consistency",
        }
    }

    pub fn label(self) -> &'static str {
        match self {
            Measure::Psnr => "PSNR",
            Measure::Ssim => "SSIM",
            Measure::Gmsd => "GMSD",
            Measure::Detail => "detail ratio",
            Measure::Consistency => "multi-view consistency",
        }
    }
}

/// Where a panel measure is taken: the variant run's pixel classes (SPEC.md §21.5).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Region {
    /// Extrapolated pixels whose surface point ≥ 2 of the variant's stage-1 views generated.
    Contested,
    /// The rest of the unseen-surface sample: the within-pair null.
    Uncontested,
    /// `Δ_contested − Δ_uncontested`: the conflicts' signature, everything global to the
    /// two runs removed.
    DiffInDiff,
}

impl Region {
    pub fn name(self) -> &'static str {
        match self {
            Region::Contested => "contested",
            Region::Uncontested => "uncontested",
            Region::DiffInDiff => "diff_in_diff",
        }
    }

    fn label(self) -> &'static str {
        match self {
            Region::Contested => "contested",
            Region::Uncontested => "uncontested",
            Region::DiffInDiff => "contested − uncontested",
        }
    }
}

/// The measure of the primary claims (SPEC.md §21.7: registered before the claims' samples,
/// revised once after the control's pilot, before any of them).
pub const PRIMARY_MEASURE: Measure = Measure::Detail;

impl Metric {
    /// The metric of a scene's row (NaN for a panel metric: it is of a pair of scenes).
    pub(crate) fn of(self, r: &Row) -> f64 {
        match self {
            Metric::PsnrAll => r.psnr_all,
            Metric::PsnrExisting => r.psnr_existing,
            Metric::PsnrExtrapolated => r.psnr_extrapolated,
            Metric::PsnrTrainHalf => r.psnr_train_half,
            Metric::Classes(..) | Metric::Fidelity => f64::NAN,
        }
    }

    /// The per-view sums of the metric's pixel class (none for the training half, which
    /// is a mean over its views, nor for a panel metric, which reads the pair's).
    fn class(self, v: &ViewRecord) -> Option<&ClassSums> {
        match self {
            Metric::PsnrAll => Some(&v.all),
            Metric::PsnrExisting => Some(&v.existing),
            Metric::PsnrExtrapolated => Some(&v.extrapolated),
            Metric::PsnrTrainHalf | Metric::Classes(..) | Metric::Fidelity => None,
        }
    }

    pub(crate) fn label(self) -> String {
        match self {
            Metric::PsnrAll => "PSNR all".into(),
            Metric::PsnrExisting => "PSNR existing".into(),
            Metric::PsnrExtrapolated => "PSNR extrapolated".into(),
            Metric::PsnrTrainHalf => "train-half PSNR".into(),
            Metric::Classes(m, r) => format!("{} {}", m.label(), r.label()),
            Metric::Fidelity => "PSNR against own generations".into(),
        }
    }

    /// The unit of the metric's Δ: `dB`, or empty for a ratio.
    pub fn unit(self) -> &'static str {
        match self {
            Metric::Classes(Measure::Ssim | Measure::Gmsd | Measure::Detail, _) => "",
            _ => "dB",
        }
    }

    /// The name in `audit.json`: `psnr_all`, …, and `<measure>_<region>` for the panel.
    pub fn name(self) -> String {
        match self {
            Metric::PsnrAll => "psnr_all".into(),
            Metric::PsnrExisting => "psnr_existing".into(),
            Metric::PsnrExtrapolated => "psnr_extrapolated".into(),
            Metric::PsnrTrainHalf => "psnr_train_half".into(),
            Metric::Classes(m, r) => format!("{}_{}", m.name(), r.name()),
            Metric::Fidelity => "psnr_fidelity".into(),
        }
    }

    /// A metric of the panel (SPEC.md §21.7), read from the pair of scenes.
    pub fn is_panel(self) -> bool {
        matches!(self, Metric::Classes(..) | Metric::Fidelity)
    }

    /// A primary claim's metric (SPEC.md §21.7): [`PRIMARY_MEASURE`] on contested pixels,
    /// or on uncontested ones (the within-pair null judged beside it).
    pub fn is_primary(self) -> bool {
        matches!(self, Metric::Classes(m, Region::Contested | Region::Uncontested) if m == PRIMARY_MEASURE)
    }
}

impl serde::Serialize for Metric {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.name())
    }
}

/// How a claim compares the full method with a variant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// The full method is better.
    Beats,
    /// The full method is not worse.
    DoesNotHurt,
}

/// What a claim compares the full method's final scene with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Baseline {
    /// The variant's final scene.
    Variant,
    /// The original scene the run started from (the claim's variant is `full` itself).
    Original,
}

/// A claim of the paper: the full method against one variant (or its own original scene)
/// on one metric.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct Claim {
    pub id: &'static str,
    /// The run Δ is measured from: `full` for the paper's claims, `full` under another
    /// choice for a sensitivity row (SPEC.md §21.2).
    pub reference: Variant,
    pub variant: Variant,
    pub baseline: Baseline,
    pub metric: Metric,
    pub direction: Direction,
    /// What the paper reports (and where).
    pub paper: &'static str,
}

impl Claim {
    /// The two rows a pair compares: full's final scene and the baseline's.
    fn rows<'a>(&self, p: &Pair<'a>) -> (&'a Row, &'a Row) {
        match self.baseline {
            Baseline::Variant => (&p.full.last, &p.variant.last),
            Baseline::Original => (&p.full.last, &p.full.original),
        }
    }

    /// The pair's difference `full − baseline` of the claim's metric (for the panel, how
    /// much better full is: [`Measure::better`]).
    fn diff(&self, p: &Pair) -> f64 {
        match self.metric {
            Metric::Fidelity => fidelity_psnr(p.full) - fidelity_psnr(p.variant),
            Metric::Classes(measure, region) => match self.scored(p) {
                Some(views) => class_diff(measure, region, views.iter()),
                None => f64::NAN,
            },
            m => {
                let (a, b) = self.rows(p);
                m.of(a) - m.of(b)
            }
        }
    }

    /// A panel claim's seed where conflicts have nowhere to act: its pair was scored (or its
    /// fidelity measured) but the variant's set was not used, or the pair's region holds no
    /// pixel (the variant's stage-1 views generated no point twice). Counted towards the
    /// plan, not as a unit, as a same computation is (SPEC.md §21.7).
    fn nowhere_to_act(&self, p: &Pair) -> bool {
        match self.metric {
            Metric::Classes(measure, region) => self.scored(p).is_some_and(|views| {
                // The pixels the measure has: the class's (the same on both sides), or for
                // consistency those seen on one surface from the neighbouring view, which
                // each run's renders decide for themselves (the fewer of the two sides').
                let pixels = |f: fn(&PairView) -> &[ClassSums; 2]| {
                    let side = |s: usize| {
                        views
                            .iter()
                            .map(|v| match measure {
                                Measure::Consistency => f(v)[s].consistency.map_or(0, |c| c.pixels),
                                _ => f(v)[s].pixels,
                            })
                            .sum::<u64>()
                    };
                    side(0).min(side(1))
                };
                p.not_applied()
                    || pixels(|v| &v.contested) == 0
                    || (region != Region::Contested && pixels(|v| &v.uncontested) == 0)
            }),
            Metric::Fidelity => {
                let measured = |r: &JobResult| {
                    r.diagnostics
                        .as_ref()
                        .is_some_and(|d| !d.fidelity.is_empty())
                };
                p.not_applied() && measured(p.full) && measured(p.variant)
            }
            _ => false,
        }
    }

    /// A panel claim's views: the variant run's pair with this claim's reference run, when
    /// it scored the very scene the pool holds for it (none otherwise).
    /// A consistency claim reads only pairs that recorded it (samples written before it
    /// was have none: SPEC.md §21.7).
    fn scored<'a>(&self, p: &Pair<'a>) -> Option<&'a [PairView]> {
        let pair = p.variant.pair.as_ref()?;
        let recorded = match self.metric {
            Metric::Classes(Measure::Consistency, _) => pair
                .views
                .iter()
                .all(|v| v.contested.iter().all(|s| s.consistency.is_some())),
            _ => true,
        };
        (recorded
            && pair.reference == self.reference.name()
            && !p.full.scene_sha256.is_empty()
            && pair.reference_scene == p.full.scene_sha256)
            .then_some(&pair.views[..])
    }
}

/// PSNR of a run's final scene against its own stage-1 generations, pooled over every
/// generated pixel (NaN when not measured).
fn fidelity_psnr(r: &JobResult) -> f64 {
    let views: &[FidelityView] = r.diagnostics.as_ref().map_or(&[], |d| &d.fidelity);
    ClassSums::psnr(views.iter().flat_map(|v| [&v.contested, &v.uncontested]))
}

/// How much better the reference run (first of each `PairView` side) is than the variant
/// on `region` of a set of views, by `measure` (SPEC.md §21.7).
fn class_diff<'a>(
    measure: Measure,
    region: Region,
    views: impl Iterator<Item = &'a PairView> + Clone,
) -> f64 {
    let delta = |side: fn(&PairView) -> &[ClassSums; 2]| {
        let full = measure.pooled(views.clone().map(|v| &side(v)[0]));
        let variant = measure.pooled(views.clone().map(|v| &side(v)[1]));
        measure.better(full, variant)
    };
    match region {
        Region::Contested => delta(|v| &v.contested),
        Region::Uncontested => delta(|v| &v.uncontested),
        Region::DiffInDiff => delta(|v| &v.contested) - delta(|v| &v.uncontested),
    }
}

/// The claims the audit tests (SPEC.md §21.2).
pub const CLAIMS: [Claim; 19] = [
    Claim {
        reference: Variant::Full,
        id: "independent views",
        baseline: Baseline::Variant,
        variant: Variant::EvenViews,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "Table 4, ScanNet++ PSNR: 23.79 vs 20.27 (−3.52 dB)",
    },
    Claim {
        reference: Variant::Full,
        id: "conflicts cost at equal coverage",
        baseline: Baseline::Variant,
        variant: Variant::ConflictingViews,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "§3.2 \"conflict-free generation\"; §4 ablation: conflict-agnostic views are \"severely plagued by content conflicts\" (no number at equal coverage)",
    },
    Claim {
        reference: Variant::Full,
        id: "depth supervision",
        baseline: Baseline::Variant,
        variant: Variant::NoDepthSupervision,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "Table 4, ScanNet++ PSNR: 23.79 vs 23.66 (−0.13 dB)",
    },
    Claim {
        reference: Variant::Full,
        id: "QA-Mask SH 5 over SH 3",
        baseline: Baseline::Variant,
        variant: Variant::QaSh3,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "Table 4, ScanNet++ PSNR: 23.79 vs 22.45 (−1.34 dB)",
    },
    Claim {
        reference: Variant::Full,
        id: "QA-Mask SH 5 over SH 4",
        baseline: Baseline::Variant,
        variant: Variant::QaSh4,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "Table 4, ScanNet++ PSNR: 23.79 vs 23.28 (−0.51 dB)",
    },
    Claim {
        reference: Variant::Full,
        id: "QA-Mask (whole image)",
        baseline: Baseline::Variant,
        variant: Variant::NoQaMask,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "Table 4, Mip-NeRF 360 CLIP-IQA: 0.404 vs 0.343 (no PSNR given)",
    },
    Claim {
        reference: Variant::Full,
        id: "DIBR propagation",
        baseline: Baseline::Variant,
        variant: Variant::NoPropagation,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "Table 4, Mip-NeRF 360 CLIP-IQA: 0.404 vs 0.316 (no PSNR given)",
    },
    Claim {
        reference: Variant::Full,
        id: "QA-Mask protects existing regions",
        baseline: Baseline::Variant,
        variant: Variant::NoQaMask,
        metric: Metric::PsnrExisting,
        direction: Direction::Beats,
        paper: "Table 3, existing PSNR: DiFix3D+ 28.11 → 28.58, GenFusion 26.49 → 28.33",
    },
    Claim {
        reference: Variant::Full,
        id: "QA-Mask does not hurt extrapolation",
        baseline: Baseline::Variant,
        variant: Variant::NoQaMask,
        metric: Metric::PsnrExtrapolated,
        direction: Direction::DoesNotHurt,
        paper: "Table 3, extrapolated PSNR: DiFix3D+ 10.23 → 10.20, GenFusion 15.04 → 15.10",
    },
    Claim {
        reference: Variant::Full,
        id: "QA-Mask over opacity maps, existing",
        baseline: Baseline::Variant,
        variant: Variant::OpacityMask,
        metric: Metric::PsnrExisting,
        direction: Direction::Beats,
        paper: "Table 3, existing PSNR: DiFix3D+ 28.15 → 28.58, GenFusion 28.03 → 28.33",
    },
    Claim {
        reference: Variant::Full,
        id: "QA-Mask over opacity maps, extrapolated",
        baseline: Baseline::Variant,
        variant: Variant::OpacityMask,
        metric: Metric::PsnrExtrapolated,
        direction: Direction::DoesNotHurt,
        paper: "Table 3, extrapolated PSNR: DiFix3D+ 10.17 → 10.20, GenFusion 15.04 → 15.10",
    },
    Claim {
        reference: Variant::Full,
        id: "interpolation stage",
        baseline: Baseline::Variant,
        variant: Variant::NoInterpolation,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "§3.3.3 (design; no ablation number)",
    },
    Claim {
        reference: Variant::Full,
        id: "video depth for dependent views",
        baseline: Baseline::Variant,
        variant: Variant::Stage2RenderFit,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "§3.3 (design: DIBR-based video depth alignment 'throughout the process'; no ablation number)",
    },
    Claim {
        reference: Variant::Full,
        id: "no deterioration within original areas",
        baseline: Baseline::Original,
        variant: Variant::Full,
        metric: Metric::PsnrTrainHalf,
        direction: Direction::DoesNotHurt,
        paper: "§4: 'no sign of rendering deterioration can be observed within original areas' (Mip-NeRF 360, no number)",
    },
    Claim {
        reference: Variant::Full,
        id: "generated views cost original areas nothing beyond the recipe",
        baseline: Baseline::Variant,
        variant: Variant::OriginalsOnly,
        metric: Metric::PsnrTrainHalf,
        direction: Direction::DoesNotHurt,
        paper: "§4: 'no sign of rendering deterioration ... within original areas ... thanks to the proposed QA-Mask' (the control: the same fine-tunes on the original views alone)",
    },
    Claim {
        reference: Variant::Full,
        id: "hierarchy over the cycle",
        baseline: Baseline::Variant,
        variant: Variant::Cycle,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "§1, §3: the hierarchical pipeline replaces the generate–reconstruct–shift cycle (no number)",
    },
    Claim {
        reference: Variant::FullMaxCardinality,
        id: "independent views (maximum-cardinality set)",
        baseline: Baseline::Variant,
        variant: Variant::EvenViewsMaxCardinality,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: SENSITIVITY_NOTE,
    },
    Claim {
        reference: Variant::FullMaxCoverage,
        id: "independent views (maximum-coverage set)",
        baseline: Baseline::Variant,
        variant: Variant::EvenViewsMaxCoverage,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: SENSITIVITY_NOTE,
    },
    Claim {
        reference: Variant::FullHull,
        id: "independent views (hull frustums)",
        baseline: Baseline::Variant,
        variant: Variant::EvenViewsHull,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: SENSITIVITY_NOTE,
    },
];

/// A claim of the panel (SPEC.md §21.7): full against `variant` by one measure on one
/// region of the variant's pixel classes, full better.
macro_rules! class_claim {
    ($id:literal, $variant:ident, $measure:ident, $region:ident) => {
        Claim {
            id: $id,
            reference: Variant::Full,
            variant: Variant::$variant,
            baseline: Baseline::Variant,
            metric: Metric::Classes(Measure::$measure, Region::$region),
            direction: Direction::Beats,
            paper: MECHANISM_NOTE,
        }
    };
}

/// The mechanism claims where conflicts act (SPEC.md §21.7, registered before their
/// samples): per variant the primary claim ([`PRIMARY_MEASURE`] on contested pixels), its
/// within-pair null (on uncontested pixels), then the secondary panel.
pub const CLASS_CLAIMS: [Claim; 32] = [
    class_claim!(
        "independent views, detail contested",
        EvenViews,
        Detail,
        Contested
    ),
    class_claim!(
        "independent views, detail uncontested",
        EvenViews,
        Detail,
        Uncontested
    ),
    class_claim!(
        "independent views, PSNR contested",
        EvenViews,
        Psnr,
        Contested
    ),
    class_claim!(
        "independent views, SSIM contested",
        EvenViews,
        Ssim,
        Contested
    ),
    class_claim!(
        "independent views, GMSD contested",
        EvenViews,
        Gmsd,
        Contested
    ),
    class_claim!(
        "independent views, detail contested − uncontested",
        EvenViews,
        Detail,
        DiffInDiff
    ),
    class_claim!(
        "independent views, PSNR contested − uncontested",
        EvenViews,
        Psnr,
        DiffInDiff
    ),
    class_claim!(
        "independent views, SSIM contested − uncontested",
        EvenViews,
        Ssim,
        DiffInDiff
    ),
    class_claim!(
        "independent views, GMSD contested − uncontested",
        EvenViews,
        Gmsd,
        DiffInDiff
    ),
    class_claim!(
        "independent views, PSNR uncontested",
        EvenViews,
        Psnr,
        Uncontested
    ),
    class_claim!(
        "independent views, SSIM uncontested",
        EvenViews,
        Ssim,
        Uncontested
    ),
    class_claim!(
        "independent views, GMSD uncontested",
        EvenViews,
        Gmsd,
        Uncontested
    ),
    class_claim!(
        "conflicts cost at equal coverage, detail contested",
        ConflictingViews,
        Detail,
        Contested
    ),
    class_claim!(
        "conflicts cost at equal coverage, detail uncontested",
        ConflictingViews,
        Detail,
        Uncontested
    ),
    class_claim!(
        "conflicts cost at equal coverage, PSNR contested",
        ConflictingViews,
        Psnr,
        Contested
    ),
    class_claim!(
        "conflicts cost at equal coverage, SSIM contested",
        ConflictingViews,
        Ssim,
        Contested
    ),
    class_claim!(
        "conflicts cost at equal coverage, GMSD contested",
        ConflictingViews,
        Gmsd,
        Contested
    ),
    class_claim!(
        "conflicts cost at equal coverage, detail contested − uncontested",
        ConflictingViews,
        Detail,
        DiffInDiff
    ),
    class_claim!(
        "conflicts cost at equal coverage, PSNR contested − uncontested",
        ConflictingViews,
        Psnr,
        DiffInDiff
    ),
    class_claim!(
        "conflicts cost at equal coverage, SSIM contested − uncontested",
        ConflictingViews,
        Ssim,
        DiffInDiff
    ),
    class_claim!(
        "conflicts cost at equal coverage, GMSD contested − uncontested",
        ConflictingViews,
        Gmsd,
        DiffInDiff
    ),
    class_claim!(
        "conflicts cost at equal coverage, PSNR uncontested",
        ConflictingViews,
        Psnr,
        Uncontested
    ),
    class_claim!(
        "conflicts cost at equal coverage, SSIM uncontested",
        ConflictingViews,
        Ssim,
        Uncontested
    ),
    class_claim!(
        "conflicts cost at equal coverage, GMSD uncontested",
        ConflictingViews,
        Gmsd,
        Uncontested
    ),
    class_claim!(
        "independent views, multi-view consistency contested",
        EvenViews,
        Consistency,
        Contested
    ),
    class_claim!(
        "independent views, multi-view consistency contested − uncontested",
        EvenViews,
        Consistency,
        DiffInDiff
    ),
    class_claim!(
        "independent views, multi-view consistency uncontested",
        EvenViews,
        Consistency,
        Uncontested
    ),
    class_claim!(
        "conflicts cost at equal coverage, multi-view consistency contested",
        ConflictingViews,
        Consistency,
        Contested
    ),
    class_claim!(
        "conflicts cost at equal coverage, multi-view consistency contested − uncontested",
        ConflictingViews,
        Consistency,
        DiffInDiff
    ),
    class_claim!(
        "conflicts cost at equal coverage, multi-view consistency uncontested",
        ConflictingViews,
        Consistency,
        Uncontested
    ),
    Claim {
        metric: Metric::Fidelity,
        ..class_claim!(
            "independent views, fidelity to own generations",
            EvenViews,
            Psnr,
            Contested
        )
    },
    Claim {
        metric: Metric::Fidelity,
        ..class_claim!(
            "conflicts cost at equal coverage, fidelity to own generations",
            ConflictingViews,
            Psnr,
            Contested
        )
    },
];

/// What a panel row's paper column says.
const MECHANISM_NOTE: &str = "§3.2 \"conflict-free generation\": overlapping generations conflict; Table 4 (−3.52 dB without detection)";

/// What a sensitivity row's paper column says: the claim of Table 4 under a choice the
/// paper does not state.
const SENSITIVITY_NOTE: &str =
    "Table 4 (−3.52 dB without detection); the paper does not say which set or outline";

/// A claim tested under one generator (SPEC.md §21.2).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Verdict {
    #[serde(flatten)]
    pub claim: Claim,
    /// Written as its name ([`GeneratorKind::name`]).
    #[serde(serialize_with = "super::generator_name")]
    pub generator: GeneratorKind,
    /// The Holm family: the room × generator family (`classical`, `truth`, a dose
    /// parameter's), with `-sensitivity` for the sensitivity rows (their own family).
    pub family: String,
    /// Units (seeds) with both runs and a finite difference in the pool, the revisions
    /// among the judged ones, and how many the test judged: those of the plan, seeds 0 to
    /// `planned − 1` (the rest are beyond it and left out of everything below).
    pub seeds: usize,
    pub revisions: Vec<u32>,
    pub judged: usize,
    /// Planned seeds whose pair is the same computation (both runs evaluated one scene,
    /// [`Pair::same_computation`]) or where the variant's mechanism did not apply
    /// ([`Pair::not_applied`]): counted towards the plan, not judged.
    pub same_computation: usize,
    pub planned: usize,
    /// Median, mean and sample standard deviation of `full − variant` over the judged
    /// units (std is NaN, `null` in JSON, with one).
    pub median_diff: f64,
    pub mean_diff: f64,
    #[serde(with = "crate::io::json_float")]
    pub std_diff: f64,
    /// The value the test compares Δ with: 0, or `−margin` for a "does not hurt" claim.
    pub null: f64,
    /// What the p-value comes from, the judged differences above and below the null
    /// value, and the median's distribution-free interval (two-sided, level `1 − α`,
    /// before the family's correction; absent below 6 units).
    pub method: Option<stats::Method>,
    pub above: usize,
    pub below: usize,
    pub ci: Option<[f64; 2]>,
    /// Holm-adjusted two-sided p-value of the null value.
    #[serde(with = "crate::io::json_float")]
    pub p_holm: f64,
    /// The smallest shift of the median from the null value found with the rule's power
    /// at the family's first Holm level, for the measured spread (∞, `null` in JSON:
    /// this many units cannot reach that level).
    #[serde(with = "crate::io::json_float")]
    pub min_detectable: f64,
    /// Percentile interval of a bootstrap over units, then over the evaluation views of
    /// each unit (pooled PSNR of the resampled views), over the `hierarchical_units`
    /// judged units with per-view records; absent below [`HIERARCHICAL_MIN_UNITS`].
    pub hierarchical: Option<[f64; 2]>,
    pub hierarchical_units: usize,
    /// `holds`, `contradicted`, `inconclusive`, `interim (n of N seeds)` or `no verdict
    /// (…)` with its reason.
    pub verdict: String,
    /// On a primary claim (SPEC.md §21.7) whose panel splits: the rows of its variant and
    /// generator on contested pixels, in difference in differences or of generation
    /// fidelity whose median has the other sign, when one of them or the primary is decided.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub panel_splits: Option<String>,
}

impl Verdict {
    /// Holds or contradicted (whatever note follows the word).
    pub fn decided(&self) -> bool {
        self.verdict.starts_with("holds") || self.verdict.starts_with("contradicted")
    }

    /// Its median Δ with the metric's unit, signed: `+0.31 dB`, `−0.0042`.
    pub fn median_shown(&self) -> String {
        shown_delta(self.median_diff, self.claim.metric)
    }
}

/// Among the seeds `eligible` accepts, the one whose Δ of `v`'s claim lies nearest its
/// median (the lowest of ties; within the plan): the one a contact sheet shows (SPEC.md
/// §21.7), `eligible` being "its sheet exists" (a batch may keep only some seeds' sheets).
pub fn median_seed(pool: &[JobResult], v: &Verdict, eligible: impl Fn(u32) -> bool) -> Option<u32> {
    let c = &v.claim;
    let pairs = pairs_against(pool, &v.generator.name(), c.reference, c.variant);
    let mut best: Option<(f64, u32)> = None;
    for (seed, d) in seed_groups(&pairs, |p| c.diff(p)) {
        let off = (d - v.median_diff).abs();
        let within = (seed as usize) < v.planned && off.is_finite() && eligible(seed);
        if within && best.is_none_or(|b| off < b.0) {
            best = Some((off, seed));
        }
    }
    best.map(|b| b.1)
}

/// A Δ of `metric` signed, with its unit: two decimals in dB, four without a unit.
pub fn shown_delta(d: f64, metric: Metric) -> String {
    match metric.unit() {
        "" => format!("{d:+.4}"),
        u => format!("{d:+.2} {u}"),
    }
}

/// Flag each primary claim whose panel splits (SPEC.md §21.7): among it and the rows of its
/// variant and generator on contested pixels, in difference in differences and of
/// generation fidelity, medians of
/// both signs, one of those rows decided; the flag lists the rows of the other sign than
/// the primary's (none when its median is 0 or absent).
fn flag_panel_splits(verdicts: &mut [Verdict]) {
    for i in 0..verdicts.len() {
        let v = &verdicts[i];
        if !(v.claim.metric.is_primary()
            && matches!(v.claim.metric, Metric::Classes(_, Region::Contested)))
        {
            continue;
        }
        let group: Vec<&Verdict> = verdicts
            .iter()
            .filter(|w| w.claim.variant == v.claim.variant && w.generator == v.generator)
            .filter(|w| {
                matches!(
                    w.claim.metric,
                    Metric::Classes(_, Region::Contested | Region::DiffInDiff) | Metric::Fidelity
                )
            })
            .filter(|w| w.median_diff.is_finite() && w.median_diff != 0.0)
            .collect();
        let positive = group.iter().any(|w| w.median_diff > 0.0);
        let negative = group.iter().any(|w| w.median_diff < 0.0);
        if !(positive && negative && group.iter().any(|w| w.decided())) {
            continue;
        }
        if !(v.median_diff.is_finite() && v.median_diff != 0.0) {
            continue;
        }
        let sign = v.median_diff > 0.0;
        let other: Vec<String> = group
            .iter()
            .filter(|w| (w.median_diff > 0.0) != sign)
            .map(|w| {
                let word = if w.decided() { &w.verdict[..] } else { "" };
                let word = word.split(';').next().unwrap_or_default();
                let label = w.claim.metric.label();
                match word {
                    "" => format!("{label} {}", w.median_shown()),
                    _ => format!("{label} {} ({word})", w.median_shown()),
                }
            })
            .collect();
        verdicts[i].panel_splits = Some(other.join(", "));
    }
}

/// Mean and sample standard deviation (NaN for fewer than 2 values).
pub(super) fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (m, f64::NAN);
    }
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0);
    (m, var.sqrt())
}

/// A stable seed for a claim's bootstraps: the first 64 bits of SHA-256 of its names.
fn bootstrap_seed(claim: &Claim, generator: &str, what: &str) -> u64 {
    let h = crate::io::sha256_hex(format!("{what}\0{}\0{generator}", claim.id).as_bytes());
    u64::from_str_radix(&h[..16], 16).expect("hex")
}

/// Replicates of the hierarchical bootstrap.
pub const HIERARCHICAL_REPLICATES: usize = 2000;

/// The fewest units the hierarchical interval is computed from: 10. A percentile bootstrap
/// of a mean over n units has the spread of the plug-in variance, `√((n − 1)/n)` of the
/// sample's, so its nominal 95 % interval covers like a t interval of half-width
/// `1.96·√((n − 1)/n)`: `2·F_t(1.96·√((n − 1)/n); n − 1) − 1` = 60 % at 2 units, 85 % at 5,
/// 90.4 % at 10 (test `hierarchical_interval_needs_ten_units`): from 10 it covers at
/// least 90 % for normal units.
pub const HIERARCHICAL_MIN_UNITS: usize = 10;

/// A unit of the hierarchical bootstrap: its evaluation views, as a claim's Δ is
/// recomputed from them.
enum Unit<'a> {
    /// The per-view records of the two rows a claim compares (the same views, in order).
    Rows(&'a [ViewRecord], &'a [ViewRecord]),
    /// A panel claim's pair of scenes scored on the variant's classes.
    Pair(&'a [PairView]),
}

impl Unit<'_> {
    fn views(&self) -> usize {
        match self {
            Unit::Rows(a, _) => a.len(),
            Unit::Pair(v) => v.len(),
        }
    }

    /// The claim's Δ on the views `picks` (with repeats): pooled PSNR of the metric's
    /// class for a row metric, [`class_diff`] for a panel one.
    fn diff(&self, metric: Metric, picks: &[usize]) -> f64 {
        match (self, metric) {
            (Unit::Pair(v), Metric::Classes(m, r)) => {
                class_diff(m, r, picks.iter().map(|&i| &v[i]))
            }
            (Unit::Rows(a, b), _) => {
                let pa = ClassSums::psnr(picks.iter().map(|&i| class_of(metric, &a[i])));
                let pb = ClassSums::psnr(picks.iter().map(|&i| class_of(metric, &b[i])));
                pa - pb
            }
            (Unit::Pair(_), _) => f64::NAN,
        }
    }
}

/// The hierarchical bootstrap's 95 % percentile interval of the mean paired difference
/// of the claim's metric: units resampled with replacement, then each unit's evaluation
/// views (the same views for both runs of the pair), the metric recomputed from the
/// resampled views (pooled PSNR of a row metric's class; a panel measure on the pair's
/// classes). Units without per-view records (or with different view lists) are left out;
/// `None` below [`HIERARCHICAL_MIN_UNITS`] and for the training half.
fn hierarchical(pairs: &[Pair], claim: &Claim, alpha: f64, seed: u64) -> (Option<[f64; 2]>, usize) {
    let metric = claim.metric;
    let units: Vec<Unit> = pairs
        .iter()
        .filter_map(|p| match metric {
            Metric::Classes(..) => claim.scored(p).map(Unit::Pair),
            _ => {
                let (a, b) = claim.rows(p);
                Some(Unit::Rows(&a.views[..], &b.views[..]))
            }
        })
        .filter(|u| match u {
            Unit::Rows(a, b) => {
                !a.is_empty()
                    && a.len() == b.len()
                    && a.iter().zip(b.iter()).all(|(x, y)| x.view == y.view)
                    && metric.class(&a[0]).is_some()
            }
            Unit::Pair(v) => !v.is_empty(),
        })
        .collect();
    let n = units.len();
    if n < HIERARCHICAL_MIN_UNITS {
        return (None, n);
    }
    let mut u = crate::rng::Uniform::new(seed);
    let mut reps = Vec::with_capacity(HIERARCHICAL_REPLICATES);
    let mut picks: Vec<usize> = Vec::new();
    for _ in 0..HIERARCHICAL_REPLICATES {
        let (mut sum, mut count) = (0.0, 0usize);
        for _ in 0..n {
            let unit = &units[u.below(n as u32) as usize];
            let views = unit.views();
            picks.clear();
            picks.extend((0..views).map(|_| u.below(views as u32) as usize));
            let d = unit.diff(metric, &picks);
            if d.is_finite() {
                sum += d;
                count += 1;
            }
        }
        if count > 0 {
            reps.push(sum / count as f64);
        }
    }
    if reps.is_empty() {
        return (None, n);
    }
    reps.sort_by(f64::total_cmp);
    let at = |q: f64| stats::quantile_sorted(&reps, q);
    (Some([at(alpha / 2.0), at(1.0 - alpha / 2.0)]), n)
}

/// The per-view sums of a metric with a pixel class (checked by the caller).
fn class_of(metric: Metric, v: &ViewRecord) -> &ClassSums {
    metric.class(v).expect("a metric with a pixel class")
}

/// One draw of a claim's pair: a seed at a numerics revision (SPEC.md §21.2; the unit of
/// the test is the seed, [`seed_means`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Pair<'a> {
    pub seed: u32,
    pub revision: u32,
    pub full: &'a JobResult,
    pub variant: &'a JobResult,
}

impl Pair<'_> {
    /// Both runs evaluated the same scene (equal final-scene digests): the variant changed
    /// nothing the evaluation sees on this draw, so the pair compares nothing (SPEC.md §21.5).
    /// False when either digest was not recorded.
    pub fn same_computation(&self) -> bool {
        !self.full.scene_sha256.is_empty() && self.full.scene_sha256 == self.variant.scene_sha256
    }

    /// The variant's mechanism did not apply on this draw: `conflicting_views` found no
    /// colliding set that qualifies (coverage and overlap) and generated the independent set, as
    /// `full` does (SPEC.md §20.2). Its Δ is then noise between two runs of one method
    /// (their random streams differ with the plan's record), so, like a same computation,
    /// the draw is no unit (SPEC.md §21.5).
    pub fn not_applied(&self) -> bool {
        self.variant
            .diagnostics
            .as_ref()
            .and_then(|d| d.choice.as_ref())
            .and_then(|c| c.conflicting.as_ref())
            .is_some_and(|c| !c.used)
    }
}

/// The pairs (full, `variant`) of `generator` in `pool`: both runs of one seed at one
/// numerics revision, in (seed, revision) order. Pairs of one seed at several revisions
/// count once, at the newest revision, when either run is bit for bit the same (a
/// revision that did not change it; metrics compared, per-view records aside): an
/// independent draw needs both runs to differ.
pub fn pairs<'a>(pool: &'a [JobResult], generator: &str, variant: Variant) -> Vec<Pair<'a>> {
    pairs_against(pool, generator, Variant::Full, variant)
}

/// [`pairs`] with another reference run than `full` (a sensitivity row's).
pub fn pairs_against<'a>(
    pool: &'a [JobResult],
    generator: &str,
    reference: Variant,
    variant: Variant,
) -> Vec<Pair<'a>> {
    let cell = |v: Variant| {
        pool.iter()
            .filter(move |r| r.generator == generator && r.variant == v.name())
    };
    let mut out: Vec<Pair<'a>> = Vec::new();
    for full in cell(reference) {
        let Some(other) = cell(variant)
            .find(|r| r.seed == full.seed && r.numerics_revision == full.numerics_revision)
        else {
            continue;
        };
        out.push(Pair {
            seed: full.seed,
            revision: full.numerics_revision,
            full,
            variant: other,
        });
    }
    // Newest revision first, so that of two bit-identical draws the one kept is the newer
    // (which carries the per-view records of later versions).
    out.sort_by_key(|p| (p.seed, std::cmp::Reverse(p.revision)));
    let bits = |r: &JobResult| serde_json::to_string(&metrics_only(&r.last)).expect("serializes");
    let mut kept: Vec<Pair<'a>> = Vec::new();
    for p in out {
        // Another revision's pair is an independent draw only if neither run reproduces
        // the kept pair's: a pair sharing one run with it would be correlated with it.
        let same = kept.iter().any(|q| {
            q.seed == p.seed && (bits(q.full) == bits(p.full) || bits(q.variant) == bits(p.variant))
        });
        if !same {
            kept.push(p);
        }
    }
    kept.sort_by_key(|p| (p.seed, p.revision));
    kept
}

/// The unit of the test is the seed: per seed, the mean of its pairs' differences
/// `full − variant` over the revisions that drew it (`pairs` in (seed, revision) order).
/// Two draws of one seed at different revisions share the seed's random streams and are
/// correlated (measured between revisions 2 and 4: r = 0.27 [0.07, 0.45] on gallery,
/// −0.08 [−0.28, 0.12] on lounge; SPEC.md §21.2), so a revision adds precision to its seed,
/// not a unit.
pub fn seed_means(pairs: &[Pair], metric: Metric) -> Vec<f64> {
    seed_diffs(pairs, |p| {
        metric.of(&p.full.last) - metric.of(&p.variant.last)
    })
}

/// [`seed_means`] of any paired difference `diff`.
fn seed_diffs(pairs: &[Pair], diff: impl Fn(&Pair) -> f64) -> Vec<f64> {
    seed_groups(pairs, diff)
        .into_iter()
        .map(|(_, d)| d)
        .collect()
}

/// Per seed (pairs in seed order), the seed and the mean of its pairs' `diff`.
fn seed_groups(pairs: &[Pair], diff: impl Fn(&Pair) -> f64) -> Vec<(u32, f64)> {
    let mut out = Vec::new();
    let mut k = 0;
    while k < pairs.len() {
        let seed = pairs[k].seed;
        let group: Vec<f64> = pairs[k..]
            .iter()
            .take_while(|p| p.seed == seed)
            .map(&diff)
            .collect();
        k += group.len();
        out.push((seed, group.iter().sum::<f64>() / group.len() as f64));
    }
    out
}

/// Per seed, its pair at the newest revision (the hierarchical bootstrap's unit).
fn newest_per_seed<'a>(pairs: &[Pair<'a>]) -> Vec<Pair<'a>> {
    let mut out: Vec<Pair<'a>> = Vec::new();
    for p in pairs {
        match out.last_mut() {
            Some(q) if q.seed == p.seed => *q = p.clone(),
            _ => out.push(p.clone()),
        }
    }
    out
}

/// A row's metrics without its per-view records (what two draws are compared on: a sample
/// written before the records existed has the same metrics bits without them).
pub(super) fn metrics_only(r: &Row) -> Row {
    Row {
        views: Vec::new(),
        ..r.clone()
    }
}

/// Every claim whose variant was run, per generator, judged by `rule` within each
/// generator family (SPEC.md §21.2).
pub fn verdicts(cfg: &AuditConfig, pool: &[JobResult], rule: &stats::Rule) -> Vec<Verdict> {
    let cells: Vec<Cell> = CLAIMS
        .iter()
        .chain(&CLASS_CLAIMS)
        .filter(|c| cfg.variants.contains(&c.variant) && cfg.variants.contains(&c.reference))
        .flat_map(|&claim| cfg.generators.iter().map(move |&g| (claim, g)))
        .filter_map(|(claim, generator)| cell(cfg, pool, rule, claim, generator))
        .collect();
    let mut out: Vec<Option<Verdict>> = cells.iter().map(|_| None).collect();
    let mut families: Vec<String> = Vec::new();
    for c in &cells {
        if !families.contains(&holm_family(c)) {
            families.push(holm_family(c));
        }
    }
    for family in families {
        let members: Vec<usize> = (0..cells.len())
            .filter(|&i| holm_family(&cells[i]) == family)
            .collect();
        let data: Vec<stats::ClaimData> = members
            .iter()
            .map(|&i| stats::ClaimData {
                diffs: &cells[i].diffs,
                null: null_of(&cells[i].claim, rule),
                untested: cells[i].same,
            })
            .collect();
        for (&i, j) in members.iter().zip(rule.judge(&data)) {
            out[i] = Some(verdict_of(&cells[i], &j, &family, rule));
        }
    }
    let mut out: Vec<Verdict> = out.into_iter().flatten().collect();
    flag_panel_splits(&mut out);
    out
}

/// One claim under one generator, as the pool gives it: its pairs within the plan, the
/// per-seed Δ of the seeds that compared something, and how many did not.
struct Cell<'a> {
    claim: Claim,
    generator: GeneratorKind,
    pairs: Vec<Pair<'a>>,
    /// Seeds with a finite Δ, the plan's or beyond it.
    seeds: usize,
    diffs: Vec<f64>,
    /// Planned seeds on which nothing was compared (SPEC.md §21.5).
    same: usize,
}

/// The cell of `claim` under `generator`, if the pool holds a pair of it.
fn cell<'a>(
    cfg: &AuditConfig,
    pool: &'a [JobResult],
    rule: &stats::Rule,
    claim: Claim,
    generator: GeneratorKind,
) -> Option<Cell<'a>> {
    // Samples of another pipeline configuration of these cells measure something else
    // ([`JobResult::config`]; empty: recorded before configurations were, by a binary whose
    // method revision 5 changed, so another one).
    let full_cfg = cfg.config_digest(generator, claim.reference).ok()?;
    let variant_cfg = cfg.config_digest(generator, claim.variant).ok()?;
    let pairs: Vec<Pair> = pairs_against(pool, &generator.name(), claim.reference, claim.variant)
        .into_iter()
        .filter(|p| p.full.config == full_cfg && p.variant.config == variant_cfg)
        .filter(|p| claim.diff(p).is_finite() || claim.nowhere_to_act(p))
        .collect();
    if pairs.is_empty() {
        return None;
    }
    // The plan is seeds 0 to `planned − 1`: later seeds are beyond it (counted in `seeds`,
    // judged nowhere); a planned seed without a finite Δ keeps the claim interim.
    let seeds = seed_diffs(&pairs, |p| claim.diff(p)).len();
    let planned = u32::try_from(rule.planned).unwrap_or(u32::MAX);
    let pairs: Vec<Pair> = pairs.into_iter().filter(|p| p.seed < planned).collect();
    // A planned seed whose every pair is the same computation (or one where the variant's
    // mechanism did not apply) did not compare anything: it counts towards the plan, not as
    // a unit (SPEC.md §21.5).
    let mut same_seeds: Vec<u32> = pairs
        .iter()
        .filter(|_| claim.baseline == Baseline::Variant)
        .filter(|p| {
            pairs.iter().all(|q| {
                q.seed != p.seed
                    || q.same_computation()
                    || q.not_applied()
                    || claim.nowhere_to_act(q)
            })
        })
        .map(|p| p.seed)
        .collect();
    same_seeds.dedup();
    let pairs: Vec<Pair> = pairs
        .into_iter()
        .filter(|p| !same_seeds.contains(&p.seed))
        .collect();
    let diffs = seed_diffs(&pairs, |p| claim.diff(p));
    Some(Cell {
        claim,
        generator,
        pairs,
        seeds,
        diffs,
        same: same_seeds.len(),
    })
}

/// The null a claim's Δ is tested against: 0 ("better") or `−margin` ("does not hurt").
fn null_of(c: &Claim, rule: &stats::Rule) -> f64 {
    match c.direction {
        Direction::Beats => 0.0,
        Direction::DoesNotHurt => -rule.margin,
    }
}

/// A cell's Holm family: the generator family; the sensitivity rows apart from the paper's
/// claims (they ask another question: whether one claim's verdict turns on a choice the
/// paper leaves open; sharing the family would make every claim's correction depend on how
/// many choices were tried); the panel's claims likewise, the primary claims with their
/// within-pair null and the secondary panel (SPEC.md §21.7), so that neither moves the
/// paper's claims.
fn holm_family(c: &Cell) -> String {
    let g = c.generator.family();
    match c.claim.metric {
        _ if c.claim.reference != Variant::Full => format!("{g}-sensitivity"),
        m if m.is_primary() => format!("{g}-classes"),
        m if m.is_panel() => format!("{g}-panel"),
        _ => g.to_string(),
    }
}

/// The verdict's words for a cell judged `j`.
fn verdict_words(c: &Cell, j: &stats::Judgement, rule: &stats::Rule) -> String {
    let conflicting = c.claim.variant == Variant::ConflictingViews;
    let mut verdict = match j.outcome {
        stats::Outcome::Interim => {
            format!(
                "interim ({} of {} seeds)",
                c.diffs.len() + c.same,
                rule.planned
            )
        }
        stats::Outcome::NotTested if c.claim.metric.is_panel() => format!(
            "not tested here (on all {} seeds the same scene, no colliding set qualified, or no contested pixel)",
            c.same
        ),
        stats::Outcome::NotTested if conflicting => format!(
            "not tested here (on all {} seeds the same scene, or no colliding set qualified)",
            c.same
        ),
        stats::Outcome::NotTested => format!(
            "not tested here (same computation on all {} seeds: both runs evaluated the same scene)",
            c.same
        ),
        stats::Outcome::NoVerdict
            if c.diffs.iter().all(|&d| d == 0.0) && c.claim.baseline == Baseline::Variant =>
        {
            "no verdict (Δ = 0 on every seed: the variant computes what full computes)".to_string()
        }
        stats::Outcome::NoVerdict => {
            "no verdict (the same Δ on every seed: one draw, not n)".to_string()
        }
        stats::Outcome::Inconclusive if j.median_and_mean_disagree => {
            "inconclusive (the median and the mean lie on opposite sides)".to_string()
        }
        o => o.word().to_string(),
    };
    if c.same > 0 && j.outcome != stats::Outcome::NotTested {
        verdict += &format!(
            "; not tested on {} of {} seeds ({})",
            c.same,
            c.same + c.diffs.len(),
            if c.claim.metric.is_panel() {
                "the same scene, no colliding set qualified, or no contested pixel"
            } else if conflicting {
                "the same scene, or no colliding set qualified"
            } else {
                "same computation"
            }
        );
    }
    verdict
}

/// The verdict of a cell judged `j` in Holm family `family`.
fn verdict_of(c: &Cell, j: &stats::Judgement, family: &str, rule: &stats::Rule) -> Verdict {
    let (mean, std) = mean_std(&c.diffs);
    let mut revisions: Vec<u32> = c.pairs.iter().map(|p| p.revision).collect();
    revisions.sort_unstable();
    revisions.dedup();
    let (hier, hier_units) = hierarchical(
        &newest_per_seed(&c.pairs),
        &c.claim,
        rule.alpha,
        bootstrap_seed(&c.claim, &c.generator.name(), "hierarchical"),
    );
    Verdict {
        claim: c.claim,
        family: family.to_string(),
        generator: c.generator,
        seeds: c.seeds,
        revisions,
        judged: c.diffs.len(),
        same_computation: c.same,
        planned: rule.planned,
        median_diff: j.test.map_or(f64::NAN, |t| t.median),
        mean_diff: mean,
        std_diff: std,
        null: null_of(&c.claim, rule),
        method: j.test.map(|t| t.method),
        above: j.test.map_or(0, |t| t.above),
        below: j.test.map_or(0, |t| t.below),
        ci: j.test.and_then(|t| t.interval),
        p_holm: j.p_holm,
        min_detectable: j.min_detectable(rule),
        hierarchical: hier,
        hierarchical_units: hier_units,
        verdict: verdict_words(c, j, rule),
        panel_splits: None,
    }
}
