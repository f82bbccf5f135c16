//! Calibration of the audit's verdict rule (SPEC.md §21.2) by simulation: thousands of
//! audits drawn from known distributions of the per-seed paired difference, judged by the
//! rule, and the rates of false verdicts and of found effects compared with what the rule
//! states (α, power). The same harness shows that the two rules it replaced fail: the old
//! `m > 2·sd` rule and the inverted "does not hurt" rule.

use crate::suite::common::{TempDir, reference};
use unseen::pipeline::audit::stats::{ClaimData, Outcome, Rule, min_detectable_effect, t_power};
use unseen::rng::Uniform;

/// Simulated audits per scenario: the standard error of a 2.5 % rate is 0.25 %.
const AUDITS: usize = 4000;
/// A rate is "within simulation error" of its bound when it is within this many binomial
/// standard errors (one-sided; a false alarm of a correct rule in ~1 of 700 checks).
const SIGMAS: f64 = 3.0;

/// A rule under calibration: the outcomes of one family of claims.
type RuleFn<'a> = &'a dyn Fn(&[ClaimData]) -> Vec<Outcome>;

fn normal(u: &mut Uniform) -> f64 {
    // Box–Muller; 1 − unit is in (0, 1].
    let r = (-2.0 * (1.0 - u.unit_f64()).ln()).sqrt();
    r * (2.0 * std::f64::consts::PI * u.unit_f64()).cos()
}

/// Per-seed differences of one simulated audit.
#[derive(Clone, Copy, Debug)]
enum Shape {
    Normal,
    /// Student's t with 3 degrees of freedom, scaled to unit variance.
    HeavyTails,
    /// Normal, but one seed at ±6 sd (a crashed or diverged training), sign at random.
    OneOutlier,
}

fn draw(u: &mut Uniform, shape: Shape, n: usize, mean: f64, sd: f64) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let z = match shape {
                Shape::Normal => normal(u),
                Shape::HeavyTails => {
                    let chi2: f64 = (0..3).map(|_| normal(u).powi(2)).sum();
                    normal(u) / (chi2 / 3.0).sqrt() / 3f64.sqrt()
                }
                Shape::OneOutlier if i == 0 => {
                    if u.unit_f64() < 0.5 {
                        6.0
                    } else {
                        -6.0
                    }
                }
                Shape::OneOutlier => normal(u),
            };
            mean + sd * z
        })
        .collect()
}

/// Rates of (holds, contradicted) of a single claim with null value `null` over
/// [`AUDITS`] audits of `n` seeds.
fn rates(
    rule: RuleFn,
    shape: Shape,
    n: usize,
    mean: f64,
    sd: f64,
    null: f64,
    seed: u64,
) -> (f64, f64) {
    let mut u = Uniform::new(seed);
    let (mut holds, mut contradicted) = (0usize, 0usize);
    for k in 0..AUDITS {
        let d = draw(&mut u, shape, n, mean, sd);
        let c = ClaimData {
            diffs: &d,
            null,
            seed: k as u64,
        };
        match rule(&[c])[0] {
            Outcome::Holds => holds += 1,
            Outcome::Contradicted => contradicted += 1,
            Outcome::Inconclusive => {}
        }
    }
    (
        holds as f64 / AUDITS as f64,
        contradicted as f64 / AUDITS as f64,
    )
}

fn se(p: f64) -> f64 {
    (p * (1.0 - p) / AUDITS as f64).sqrt()
}

/// Claims of the differences `d` with null value 0, seeded from audit `k`.
fn family(d: &[Vec<f64>], k: usize) -> Vec<ClaimData<'_>> {
    d.iter()
        .enumerate()
        .map(|(i, d)| ClaimData {
            diffs: d,
            null: 0.0,
            seed: (k * d.len() + i) as u64,
        })
        .collect()
}

