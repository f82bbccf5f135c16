//! The audit's claims and verdicts (SPEC.md §21.2–§21.7) on pools of samples: the original
//! areas' non-inferiority, the recipe's control, the conflicting set, the panel, sweeps,
//! sensitivity rows and the pooling of seeds and revisions.

use crate::support::{TempDir, reference};

/// A sample of the audit with the given PSNR (all classes) of its final scene.
pub(super) fn sample(
    variant: &str,
    seed: u32,
    revision: u32,
    psnr: f64,
) -> unseen::audit::JobResult {
    use unseen::pipeline::evaluate::Row;
    let row = Row {
        scene: "interpolate".into(),
        psnr_all: psnr,
        psnr_existing: psnr,
        psnr_extrapolated: psnr,
        ssim_all: 0.5,
        ssim_existing: 0.5,
        ssim_extrapolated: 0.5,
        psnr_train_half: 30.0,
        ssim_train_half: 0.9,
        gaussians: 1,
        lineage: None,
        views: vec![],
    };
    unseen::audit::JobResult {
        generator: "truth-low".into(),
        variant: variant.into(),
        seed,
        numerics_revision: revision,
        crate_version: "0.1.0".into(),
        config: unseen::audit::AuditConfig::preset(unseen::pipeline::Preset::Quick)
            .config_digest(
                unseen::audit::GeneratorKind::by_name("truth-low").unwrap(),
                variant.parse::<unseen::audit::Variant>().unwrap(),
            )
            .unwrap(),
        original: row.clone(),
        last: row,
        stage_seconds: Default::default(),
        steps: vec![],
        scene_sha256: String::new(),
        final_scene: String::new(),
        pair: None,
        diagnostics: None,
        candidates: None,
        stages: vec![],
    }
}

/// "No deterioration within original areas" (SPEC.md §21.2): full's final scene against
/// its own original scene on the training half, as non-inferiority at the margin; it needs
/// only the `full` runs and is never a same computation.
#[test]
fn the_original_areas_claim_is_non_inferiority_of_the_final_scene_against_the_original() {
    use unseen::audit::{AuditConfig, GeneratorKind, Variant, stats::Rule, verdicts};
    let cfg = AuditConfig {
        variants: vec![Variant::Full],
        generators: vec![GeneratorKind::Truth(unseen::pipeline::Level::Low)],
        ..AuditConfig::quick()
    };
    let judge = |loss: f64| {
        let pool: Vec<_> = (0..16)
            .map(|seed| {
                let mut r = sample("full", seed, 7, 20.0);
                // Spread around the loss, the same scene digest as "itself".
                r.last.psnr_train_half = r.original.psnr_train_half - loss + 0.01 * seed as f64;
                r.scene_sha256 = "a".repeat(64);
                r
            })
            .collect();
        let v = verdicts(&cfg, &pool, &Rule::default());
        assert_eq!(
            v.len(),
            1,
            "only the original-areas claim has its runs: {v:?}"
        );
        v[0].clone()
    };
    let small = judge(0.05);
    assert_eq!(small.claim.id, "no deterioration within original areas");
    assert_eq!(
        (small.judged, small.same_computation, small.null),
        (16, 0, -0.2)
    );
    assert_eq!(small.verdict, "holds", "{small:?}");
    let large = judge(1.0);
    assert_eq!(large.verdict, "contradicted", "{large:?}");
}

/// The recipe's control (issue #72): full's final scene against `originals_only`'s (the
/// same fine-tunes on the original views alone) on the training half, as non-inferiority
/// at the margin; judged only where `originals_only` ran.
#[test]
fn generated_views_are_judged_against_the_recipe_on_the_training_half() {
    use unseen::audit::{AuditConfig, GeneratorKind, Variant, stats::Rule, verdicts};
    let id = "generated views cost original areas nothing beyond the recipe";
    let cfg = |variants| AuditConfig {
        variants,
        generators: vec![GeneratorKind::Truth(unseen::pipeline::Level::Low)],
        ..AuditConfig::quick()
    };
    let judge = |cost: f64| {
        let mut pool = Vec::new();
        for seed in 0..16u32 {
            let mut full = sample("full", seed, 8, 20.0);
            full.last.psnr_train_half = 30.0 - cost + 0.01 * f64::from(seed);
            full.scene_sha256 = format!("{seed:064}");
            let mut control = sample("originals_only", seed, 8, 20.0);
            control.scene_sha256 = format!("{:064}", seed + 100);
            pool.extend([full, control]);
        }
        let v = verdicts(
            &cfg(vec![Variant::Full, Variant::OriginalsOnly]),
            &pool,
            &Rule::default(),
        );
        let c = v.iter().find(|v| v.claim.id == id).cloned();
        let without = verdicts(&cfg(vec![Variant::Full]), &pool, &Rule::default());
        assert!(!without.iter().any(|v| v.claim.id == id));
        c.expect("judged where originals_only ran")
    };
    let small = judge(0.05);
    assert_eq!((small.judged, small.null), (16, -0.2), "{small:?}");
    assert_eq!(small.verdict, "holds", "{small:?}");
    assert_eq!(judge(1.0).verdict, "contradicted");
    assert_eq!(
        "originals_only".parse::<Variant>().unwrap(),
        Variant::OriginalsOnly
    );
}