/// Every calibration check the rule fails, in words.
fn calibrate(rule: RuleFn) -> Vec<String> {
    let r = Rule::default();
    let tail = r.alpha / 2.0;
    let mut fails = Vec::new();
    let at_most = |fails: &mut Vec<String>, what: String, rate: f64, bound: f64| {
        if rate > bound + SIGMAS * se(bound) {
            fails.push(format!(
                "{what}: {:.2} % > {:.2} %",
                100.0 * rate,
                100.0 * bound
            ));
        }
    };
    // No effect: each false verdict at most α/2 (the two sides of a two-sided test).
    for (shape, ns) in [
        (Shape::Normal, &[3usize, 5, 8, 10, 12, 20][..]),
        (Shape::HeavyTails, &[5, 12, 20][..]),
        (Shape::OneOutlier, &[5, 12][..]),
    ] {
        for &n in ns {
            let (h, c) = rates(rule, shape, n, 0.0, 0.33, 0.0, 11 + n as u64);
            at_most(
                &mut fails,
                format!("false holds, {shape:?}, n = {n}"),
                h,
                tail,
            );
            at_most(
                &mut fails,
                format!("false contradicted, {shape:?}, n = {n}"),
                c,
                tail,
            );
        }
    }
    // "Does not hurt" at the margin's edge (the variant better by exactly the margin) and
    // well beyond it (the lounge case: −0.68 ± 0.45 dB over 3 seeds): holds at most α/2.
    for (n, mean, sd) in [
        (4, -r.margin, 0.33),
        (12, -r.margin, 0.33),
        (3, -0.68, 0.45),
    ] {
        let (h, _) = rates(rule, Shape::Normal, n, mean, sd, -r.margin, 29 + n as u64);
        at_most(
            &mut fails,
            format!("false non-inferiority, Δ = {mean} dB, sd {sd}, n = {n}"),
            h,
            tail,
        );
    }
    // The stated power: an effect of the minimum detectable size is found in `power` of
    // the audits, within simulation error on both sides for the t test alone (n < 10);
    // from 10 seeds the bootstrap must agree too, which can only lower it, so there only
    // the lower side is checked; effects of k·sd as the noncentral t predicts.
    for n in [3usize, 6, 12, 20] {
        let mde = min_detectable_effect(n, 0.33, r.alpha, r.power);
        let (h, _) = rates(rule, Shape::Normal, n, mde, 0.33, 0.0, 47 + n as u64);
        let lo = r.power - SIGMAS * se(r.power);
        let hi = r.power + SIGMAS * se(r.power);
        if h < lo || (n < r.bootstrap_from && h > hi) {
            fails.push(format!(
                "power at the minimum detectable effect {mde:.3} dB, n = {n}: {:.1} %, stated {:.0} %",
                100.0 * h,
                100.0 * r.power
            ));
        }
    }
    for k in [0.5, 1.0] {
        let n = 6;
        let want = t_power(n, k * (n as f64).sqrt(), r.alpha);
        let (h, _) = rates(rule, Shape::Normal, n, k * 0.33, 0.33, 0.0, 61);
        if (h - want).abs() > SIGMAS * se(want) {
            fails.push(format!(
                "power at Δ = {k} sd, n = {n}: {:.1} %, noncentral t {:.1} %",
                100.0 * h,
                100.0 * want
            ));
        }
    }
    // Large effects are found however skewed: eleven claims of Δ = 1 dB with one low
    // seed each (a left-skewed spread, t ≈ 9–30) in a family of 11 at n = 12 all hold
    // in every audit — a bootstrap p-value with a floor near 1/B would hold none at the
    // family's first Holm level.
    let mut u = Uniform::new(83);
    let mut missed = 0usize;
    for k in 0..200 {
        let d: Vec<Vec<f64>> = (0..11)
            .map(|_| {
                let mut d = draw(&mut u, Shape::Normal, 12, 1.0, 0.05);
                d[0] = 0.3 + 0.1 * u.unit_f64();
                d
            })
            .collect();
        let family = family(&d, k);
        missed += rule(&family)
            .iter()
            .filter(|o| **o != Outcome::Holds)
            .count();
    }
    if missed > 0 {
        fails.push(format!(
            "large skewed effects: {missed} of 2200 claims not found"
        ));
    }
    // A family of eleven claims with no effect: any false verdict at most α (Holm).
    let mut u = Uniform::new(71);
    let mut any = 0usize;
    for k in 0..AUDITS {
        let d: Vec<Vec<f64>> = (0..11)
            .map(|_| draw(&mut u, Shape::Normal, 12, 0.0, 0.33))
            .collect();
        let family = family(&d, k);
        if rule(&family).iter().any(|o| *o != Outcome::Inconclusive) {
            any += 1;
        }
    }
    at_most(
        &mut fails,
        "family-wise false verdicts, 11 claims, n = 12".into(),
        any as f64 / AUDITS as f64,
        r.alpha,
    );
    fails
}

/// The rule as the audit applies it, with fewer bootstrap replicates (the simulation
/// draws 4 000 audits per scenario; replicates move an interval's end by Monte Carlo
/// noise, not its calibration).
fn current(family: &[ClaimData]) -> Vec<Outcome> {
    let rule = Rule {
        replicates: 2000,
        ..Rule::default()
    };
    rule.judge(family).iter().map(|j| j.outcome).collect()
}