/// `conflicting_views` where no colliding set qualified (SPEC.md §20.2)
/// generates the independent set, as `full` does, with other random streams: such a seed is
/// not a unit of "conflicts cost at equal coverage" (its Δ would be noise between two runs
/// of one method), and the verdict says on how many seeds the claim was not tested.
#[test]
fn a_conflicting_set_that_was_not_used_is_not_a_unit() {
    use unseen::audit::{AuditConfig, GeneratorKind, Variant, stats::Rule, verdicts};
    let cfg = AuditConfig {
        variants: vec![Variant::Full, Variant::ConflictingViews],
        generators: vec![GeneratorKind::Truth(unseen::pipeline::Level::Low)],
        ..AuditConfig::quick()
    };
    let diagnostics = |used: bool| {
        serde_json::from_value(serde_json::json!({
            "candidates": 12, "covered": 0, "set_aside": [], "collisions": 40, "pairs": 66,
            "stage1_views": ["a", "b"], "stage1_collisions": u32::from(used),
            "dependent_per_gap": [10], "interpolated": 0, "degenerate_gaps": 0,
            "stage1": null, "stage2_filled": 0.1,
            "choice": {"rule": "greedy", "independent": ["a", "b"], "coverage": 100,
                       "conflicting": {"views": ["a", "c"], "coverage": if used { 98 } else { 60 },
                                       "coverage_difference": if used { 0.02 } else { 0.4 },
                                       "used": used}}
        }))
        .unwrap()
    };
    let mut pool = Vec::new();
    for seed in 0..16 {
        let used = seed % 4 != 3; // 12 seeds with a matched set, 4 without
        let mut full = sample("full", seed, 7, 20.0 + 0.1 * seed as f64);
        full.scene_sha256 = format!("{seed:064}");
        let shift = if used { 1.0 } else { -0.5 }; // the unused seeds would pull Δ below 0
        let mut c = sample("conflicting_views", seed, 7, full.last.psnr_all - shift);
        c.scene_sha256 = format!("{:064}", seed + 100);
        c.diagnostics = Some(diagnostics(used));
        pool.extend([full, c]);
    }
    let v = verdicts(&cfg, &pool, &Rule::default());
    let v = v
        .iter()
        .find(|v| v.claim.id == "conflicts cost at equal coverage")
        .unwrap();
    assert_eq!((v.judged, v.same_computation), (12, 4), "{v:?}");
    assert_eq!((v.above, v.below), (12, 0), "{v:?}");
    assert!(v.verdict.contains("not tested on 4 of 16 seeds"), "{v:?}");
}