/// The rule of SPEC.md §21.2 before: `m > 2·sd` holds, `m < −2·sd` does not hold; "does
/// not hurt" holds unless `m < −2·sd`; no correction for multiplicity.
fn two_sd(family: &[ClaimData]) -> Vec<Outcome> {
    family
        .iter()
        .map(|c| {
            let n = c.diffs.len() as f64;
            let m = c.diffs.iter().sum::<f64>() / n;
            let sd = (c.diffs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            let does_not_hurt = c.null < 0.0;
            if m < -2.0 * sd {
                Outcome::Contradicted
            } else if does_not_hurt || m > 2.0 * sd {
                Outcome::Holds
            } else {
                Outcome::Inconclusive
            }
        })
        .collect()
}

/// Today's intervals with the inverted "does not hurt": it holds unless the loss beyond the
/// margin is significant.
fn inverted_non_inferiority(family: &[ClaimData]) -> Vec<Outcome> {
    let out = current(family);
    family
        .iter()
        .zip(out)
        .map(|(c, o)| match o {
            Outcome::Inconclusive if c.null < 0.0 => Outcome::Holds,
            o => o,
        })
        .collect()
}

#[test]
fn audit_rule_is_calibrated_and_the_rules_it_replaced_are_not() {
    let fails = calibrate(&current);
    assert!(fails.is_empty(), "the audit's rule: {fails:#?}");
    let old = calibrate(&two_sd);
    assert!(
        old.iter()
            .any(|f| f.starts_with("false holds, Normal, n = 3"))
            && old
                .iter()
                .any(|f| f.starts_with("power at the minimum detectable")),
        "the 2·sd rule should fail on false holds with 3 seeds and on power: {old:#?}"
    );
    let inverted = calibrate(&inverted_non_inferiority);
    assert!(
        inverted
            .iter()
            .any(|f| f.starts_with("false non-inferiority")),
        "the inverted rule should fail on non-inferiority: {inverted:#?}"
    );
    // The failures, for the record (`cargo test -- --nocapture`).
    println!("2·sd rule fails: {old:#?}\ninverted non-inferiority fails: {inverted:#?}");
}

/// The committed audits of the paper's mechanisms (`reference_data/audit/<room>-mechanisms/`)
/// are what this code judges from their samples: `audit.json` and `inconsistency.svg`
/// re-made from the committed `samples.json` alone (no job runs) are byte-identical to the
/// committed ones (`audit.md` also reports the last batch's step-cache savings, which only
/// a batch that ran knows), every sample is of this binary's configuration,
/// and both rooms hold their planned 16 seeds. A change to the statistics, the report or a
/// variant's configuration shows here first (then rerun the batches or say why the
/// committed verdicts still stand).
#[test]
fn committed_mechanisms_audits_follow_from_their_samples() {
    use unseen::pipeline::audit::{self, AuditConfig, GeneratorKind, Variant};
    for room in ["lounge", "gallery"] {
        let committed = reference(&format!("audit/{room}-mechanisms"));
        let dataset = reference(&format!("scenes/{room}"));
        let tmp = TempDir::new(&format!("mechanisms-{room}"));
        std::fs::copy(committed.join("samples.json"), tmp.join("samples.json")).unwrap();
        let mut cfg = AuditConfig::preset(unseen::pipeline::Preset::Quick);
        cfg.variants = [
            "full",
            "even_views",
            "no_depth_supervision",
            "stage2_render_fit",
        ]
        .map(|v| Variant::by_name(v).unwrap())
        .to_vec();
        cfg.generators = ["classical", "truth-low", "truth-low+hallucinating+relative"]
            .map(|g| GeneratorKind::by_name(g).unwrap())
            .to_vec();
        let report = audit::report(&cfg, &dataset, &tmp, &[]).unwrap();
        assert_eq!(report.seeds, (0..16).collect::<Vec<u32>>(), "{room}");
        assert_eq!(
            report.other_config, 0,
            "{room}: samples of another configuration"
        );
        for file in ["audit.json", "inconsistency.svg"] {
            let want = std::fs::read_to_string(committed.join(file)).unwrap();
            let got = std::fs::read_to_string(tmp.join(file)).unwrap();
            assert!(
                got == want,
                "{room}/{file} differs from what its samples give"
            );
        }
    }
}