/// The panel (SPEC.md §21.7): both runs of a pair judged on the variant's contested and
/// uncontested pixels from the variant's `pair`, every Δ oriented so that positive means
/// full is better (GMSD's sign flipped, the detail ratio by its distance from 1), the
/// primary claims in their own Holm family with their uncontested null, the rest in the
/// panel's, the paper's claims untouched; a pair that scored another scene than the
/// pool's full run is no unit; a panel that disagrees with the primary is flagged.
#[test]
fn the_panel_judges_both_runs_on_the_variants_contested_pixels() {
    use unseen::audit::pairs::{Pair, PairView};
    use unseen::audit::{AuditConfig, GeneratorKind, Measure, Variant, stats::Rule, verdicts};
    use unseen::pipeline::evaluate::ClassSums;
    let cfg = AuditConfig {
        variants: vec![Variant::Full, Variant::ConflictingViews],
        generators: vec![GeneratorKind::Truth(unseen::pipeline::Level::Low)],
        ..AuditConfig::quick()
    };
    // Sums of a class of 100 pixels (weight 1 each): squared error `se`, SSIM `ss`, the
    // GMSD deficit's mean `m` and spread `sd`, gradient energy `r` over the truth's 1.
    let sums = |se: f64, ss: f64, m: f64, sd: f64, r: f64| ClassSums {
        pixels: 100,
        squared_error: se,
        ssim_sum: 100.0 * ss,
        gms_weight: 100.0,
        gms_deficit: 100.0 * m,
        gms_deficit_squares: 100.0 * (sd * sd + m * m),
        render_gradient_energy: 100.0 * r,
        truth_gradient_energy: 100.0,
        consistency: None,
    };
    let pool = |mismatched: Option<u32>| {
        let mut pool = Vec::new();
        for seed in 0..16u32 {
            let e = 0.001 * f64::from(seed);
            let mut full = sample("full", seed, 8, 20.0);
            full.scene_sha256 = format!("{seed:064}");
            let mut c = sample("conflicting_views", seed, 8, 20.0);
            c.scene_sha256 = format!("{:064}", seed + 100);
            // On contested pixels the variant averaged two generations: less squared error
            // (PSNR rewards it), a larger GMSD and less detail; on uncontested pixels the
            // two runs differ by noise only.
            let noise = if seed % 2 == 0 { e } else { -e };
            let reference_scene = if mismatched == Some(seed) {
                "another scene".into()
            } else {
                full.scene_sha256.clone()
            };
            c.pair = Some(Pair {
                reference: "full".into(),
                reference_scene,
                views: vec![PairView {
                    view: "v".into(),
                    contested: [
                        sums(3.0, 0.6, 0.1, 0.05, 1.0),
                        sums(2.0 + e, 0.6 - e, 0.1, 0.15 + e, 0.9 - e),
                    ],
                    uncontested: [
                        sums(1.0, 0.8, 0.1, 0.05, 1.01),
                        sums(1.0, 0.8, 0.1, 0.05 + noise, 1.01 + noise),
                    ],
                }],
            });
            // Each run's scene against its own generations: the variant's cannot reproduce
            // both of two disagreeing ones.
            let fidelity = |se: f64| {
                serde_json::from_value(serde_json::json!({
                    "candidates": 4, "covered": 0, "set_aside": [], "collisions": 2, "pairs": 6,
                    "stage1_views": ["a", "b"], "stage1_collisions": 0, "dependent_per_gap": [1],
                    "interpolated": 0, "degenerate_gaps": 0, "stage1": null, "stage2_filled": 0.1,
                    "fidelity": [{"view": "a",
                                  "contested": {"pixels": 50, "squared_error": se, "ssim_sum": 40.0},
                                  "uncontested": {"pixels": 50, "squared_error": se, "ssim_sum": 40.0}}]
                }))
                .unwrap()
            };
            full.diagnostics = Some(fidelity(0.3));
            c.diagnostics = Some(fidelity(0.6 + e));
            pool.extend([full, c]);
        }
        pool
    };
    // A pair that scored another scene than the pool's full run is no Δ: the claim waits
    // for that seed.
    let v = verdicts(&cfg, &pool(Some(15)), &Rule::default());
    let id = "conflicts cost at equal coverage, detail contested";
    let primary = v.iter().find(|v| v.claim.id == id).unwrap();
    assert_eq!(primary.verdict, "interim (15 of 16 seeds)", "{primary:?}");
    // A seed where the variant's views generated no point twice: nowhere for conflicts to
    // act, so counted towards the plan and not as a unit.
    let mut none_contested = pool(None);
    for r in none_contested
        .iter_mut()
        .filter(|r| r.seed == 3 && r.pair.is_some())
    {
        for v in &mut r.pair.as_mut().unwrap().views {
            v.contested = Default::default();
        }
    }
    let v = verdicts(&cfg, &none_contested, &Rule::default());
    let primary = v.iter().find(|v| v.claim.id == id).unwrap();
    assert_eq!(
        (primary.judged, primary.same_computation),
        (15, 1),
        "{primary:?}"
    );
    assert!(
        primary.verdict.contains("not tested on 1 of 16 seeds")
            && primary.verdict.contains("no contested pixel"),
        "{primary:?}"
    );
    let v = verdicts(&cfg, &pool(None), &Rule::default());
    let find = |id: &str| {
        v.iter()
            .find(|v| v.claim.id == id)
            .unwrap_or_else(|| panic!("{id}: {v:#?}"))
    };
    let primary = find("conflicts cost at equal coverage, detail contested");
    assert_eq!(primary.family, "truth-classes");
    // Every seed full closer to 1 by −ln(0.9 − e): the median of 16, the mean of seeds 7
    // and 8's.
    assert_eq!(
        (primary.judged, primary.above, primary.below),
        (16, 16, 0),
        "{primary:?}"
    );
    assert!(primary.verdict.starts_with("holds"), "{primary:?}");
    let want = -0.5 * (0.893f64.ln() + 0.892f64.ln());
    assert!((primary.median_diff - want).abs() < 1e-12, "{primary:?}");
    let null = find("conflicts cost at equal coverage, detail uncontested");
    assert_eq!(null.family, "truth-classes");
    assert!(null.verdict.starts_with("inconclusive"), "{null:?}");
    let psnr = find("conflicts cost at equal coverage, PSNR contested");
    assert_eq!(psnr.family, "truth-panel");
    assert!(psnr.verdict.starts_with("contradicted"), "{psnr:?}");
    // The median of 16 is the mean of seeds 7 and 8's Δ.
    let at = |e: f64| -10.0 * (3.0f64 / 300.0).log10() + 10.0 * ((2.0 + e) / 300.0).log10();
    let want = 0.5 * (at(0.007) + at(0.008));
    assert!((psnr.median_diff - want).abs() < 1e-12, "{psnr:?}");
    // GMSD, lower better: Δ = variant − full = 0.1 + e, in the secondary family.
    let gmsd = find("conflicts cost at equal coverage, GMSD contested");
    assert_eq!(gmsd.family, "truth-panel");
    assert!(gmsd.verdict.starts_with("holds"), "{gmsd:?}");
    assert!((gmsd.median_diff - 0.1075).abs() < 1e-9, "{gmsd:?}");
    // Fidelity: 10·log10 of the squared-error ratio, full better.
    let fid = find("conflicts cost at equal coverage, fidelity to own generations");
    assert_eq!(fid.family, "truth-panel");
    let want = 0.5 * (10.0 * (0.607f64 / 0.3).log10() + 10.0 * (0.608f64 / 0.3).log10());
    assert!((fid.median_diff - want).abs() < 1e-12, "{fid:?}");
    assert!(fid.verdict.starts_with("holds"), "{fid:?}");
    let did = find("conflicts cost at equal coverage, detail contested − uncontested");
    assert!(did.verdict.starts_with("holds"), "{did:?}");
    // The primary holds while PSNR on the same pixels is contradicted: the panel splits.
    let split = primary.panel_splits.as_deref().expect("split flagged");
    assert!(
        split.contains("PSNR contested") && split.contains("contradicted"),
        "{split}"
    );
    assert!(
        !split.contains("GMSD") && !split.contains("detail"),
        "{split}"
    );
    // The paper's claim is judged as before, in its own family.
    let paper = find("conflicts cost at equal coverage");
    assert_eq!(paper.family, "truth");
    assert!(
        paper.verdict.starts_with("no verdict"),
        "Δ = 0 on every seed: {paper:?}"
    );
    // Orientation of each measure.
    assert_eq!(Measure::Gmsd.better(0.1, 0.25), 0.15);
    assert_eq!(Measure::Psnr.better(21.0, 20.0), 1.0);
    assert!((Measure::Detail.better(2.0, 0.25) - (4f64.ln() - 2f64.ln())).abs() < 1e-15);
    assert!(
        v.iter().filter(|v| v.family == "truth-panel").count() == 11,
        "{v:#?}"
    );

    // Pairs recorded before multi-view consistency have no record: its claims skip them.
    assert!(
        !v.iter()
            .any(|v| v.claim.id.contains("multi-view consistency")),
        "{v:#?}"
    );
    // Recorded: each run's renders agree with their neighbours' to `se` on 100 pixels; the
    // variant's less on contested pixels. A seed whose contested pixels no neighbour sees
    // on one surface is nowhere to act.
    let with_consistency = |blind: Option<u32>| {
        let mut pool = pool(None);
        for r in pool.iter_mut().filter(|r| r.pair.is_some()) {
            let (seed, e) = (r.seed, 0.001 * f64::from(r.seed));
            for v in &mut r.pair.as_mut().unwrap().views {
                let c = |pixels: u64, squared_error: f64| {
                    Some(unseen::pipeline::evaluate::Consistency {
                        pixels,
                        squared_error,
                    })
                };
                let contested = if blind == Some(seed) { 0 } else { 100 };
                v.contested[0].consistency = c(contested, 0.3);
                v.contested[1].consistency = c(contested, 0.6 + e);
                v.uncontested[0].consistency = c(100, 0.3);
                v.uncontested[1].consistency = c(100, 0.3 + if seed % 2 == 0 { e } else { -e });
            }
        }
        pool
    };
    let v = verdicts(&cfg, &with_consistency(None), &Rule::default());
    let mvc = |v: &[unseen::audit::Verdict], id: &str| {
        v.iter()
            .find(|v| {
                v.claim.id
                    == format!("conflicts cost at equal coverage, multi-view consistency {id}")
            })
            .cloned()
            .unwrap_or_else(|| panic!("{id}: {v:#?}"))
    };
    let contested = mvc(&v, "contested");
    assert_eq!(contested.family, "truth-panel");
    let want = 0.5 * (10.0 * (0.607f64 / 0.3).log10() + 10.0 * (0.608f64 / 0.3).log10());
    assert!(
        (contested.median_diff - want).abs() < 1e-12,
        "{contested:?}"
    );
    assert!(contested.verdict.starts_with("holds"), "{contested:?}");
    assert!(mvc(&v, "uncontested").verdict.starts_with("inconclusive"));
    assert_eq!(v.iter().filter(|v| v.family == "truth-panel").count(), 14);
    let v = verdicts(&cfg, &with_consistency(Some(3)), &Rule::default());
    let contested = mvc(&v, "contested");
    assert_eq!(
        (contested.judged, contested.same_computation),
        (15, 1),
        "{contested:?}"
    );
    // Each run decides what its own renders see: none on the full run's side is nowhere
    // to act as well (not a planned seed without a Δ, which would keep it interim).
    let mut blind_full = with_consistency(None);
    for r in blind_full.iter_mut().filter(|r| r.seed == 5) {
        for v in r.pair.iter_mut().flat_map(|p| &mut p.views) {
            v.contested[0].consistency = Some(Default::default());
        }
    }
    let contested = mvc(&verdicts(&cfg, &blind_full, &Rule::default()), "contested");
    assert_eq!(
        (contested.judged, contested.same_computation),
        (15, 1),
        "{contested:?}"
    );

    // The report: its own section with each metric's unit, the split, the names in JSON.
    let lounge = reference("scenes/lounge");
    let tmp = TempDir::new("panel-report");
    let mut samples = unseen::audit::samples::Samples::new(unseen::audit::samples::Provenance {
        dataset: "lounge".into(),
        dataset_digest: unseen::audit::samples::dataset_digest(&lounge).unwrap(),
        preset: cfg.base.preset,
        train_iterations: cfg.train_iterations,
        train_resolution: cfg.train_resolution,
        candidates: None,
    });
    for r in pool(None) {
        samples.insert(r);
    }
    samples
        .write(&tmp.join(unseen::audit::samples::SAMPLES_FILE))
        .unwrap();
    unseen::audit::Audit::new(&cfg, &lounge, &tmp)
        .unwrap()
        .report(&[])
        .unwrap();
    let md = std::fs::read_to_string(tmp.join("audit.md")).unwrap();
    let section = md
        .split("## Where conflicts act")
        .nth(1)
        .expect("the panel's section");
    assert!(
        section.contains("| conflicting_views | **detail ratio contested** | truth-low | truth-classes | 16 | +0.1137 | 16 / 0 |"),
        "{section}"
    );
    assert!(
        section.contains("PSNR contested -1.74 dB (contradicted)"),
        "{section}"
    );
    let claims = md
        .split("## Claims")
        .nth(1)
        .unwrap()
        .split("## ")
        .next()
        .unwrap();
    assert!(
        !claims.contains("GMSD"),
        "the paper's table holds its claims only: {claims}"
    );
    let json = std::fs::read_to_string(tmp.join("audit.json")).unwrap();
    assert!(json.contains("\"metric\": \"detail_contested\""), "{json}");
    assert!(json.contains("\"metric\": \"psnr_diff_in_diff\""), "{json}");
}

/// A dose–response sweep (SPEC.md §21.6): each level is a generator judged as any other
/// (Holm within the sweep), and the response of a claim whose Δ falls with the level
/// crosses 0 between the levels around the sign change, with a plot.
#[test]
fn a_sweep_gives_each_claim_its_response_and_crossing() {
    use unseen::audit::dose::{DoseParam, plot, plot_name, responses};
    use unseen::audit::{AuditConfig, GeneratorKind, Variant, stats::Rule, verdicts};
    let levels = [0u8, 25, 50, 75, 100];
    let cfg = AuditConfig {
        variants: vec![Variant::Full, Variant::EvenViews],
        generators: levels
            .iter()
            .map(|&percent| GeneratorKind::Dose {
                param: DoseParam::Hallucination,
                percent,
            })
            .collect(),
        ..AuditConfig::quick()
    };
    let mut pool = Vec::new();
    for &g in &cfg.generators {
        let GeneratorKind::Dose { percent, .. } = g else {
            unreachable!()
        };
        // Δ = 1 − 4·level ± 0.1: +1 dB at none, −3 dB at full; crosses 0 at 0.25.
        for seed in 0..16u32 {
            let d = 1.0 - 4.0 * f64::from(percent) / 100.0 + 0.01 * f64::from(seed % 5) - 0.02;
            for (variant, psnr) in [("full", 20.0 + d), ("even_views", 20.0)] {
                let mut r = sample(variant, seed, 7, psnr);
                r.generator = g.name();
                r.config = cfg
                    .config_digest(g, variant.parse::<Variant>().unwrap())
                    .unwrap();
                pool.push(r);
            }
        }
    }
    let v = verdicts(&cfg, &pool, &Rule::default());
    let family: Vec<&str> = v.iter().map(|x| x.family.as_str()).collect();
    assert!(
        family.iter().all(|f| *f == "dose-hallucination"),
        "{family:?}"
    );
    let r = responses(&v);
    let views = r.iter().find(|r| r.claim == "independent views").unwrap();
    assert_eq!(views.levels.len(), 5);
    assert_eq!(views.levels[0].verdict, "holds");
    assert_eq!(views.levels[4].verdict, "contradicted");
    assert!((views.crossing - 0.25).abs() < 0.01, "{views:?}");
    let [lo, hi] = views.crossing_range;
    assert!(
        lo.unwrap() <= views.crossing && views.crossing <= hi.unwrap(),
        "{views:?}"
    );
    assert_eq!(plot_name(views), "dose-hallucination-independent-views.svg");
    let svg = plot(views);
    assert!(svg.starts_with("<svg") && svg.matches("<circle").count() == 5);
}

/// The sensitivity rows (SPEC.md §21.2): the independent-views claim under a choice the
/// paper leaves open compares `full` and `even_views` both under that choice, never with
/// the default `full`; every variant's name round-trips and sets its switches.
#[test]
fn sensitivity_rows_compare_full_and_even_views_under_the_same_choice() {
    use unseen::audit::{AuditConfig, GeneratorKind, Variant, stats::Rule, verdicts};
    use unseen::collide::frustum::Outline;
    use unseen::pipeline::selection::SelectionRule;
    // Every variant is named once, round-trips, and is in exactly one of the lists.
    let listed: Vec<Variant> = Variant::PRESET
        .into_iter()
        .chain(Variant::SENSITIVITY)
        .chain(Variant::CONTROLS)
        .collect();
    assert_eq!(listed, Variant::ALL);
    for v in Variant::ALL {
        assert_eq!(v.name().parse::<Variant>().unwrap(), v);
    }
    assert!(
        "nope"
            .parse::<Variant>()
            .unwrap_err()
            .to_string()
            .contains("unknown variant 'nope'")
    );
    let g = GeneratorKind::Truth(unseen::pipeline::Level::Low);
    let cfg = AuditConfig {
        variants: vec![
            Variant::Full,
            Variant::EvenViews,
            Variant::FullMaxCardinality,
            Variant::EvenViewsMaxCardinality,
            Variant::FullHull,
        ],
        generators: vec![g],
        ..AuditConfig::quick()
    };
    let pc = |v| cfg.pipeline_config(g, v, 0).unwrap();
    let even = pc(Variant::EvenViewsMaxCardinality);
    assert!(!even.independent_detection && even.selection == SelectionRule::MaxCardinality);
    assert_eq!(pc(Variant::FullHull).frustum_outline, Outline::Hull);
    assert!(pc(Variant::FullHull).independent_detection);
    // Default full 1 dB above its even views, max-cardinality full 1 dB below its own.
    let mut pool = Vec::new();
    for seed in 0..16u32 {
        let jitter = 0.01 * f64::from(seed);
        for (v, psnr) in [
            (Variant::Full, 21.0 + jitter),
            (Variant::EvenViews, 20.0),
            (Variant::FullMaxCardinality, 19.0 + jitter),
            (Variant::EvenViewsMaxCardinality, 20.0),
            (Variant::FullHull, 20.0),
        ] {
            let mut r = sample(v.name(), seed, 7, psnr);
            r.config = cfg.config_digest(g, v).unwrap();
            pool.push(r);
        }
    }
    let v = verdicts(&cfg, &pool, &Rule::default());
    let of = |id: &str| v.iter().find(|x| x.claim.id == id).unwrap().clone();
    assert_eq!(of("independent views").verdict, "holds");
    let sensitive = of("independent views (maximum-cardinality set)");
    assert_eq!(sensitive.verdict, "contradicted", "{sensitive:?}");
    assert!(sensitive.median_diff < -0.9);
    // The sensitivity rows are a Holm family of their own: the paper's claim gets the
    // p-value it gets without them.
    assert_eq!(
        (
            of("independent views").family.as_str(),
            sensitive.family.as_str()
        ),
        ("truth", "truth-sensitivity")
    );
    let alone = AuditConfig {
        variants: vec![Variant::Full, Variant::EvenViews],
        ..cfg.clone()
    };
    let pool_alone: Vec<_> = pool
        .iter()
        .filter(|r| r.variant == "full" || r.variant == "even_views")
        .cloned()
        .collect();
    let v_alone = verdicts(&alone, &pool_alone, &Rule::default());
    assert_eq!(
        v_alone[0].p_holm.to_bits(),
        of("independent views").p_holm.to_bits()
    );
    // The hull row needs its even views: not run, no row.
    assert!(
        !v.iter()
            .any(|x| x.claim.id == "independent views (hull frustums)")
    );
}

/// The verdicts of pooled samples (SPEC.md §21.2): a unit is a seed at a revision, a pair
/// another revision reproduced bit for bit counts once, a claim below its planned sample is
/// an interim look (the lounge case of the old rule, −0.68 ± 0.45 dB over 3 seeds, is no
/// longer *holds*), a "does not hurt" claim is tested against the margin and a loss beyond
/// it that the planned twelve units show is *contradicted*, seeds beyond the plan are
/// judged nowhere, and identical differences give no verdict.
#[test]
fn audit_verdicts_pool_seeds_and_revisions_and_test_non_inferiority() {
    use unseen::audit::{AuditConfig, GeneratorKind, Variant, stats::Rule, verdicts};
    let cfg = AuditConfig {
        variants: vec![Variant::Full, Variant::NoQaMask],
        generators: vec![GeneratorKind::Truth(unseen::pipeline::Level::Low)],
        ..AuditConfig::quick()
    };
    let rule = Rule::default();
    let claim = |v: &[unseen::audit::Verdict], id: &str| {
        v.iter().find(|x| x.claim.id == id).unwrap().clone()
    };
    // Three seeds at revision 3, Δ = −0.2, −0.7, −1.15 (mean −0.68, sd 0.48).
    let mut pool = Vec::new();
    for (seed, d) in [(0, -0.2), (1, -0.7), (2, -1.15)] {
        pool.push(sample("full", seed, 3, 20.0 + d));
        pool.push(sample("no_qa_mask", seed, 3, 20.0));
    }
    let v = verdicts(&cfg, &pool, &rule);
    let ni = claim(&v, "QA-Mask does not hurt extrapolation");
    assert_eq!((ni.seeds, ni.judged, ni.null), (3, 3, -0.2));
    assert!((ni.mean_diff + 0.6833333).abs() < 1e-6, "{ni:?}");
    // (19.8 − 20 rounds to just above −0.2: that seed counts above the null value.)
    assert!(
        (ni.median_diff + 0.7).abs() < 1e-9 && ni.below == 2,
        "{ni:?}"
    );
    assert_eq!(ni.verdict, "interim (3 of 16 seeds)", "{ni:?}");
    // Three seeds cannot reach the family's Holm level (2/8 > 0.05/3): no interval of the
    // median, an infinite MDE.
    assert!(
        ni.ci.is_none() && ni.min_detectable == f64::INFINITY,
        "{ni:?}"
    );
    // The same three seeds recomputed at revision 4 with the same metrics bits (and the
    // per-view records revision 3 did not write): one draw each.
    let record = |psnr: f64| {
        let sums = unseen::pipeline::evaluate::ClassSums {
            pixels: 1,
            squared_error: 3.0 * 10f64.powf(-psnr / 10.0),
            ssim_sum: 0.5,
            ..Default::default()
        };
        unseen::pipeline::evaluate::ViewRecord {
            view: "v".into(),
            all: sums,
            existing: sums,
            extrapolated: sums,
        }
    };
    for (seed, d) in [(0, -0.2), (1, -0.7), (2, -1.15)] {
        for (variant, psnr) in [("full", 20.0 + d), ("no_qa_mask", 20.0)] {
            let mut s = sample(variant, seed, 4, psnr);
            s.last.views.push(record(psnr));
            pool.push(s);
        }
    }
    let again = claim(
        &verdicts(&cfg, &pool, &rule),
        "QA-Mask does not hurt extrapolation",
    );
    assert_eq!(
        (again.seeds, again.revisions.clone()),
        (3, vec![4]),
        "{again:?}"
    );
    // The draw kept is the one with the records: the views bootstrap runs on all three.
    assert_eq!(again.hierarchical_units, 3, "{again:?}");
    // Nine more seeds at revision 4 and four of the first seeds at revision 5 (other
    // bits: another draw of those seeds, averaged into them): twelve units, with a plan of
    // twelve a loss beyond the margin is contradicted. All with per-view records: the
    // hierarchical interval (from ten units) runs on the newest draw of each seed.
    let with_record = |variant: &str, seed: u32, revision: u32, psnr: f64| {
        let mut s = sample(variant, seed, revision, psnr);
        s.last.views.push(record(psnr));
        s
    };
    for seed in 3..12 {
        let d = -0.68 + 0.05 * (seed as f64 - 7.5);
        pool.push(with_record("full", seed, 4, 20.0 + d));
        pool.push(with_record("no_qa_mask", seed, 4, 20.0));
    }
    for seed in 0..4 {
        let d = -0.6 - 0.03 * seed as f64;
        pool.push(with_record("full", seed, 5, 20.1 + d));
        pool.push(with_record("no_qa_mask", seed, 5, 20.1));
    }
    // A revision that changed only one run of a pair gives no independent draw: seed 4 at
    // revision 5 shares its no_qa_mask run with revision 4's and is not counted.
    pool.push(sample("full", 4, 5, 19.0));
    pool.push(sample("no_qa_mask", 4, 5, 20.0));
    assert_eq!(
        claim(
            &verdicts(&cfg, &pool, &rule),
            "QA-Mask does not hurt extrapolation"
        )
        .verdict,
        "interim (12 of 16 seeds)"
    );
    let rule = Rule {
        planned: 12,
        ..Rule::default()
    };
    let v = verdicts(&cfg, &pool, &rule);
    let ni = claim(&v, "QA-Mask does not hurt extrapolation");
    assert_eq!((ni.seeds, ni.revisions.clone()), (12, vec![4, 5]), "{ni:?}");
    // Seed 0's unit is the mean of its two draws (−0.2 at revision 4, −0.6 at 5): the
    // twelve units' mean is the mean of the seed means.
    let pairs = unseen::audit::pairs(&pool, "truth-low", Variant::NoQaMask);
    let means = unseen::audit::seed_means(&pairs, unseen::audit::Metric::PsnrExtrapolated);
    assert_eq!(means.len(), 12);
    assert!((means[0] + 0.4).abs() < 1e-9, "{means:?}");
    assert!((ni.mean_diff - means.iter().sum::<f64>() / 12.0).abs() < 1e-12);
    assert_eq!(ni.method, Some(unseen::audit::stats::Method::Sign));
    // Eleven units with records (seed 4's draw kept is revision 5's, written without);
    // one view each, so the interval lies within the newest draws' differences.
    let [lo, hi] = ni.hierarchical.expect("eleven units");
    assert_eq!(ni.hierarchical_units, 11, "{ni:?}");
    assert!(-0.71 < lo && lo < hi && hi < -0.5, "{ni:?}");
    // Every unit below −0.2: p = 2·2⁻¹², ×3 by Holm.
    assert_eq!((ni.above, ni.below), (0, 12), "{ni:?}");
    assert!((ni.p_holm - 3.0 * 2.0 / 4096.0).abs() < 1e-15, "{ni:?}");
    assert_eq!(ni.verdict, "contradicted", "{ni:?}");
    // The three claims on no_qa_mask are one Holm family; the "better" claims see the
    // same loss and are contradicted too.
    for id in ["QA-Mask (whole image)", "QA-Mask protects existing regions"] {
        assert_eq!(claim(&v, id).verdict, "contradicted");
    }
    // Seeds beyond the plan are judged nowhere: eight more that gain 1 dB change nothing
    // but the count.
    let mut more = pool.clone();
    for seed in 12..20 {
        more.push(sample("full", seed, 4, 21.0));
        more.push(sample("no_qa_mask", seed, 4, 20.0));
    }
    let beyond = claim(
        &verdicts(&cfg, &more, &rule),
        "QA-Mask does not hurt extrapolation",
    );
    assert_eq!((beyond.seeds, beyond.judged), (20, 12));
    assert_eq!(
        (beyond.verdict.as_str(), beyond.p_holm, beyond.mean_diff),
        (ni.verdict.as_str(), ni.p_holm, ni.mean_diff)
    );
    // One seed: interim, no interval.
    let one = verdicts(&cfg, &pool[..2], &Rule::default());
    assert_eq!(one[0].verdict, "interim (1 of 16 seeds)");
    assert!(one[0].ci.is_none());
    // Twelve seeds whose runs agree bit for bit (Δ = 0), or differ by the same amount on
    // every seed: no verdict, whatever the plan.
    for (d, why) in [
        (
            0.0,
            "no verdict (Δ = 0 on every seed: the variant computes what full computes)",
        ),
        (
            0.5,
            "no verdict (the same Δ on every seed: one draw, not n)",
        ),
    ] {
        let same: Vec<_> = (0..12)
            .flat_map(|seed| {
                [
                    sample("full", seed, 4, 20.0 + d),
                    sample("no_qa_mask", seed, 4, 20.0),
                ]
            })
            .collect();
        let v: Vec<_> = verdicts(&cfg, &same, &rule)
            .into_iter()
            .filter(|x| x.claim.variant == Variant::NoQaMask)
            .collect();
        assert!(v.iter().all(|x| x.verdict == why), "{v:?}");
        assert!(
            v.iter()
                .all(|x| x.min_detectable.is_nan() && x.p_holm.is_nan())
        );
    }
}
