//! The statistics of the audit's verdicts (SPEC.md §21.2): the sign test of a median
//! paired difference over seeds (exact for every distribution, from the binomial tail), its
//! distribution-free interval, Holm's step-down correction within a family of claims, the
//! planned sample that separates verdicts from interim looks, and the minimum shift a test
//! detects with a given power. Also Student's t and the normal distribution (the rule the
//! sign test replaced, and the quantile the power needs).
//!
//! Written from the definitions: the t distribution's CDF by its finite trigonometric
//! series for integer degrees of freedom (Abramowitz & Stegun 26.7.3–4), the normal CDF by
//! the error function's series and continued fraction (A&S 7.1.6, 7.1.14), the sign test
//! and its order-statistic interval (Conover, "Practical Nonparametric Statistics", 3rd
//! ed., §3.4), Holm (1979, "A simple sequentially rejective multiple test procedure",
//! Scand. J. Statist. 6:65). Single-threaded, so the same bits for any thread count.
use std::f64::consts::{FRAC_2_SQRT_PI, PI};

/// `P(T ≤ t)` for Student's t with `df ≥ 1` degrees of freedom.
pub fn student_t_cdf(t: f64, df: u32) -> f64 {
    assert!(df >= 1, "t needs at least one degree of freedom");
    if t.is_nan() {
        return f64::NAN;
    }
    if t.is_infinite() {
        return if t > 0.0 { 1.0 } else { 0.0 };
    }
    // A(|t|) = P(|T| < |t|) by A&S 26.7.3 (odd df) / 26.7.4 (even df), θ = atan(|t|/√ν).
    let nu = df as f64;
    let theta = (t.abs() / nu.sqrt()).atan();
    let (s, c) = theta.sin_cos();
    let c2 = c * c;
    let a = if !df.is_multiple_of(2) {
        // (2/π)[θ + sinθ(cosθ + (2/3)cos³θ + … + (2·4···(ν−3))/(1·3···(ν−2))cos^(ν−2)θ)]
        let mut sum = 0.0;
        if df > 1 {
            let mut term = c;
            sum = c;
            let mut k = 1u32;
            while k + 2 < df {
                term *= c2 * (k + 1) as f64 / (k + 2) as f64;
                sum += term;
                k += 2;
            }
        }
        2.0 / PI * (theta + s * sum)
    } else {
        // sinθ[1 + (1/2)cos²θ + (1·3)/(2·4)cos⁴θ + … + (1·3···(ν−3))/(2·4···(ν−2))cos^(ν−2)θ]
        let mut term = 1.0;
        let mut sum = 1.0;
        let mut k = 0u32;
        while k + 2 < df {
            term *= c2 * (k + 1) as f64 / (k + 2) as f64;
            sum += term;
            k += 2;
        }
        s * sum
    };
    let a = a.clamp(0.0, 1.0);
    if t >= 0.0 {
        0.5 + 0.5 * a
    } else {
        0.5 - 0.5 * a
    }
}

/// The `p`-quantile of Student's t with `df` degrees of freedom (`0 < p < 1`), by
/// bisection on [`student_t_cdf`] to the last representable step.
pub fn student_t_quantile(p: f64, df: u32) -> f64 {
    assert!(p > 0.0 && p < 1.0, "a quantile needs 0 < p < 1");
    if p == 0.5 {
        return 0.0;
    }
    // The upper tail's quantile, by symmetry.
    let q = p.max(1.0 - p);
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    while student_t_cdf(hi, df) < q {
        hi *= 2.0;
    }
    loop {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if student_t_cdf(mid, df) < q {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let x = 0.5 * (lo + hi);
    if p > 0.5 { x } else { -x }
}

/// The complementary error function, |relative error| ≲ 1e-13: the positive series
/// `erf x = (2/√π) e^(−x²) Σ 2ⁿ x^(2n+1) / (1·3···(2n+1))` (A&S 7.1.6) below 1, the
/// continued fraction of A&S 7.1.14 from 1 (where `1 − erf` would lose digits; ≤ 200
/// terms there).
pub fn erfc(x: f64) -> f64 {
    if x.is_nan() {
        return f64::NAN;
    }
    if x == f64::INFINITY {
        return 0.0;
    }
    if x < 0.0 {
        return 2.0 - erfc(-x);
    }
    if x < 1.0 {
        let x2 = x * x;
        let (mut term, mut sum) = (x, x);
        let mut k = 0.0;
        loop {
            k += 1.0;
            term *= 2.0 * x2 / (2.0 * k + 1.0);
            sum += term;
            if term <= sum * 1e-17 {
                break;
            }
        }
        return 1.0 - FRAC_2_SQRT_PI * (-x2).exp() * sum;
    }
    // erfc x = e^(−x²)/√π · 1/(x + (1/2)/(x + 1/(x + (3/2)/(x + 2/(x + …))))), by Lentz's
    // method on the fraction b₀ = x, aₖ = k/2, bₖ = x.
    let tiny = 1e-300;
    let mut f = x;
    let (mut c, mut d) = (x, 0.0);
    for k in 1..500 {
        let a = k as f64 / 2.0;
        d = x + a * d;
        if d.abs() < tiny {
            d = tiny;
        }
        c = x + a / c;
        if c.abs() < tiny {
            c = tiny;
        }
        d = 1.0 / d;
        let delta = c * d;
        f *= delta;
        if (delta - 1.0).abs() < 1e-16 {
            break;
        }
    }
    (-x * x).exp() / (PI.sqrt() * f)
}

/// The standard normal CDF Φ.
pub fn normal_cdf(x: f64) -> f64 {
    0.5 * erfc(-x / std::f64::consts::SQRT_2)
}

/// The standard normal density φ.
fn normal_pdf(x: f64) -> f64 {
    (-0.5 * x * x).exp() / (2.0 * PI).sqrt()
}

/// Φ⁻¹(p) for `0 < p < 1`: safeguarded Newton on [`normal_cdf`] inside a bisection
/// bracket.
pub fn normal_quantile(p: f64) -> f64 {
    assert!(p > 0.0 && p < 1.0, "a quantile needs 0 < p < 1");
    // Start in the right tail region: |x| ≈ √(−2 ln min(p, 1 − p)) (Newton from 0 would
    // crawl into a far tail in steps of ~1/|x|).
    let tail = p.min(1.0 - p);
    let start = if tail < 0.1 {
        (-2.0 * tail.ln()).sqrt().copysign(p - 0.5)
    } else {
        0.0
    };
    let (mut lo, mut hi, mut x) = (-40.0f64, 40.0f64, start);
    for _ in 0..200 {
        let f = normal_cdf(x) - p;
        if f == 0.0 {
            break;
        }
        if f < 0.0 {
            lo = x;
        } else {
            hi = x;
        }
        let mut next = x - f / normal_pdf(x);
        if !(next > lo && next < hi) {
            next = 0.5 * (lo + hi);
        }
        if next == x || hi - lo <= f64::EPSILON * x.abs().max(1e-300) {
            break;
        }
        x = next;
    }
    x
}

/// `ln C(n, k)`, summed exactly enough for `n` up to millions (`Σ ln((n − j)/(j + 1))`
/// over the shorter side).
fn ln_choose(n: usize, k: usize) -> f64 {
    let k = k.min(n - k);
    (0..k).map(|j| ((n - j) as f64 / (j + 1) as f64).ln()).sum()
}

/// `P(X ≥ k)` for `X ~ Binomial(n, p)`, `0 ≤ p ≤ 1`: the terms `ln P(X = j)` by the
/// recurrence `+ ln((n − j)/(j + 1)) + ln(p/(1 − p))` from `j = k` (O(n)), summed relative
/// to the largest (no underflow of `pⁿ` for large n). Relative error ≲ 1e-13 for n ≤ 16,
/// growing like n·ε (≈ 1e-11 at n = 20 000: the recurrence's rounding).
pub fn binomial_upper_tail(n: usize, k: usize, p: f64) -> f64 {
    if k == 0 {
        return 1.0;
    }
    if k > n || p <= 0.0 || p.is_nan() {
        return 0.0;
    }
    if p >= 1.0 {
        return 1.0;
    }
    let (lp, lq) = (p.ln(), (-p).ln_1p());
    let mut t = ln_choose(n, k) + k as f64 * lp + (n - k) as f64 * lq;
    let mut terms = Vec::with_capacity(n - k + 1);
    for j in k..=n {
        terms.push(t);
        if j < n {
            t += ((n - j) as f64 / (j + 1) as f64).ln() + lp - lq;
        }
    }
    let top = terms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let sum: f64 = terms.iter().map(|t| (t - top).exp()).sum();
    (top + sum.ln()).exp().min(1.0)
}

/// What a test's p-values come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The sign test of the median: `#{d > θ₀}` against Binomial(n, ½), exact for every
    /// distribution of the differences (SPEC.md §21.2).
    Sign,
}

/// The test of the median paired difference against a null value.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Test {
    pub n: usize,
    pub median: f64,
    pub mean: f64,
    /// Sample standard deviation (n − 1).
    pub sd: f64,
    pub method: Method,
    /// Differences above and below the null value (the rest equal it).
    pub above: usize,
    pub below: usize,
    /// The distribution-free two-sided `1 − α` interval of the median, `[d₍ₖ₎, d₍ₙ₊₁₋ₖ₎]`
    /// (order statistics; coverage ≥ 1 − α for any continuous distribution); `None`
    /// below 6 differences, where no such k exists at α = 0.05.
    pub interval: Option<[f64; 2]>,
    /// One-sided p-values of the null value `θ₀`: `p_above` of H₀ "median ≤ θ₀",
    /// `P(Binomial(n, ½) ≥ above)`; `p_below` of H₀ "median ≥ θ₀". Valid for any
    /// distribution, atoms included (H₀ implies `P(d > θ₀) ≤ ½`; a difference equal to
    /// θ₀ counts for neither side).
    pub p_above: f64,
    pub p_below: f64,
}

impl Test {
    /// The two-sided p-value: `2·min(p_above, p_below)`, at most 1.
    pub fn p_two_sided(&self) -> f64 {
        (2.0 * self.p_above.min(self.p_below)).min(1.0)
    }
}

/// The verdict rule (SPEC.md §21.2).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Rule {
    /// Two-sided level of each family after Holm's correction.
    pub alpha: f64,
    /// Non-inferiority margin (dB) of "does not hurt" claims.
    pub margin: f64,
    /// Power at which the minimum detectable effect is stated.
    pub power: f64,
    /// The planned sample: a claim is judged once it has `planned` units (the audit's plan
    /// is seeds 0 to `planned − 1`); before, its outcome is [`Outcome::Interim`].
    pub planned: usize,
}

/// The planned sample of an audit: seeds 0 to 15 of every claim. At 16 the sign test reaches
/// the strictest Holm level of the presets' families — 15 claims per generator (`2·P(X ≥
/// 15) = 2·17/2¹⁶ = 0.00052 < 0.05/15`; 14 of 16, 0.0042, does not), and the paper preset's
/// 45 truth claims (`< 0.05/45`) — and finds a shift of the median of 1.63 standard
/// deviations with 80 % power at 12 to 45 claims (1.30 at 11 or fewer, where 14 of 16
/// suffice).
pub const PLANNED_SEEDS: usize = 16;

impl Default for Rule {
    fn default() -> Rule {
        Rule {
            alpha: 0.05,
            margin: 0.2,
            power: 0.8,
            planned: PLANNED_SEEDS,
        }
    }
}

/// A claim's outcome.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    Holds,
    Contradicted,
    Inconclusive,
    /// Fewer units than planned: a look at a growing pool, not a verdict.
    Interim,
    /// Every unit gave the same difference (0: the variant computes what the full method
    /// computes): the seeds do not vary the comparison, so there is one draw, not n.
    NoVerdict,
    /// Every planned seed's pair is the same computation (both runs evaluated the same
    /// scene, SPEC.md §21.5): the comparison did not happen, so no test and no MDE.
    NotTested,
}

impl Outcome {
    pub fn word(self) -> &'static str {
        match self {
            Outcome::Holds => "holds",
            Outcome::Contradicted => "contradicted",
            Outcome::Inconclusive => "inconclusive",
            Outcome::Interim => "interim",
            Outcome::NoVerdict => "no verdict",
            Outcome::NotTested => "not tested here",
        }
    }
}

/// One claim of a family: its paired differences in unit (seed) order, the null value
/// of its test (0 for "the full method is better", `−margin` for "does not hurt") and the
/// planned seeds on which the comparison did not happen (same computation, SPEC.md §21.5):
/// they count towards the plan, not as units.
#[derive(Clone, Debug)]
pub struct ClaimData<'a> {
    pub diffs: &'a [f64],
    pub null: f64,
    pub untested: usize,
}

/// A claim's judgement within its family.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Judgement {
    pub outcome: Outcome,
    /// The test of the units judged (the first [`Rule::planned`]); `None` without units.
    pub test: Option<Test>,
    /// Holm-adjusted two-sided p-value of the null value (NaN without a test; an interim
    /// claim's own, as if it were complete: the others' entered it at p = 1).
    pub p_holm: f64,
    /// Claims with a test in the family (Holm's `m`).
    pub family_tests: usize,
    /// The test was significant but the mean lies on the other side of the null value than
    /// the median (or on it): no verdict either way (the outcome is inconclusive).
    pub median_and_mean_disagree: bool,
}

impl Rule {
    /// The sign test of `d` (finite values) against `null`; `None` when empty.
    pub fn test(&self, d: &[f64], null: f64) -> Option<Test> {
        let n = d.len();
        if n == 0 {
            return None;
        }
        let mut sorted = d.to_vec();
        sorted.sort_by(f64::total_cmp);
        let median = quantile_sorted(&sorted, 0.5);
        let mean = d.iter().sum::<f64>() / n as f64;
        let sd = if n > 1 {
            (d.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1) as f64).sqrt()
        } else {
            f64::NAN
        };
        let above = d.iter().filter(|&&x| x > null).count();
        let below = d.iter().filter(|&&x| x < null).count();
        // The largest k with P(X ≤ k − 1) ≤ α/2 (X ~ Binomial(n, ½), symmetric).
        let k = (1..=n / 2)
            .take_while(|&k| binomial_upper_tail(n, n - k + 1, 0.5) <= self.alpha / 2.0)
            .last();
        Some(Test {
            n,
            median,
            mean,
            sd,
            method: Method::Sign,
            above,
            below,
            interval: k.map(|k| [sorted[k - 1], sorted[n - k]]),
            p_above: binomial_upper_tail(n, above, 0.5),
            p_below: binomial_upper_tail(n, below, 0.5),
        })
    }

    /// Judge a family of claims: each claim's first [`Rule::planned`] units tested against
    /// its null value, then Holm's step-down correction of the two-sided p-values over the
    /// claims with a test and some spread. A claim below its plan enters Holm at p = 1 (still
    /// counted in m): a complete claim's verdict does not depend on other claims' interim
    /// looks, and as they complete its adjusted p can only fall. The outcome: *no verdict*
    /// where every unit gave the same difference, *interim* below the planned sample, else
    /// *holds* where the adjusted p is below α and more units lie above the null value than
    /// below and so does the mean, *contradicted* likewise below, *inconclusive* otherwise
    /// (also where the median and the mean disagree: then the claim means different things
    /// for the typical seed and on average).
    pub fn judge(&self, family: &[ClaimData]) -> Vec<Judgement> {
        let judged: Vec<&[f64]> = family
            .iter()
            .map(|c| &c.diffs[..c.diffs.len().min(self.planned.saturating_sub(c.untested))])
            .collect();
        let tests: Vec<Option<Test>> = family
            .iter()
            .zip(&judged)
            .map(|(c, d)| self.test(d, c.null))
            .collect();
        // (`==`: +0.0 and −0.0 are the same difference.)
        let spread = |d: &[f64]| d.iter().any(|&x| x != d[0]);
        let complete = |c: &ClaimData, d: &[f64]| d.len() + c.untested >= self.planned;
        let raw: Vec<f64> = tests
            .iter()
            .zip(family.iter().zip(&judged))
            .map(|(t, (c, d))| match t {
                Some(t) if spread(d) && complete(c, d) => t.p_two_sided(),
                // Below its plan (one seed included, which has no spread yet): p = 1.
                Some(_) if !complete(c, d) => 1.0,
                _ => f64::NAN,
            })
            .collect();
        let adjusted = holm(&raw);
        let m = raw.iter().filter(|p| !p.is_nan()).count().max(1);
        family
            .iter()
            .zip(tests)
            .zip(judged.iter().zip(adjusted))
            .enumerate()
            .map(|(i, ((c, test), (d, p_holm)))| {
                // An interim claim's adjusted p as if it were complete (for the report).
                let p_holm = match test {
                    Some(t) if spread(d) && !complete(c, d) => {
                        let mut look = raw.clone();
                        look[i] = t.p_two_sided();
                        holm(&look)[i]
                    }
                    _ => p_holm,
                };
                let significant = p_holm < self.alpha;
                let side = |t: &Test| {
                    if t.above > t.below && t.mean > c.null {
                        Some(Outcome::Holds)
                    } else if t.below > t.above && t.mean < c.null {
                        Some(Outcome::Contradicted)
                    } else {
                        None
                    }
                };
                let mut disagree = false;
                let outcome = match test {
                    None if c.untested > 0 && complete(c, d) => Outcome::NotTested,
                    Some(_) if d.len() > 1 && !spread(d) => Outcome::NoVerdict,
                    _ if !complete(c, d) => Outcome::Interim,
                    Some(t) if significant => side(&t).unwrap_or_else(|| {
                        disagree = true;
                        Outcome::Inconclusive
                    }),
                    _ => Outcome::Inconclusive,
                };
                Judgement {
                    outcome,
                    test,
                    p_holm,
                    family_tests: m,
                    median_and_mean_disagree: disagree,
                }
            })
            .collect()
    }
}

impl Judgement {
    /// The smallest shift of the median from the null value that the claim's sign test
    /// finds with the rule's power at the family's first Holm level `α/m`, were the
    /// differences normal with the measured sd ([`sign_min_detectable`]). NaN without a
    /// test or spread.
    pub fn min_detectable(&self, rule: &Rule) -> f64 {
        self.test.map_or(f64::NAN, |t| {
            sign_min_detectable(t.n, t.sd, rule.alpha / self.family_tests as f64, rule.power)
        })
    }
}

/// The fewest of `n` differences that must lie on one side of the null value for the
/// two-sided sign test to fall below `alpha` (`n + 1`: never).
pub fn sign_critical(n: usize, alpha: f64) -> usize {
    (0..=n)
        .find(|&k| 2.0 * binomial_upper_tail(n, k, 0.5) < alpha)
        .unwrap_or(n + 1)
}

/// The shift δ of the median (in the units of `sd`) that the two-sided sign test at level
/// `alpha` finds in the claimed direction with probability `power` from `n` differences
/// drawn from a normal distribution of standard deviation `sd`: each lies beyond the
/// null value with `p = Φ(δ/sd)`, so the power is `P(Binomial(n, p) ≥ c)` with `c` of
/// [`sign_critical`]; `p` by bisection. ∞ when `n` differences cannot reach `alpha`, NaN
/// without a finite positive sd.
pub fn sign_min_detectable(n: usize, sd: f64, alpha: f64, power: f64) -> f64 {
    if n < 2 || !(sd.is_finite() && sd > 0.0) || !(power > 0.0 && power < 1.0) {
        return f64::NAN;
    }
    let c = sign_critical(n, alpha);
    if c > n {
        return f64::INFINITY;
    }
    let (mut lo, mut hi) = (0.5f64, 1.0f64);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if binomial_upper_tail(n, c, mid) < power {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    normal_quantile(hi) * sd
}

/// The `level`-quantile of ascending `sorted` (non-empty) by linear interpolation between
/// order statistics (position `level·(n − 1)`; a NaN level gives the first).
pub fn quantile_sorted(sorted: &[f64], level: f64) -> f64 {
    let n = sorted.len();
    let h = level.clamp(0.0, 1.0) * (n - 1) as f64;
    let i = (h.floor() as usize).min(n - 1);
    let j = (i + 1).min(n - 1);
    sorted[i] + (h - i as f64) * (sorted[j] - sorted[i])
}

/// Holm's step-down adjustment of p-values (NaN entries are not tests and stay NaN):
/// `p̃₍ᵢ₎ = max over j ≤ i of min(1, (m − j + 1)·p₍ⱼ₎)` in ascending order of p.
pub fn holm(p: &[f64]) -> Vec<f64> {
    let mut order: Vec<usize> = (0..p.len()).filter(|&i| !p[i].is_nan()).collect();
    order.sort_by(|&a, &b| p[a].total_cmp(&p[b]).then(a.cmp(&b)));
    let m = order.len();
    let mut out = vec![f64::NAN; p.len()];
    let mut running = 0.0f64;
    for (j, &i) in order.iter().enumerate() {
        running = running.max(((m - j) as f64 * p[i]).min(1.0));
        out[i] = running;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quantiles of Student's t and the normal distribution, and erfc, against SciPy 1.17.1
    /// (`scipy.stats.t.ppf`, `scipy.stats.norm.ppf`, `scipy.special.erfc`; the same as any
    /// statistics table to the digits printed there).
    #[test]
    fn quantiles_match_published_values() {
        for (p, df, want) in [
            (0.975, 1, 12.706204736174694),
            (0.975, 2, 4.302652729749462),
            (0.975, 3, 3.1824463052837078),
            (0.975, 5, 2.5705818356363146),
            (0.975, 10, 2.228138851986274),
            (0.975, 11, 2.200985160091639),
            (0.975, 30, 2.0422724563012378),
            (0.8, 5, 0.9195437802408271),
            (0.995, 20, 2.8453397097861077),
        ] {
            let got = student_t_quantile(p, df);
            assert!(
                (got - want).abs() < 1e-12 * want,
                "t({p}, {df}) = {got}, want {want}"
            );
        }
        for (p, want) in [
            (0.975, 1.959963984540054),
            (0.8, 0.8416212335729143),
            (0.5, 0.0),
            (1e-10, -6.361340902404056),
            (0.0025, -2.8070337683438042),
        ] {
            let got = normal_quantile(p);
            assert!(
                (got - want).abs() < 1e-12 * want.abs().max(1.0),
                "z({p}) = {got}, want {want}"
            );
        }
        // erfc in both branches (they meet at 1) and its limits; SciPy's values.
        for (x, want) in [
            (3.0, 2.2090496998585445e-05),
            (0.5, 0.4795001221869535),
            (1.0, 0.15729920705028516),
            (2.5, 0.00040695201744495886),
            (10.0, 2.0884875837625446e-45),
        ] {
            assert!(
                (erfc(x) / want - 1.0).abs() < 1e-13,
                "erfc({x}) = {}",
                erfc(x)
            );
        }
        assert_eq!((erfc(f64::INFINITY), erfc(f64::NEG_INFINITY)), (0.0, 2.0));
        assert!((normal_quantile(1e-300) + 37.0470962993612).abs() < 1e-9);
    }

    /// Seeds on which the variant computed what full computed count towards the plan but
    /// are no units: all of them is *not tested* (no test, no MDE); some of them leaves the
    /// others' test as it would be alone, and the claim complete.
    #[test]
    fn same_computation_seeds_count_towards_the_plan_not_as_units() {
        let rule = Rule {
            planned: 6,
            ..Rule::default()
        };
        let none = rule.judge(&[ClaimData {
            diffs: &[],
            null: 0.0,
            untested: 6,
        }]);
        assert_eq!(none[0].outcome, Outcome::NotTested);
        assert!(none[0].test.is_none() && none[0].min_detectable(&rule).is_nan());
        let d = [1.0, 2.0, 3.0, 4.0];
        let some = rule.judge(&[ClaimData {
            diffs: &d,
            null: 0.0,
            untested: 2,
        }]);
        assert_eq!(some[0].test.unwrap().n, 4);
        assert_ne!(some[0].outcome, Outcome::Interim);
        // Too few seeds either way: still interim.
        let few = rule.judge(&[ClaimData {
            diffs: &d,
            null: 0.0,
            untested: 1,
        }]);
        assert_eq!(few[0].outcome, Outcome::Interim);
    }

    #[test]
    fn holm_steps_down() {
        let p = [0.01, 0.04, 0.03, f64::NAN, 0.005];
        let a = holm(&p);
        // Sorted 0.005, 0.01, 0.03, 0.04 with m = 4: 0.02, 0.03, 0.06, 0.06.
        assert_eq!(a[4], 0.02);
        assert!((a[0] - 0.03).abs() < 1e-15);
        assert!((a[2] - 0.06).abs() < 1e-15 && (a[1] - 0.06).abs() < 1e-15);
        assert!(a[3].is_nan());
    }

    /// The binomial tail against exact fractions, the sign test's p-values and its
    /// distribution-free interval, the critical count and the minimum detectable shift.
    #[test]
    fn sign_test_is_exact() {
        // P(X ≥ 14 | n = 16) = (1 + 16 + 120)/2¹⁶; P(X ≥ 0) = 1; P(X ≥ 17) = 0.
        assert!((binomial_upper_tail(16, 14, 0.5) - 137.0 / 65536.0).abs() < 1e-16);
        assert_eq!(binomial_upper_tail(16, 0, 0.5), 1.0);
        assert_eq!(binomial_upper_tail(16, 17, 0.5), 0.0);
        // P(X ≥ 2 | n = 3, p = 0.3) = 3·0.09·0.7 + 0.027.
        assert!((binomial_upper_tail(3, 2, 0.3) - 0.216).abs() < 1e-15);
        // Far tails of large n stay finite (0.5¹⁵⁰⁰ underflows).
        let t = binomial_upper_tail(1500, 1500, 0.5);
        assert!(t == 0.0 || t.is_finite());
        assert!((binomial_upper_tail(2000, 1000, 0.5) - 0.5 - 0.5 * 0.017836).abs() < 1e-4);
        assert_eq!(sign_critical(16, 0.05 / 11.0), 14);
        assert_eq!(sign_critical(16, 0.05 / 12.0), 15); // 2·137/2¹⁶ = 0.00418 > 0.05/12
        assert_eq!(sign_critical(8, 0.05 / 11.0), 9); // 2/256 > 0.0045: never
        assert_eq!(sign_critical(6, 0.05), 6);
        let rule = Rule::default();
        let d: Vec<f64> = (1..=16).map(|k| k as f64 / 10.0 - 0.35).collect();
        let t = rule.test(&d, 0.0).unwrap();
        // Three below 0 (−0.25, −0.15, −0.05), thirteen above.
        assert_eq!((t.above, t.below), (13, 3));
        assert!((t.p_above - binomial_upper_tail(16, 13, 0.5)).abs() == 0.0);
        // n = 16: k = 4 (P(X ≤ 3) = 697/65536 ≤ 0.025 < P(X ≤ 4)): [d₍₄₎, d₍₁₃₎].
        assert_eq!(t.interval, Some([d[3], d[12]]));
        assert_eq!(rule.test(&d[..5], 0.0).unwrap().interval, None);
        assert_eq!(sign_min_detectable(8, 1.0, 0.05 / 11.0, 0.8), f64::INFINITY);
        // At the minimum detectable shift the power is the rule's.
        let mde = sign_min_detectable(16, 0.33, 0.05 / 11.0, 0.8);
        let p = normal_cdf(mde / 0.33);
        assert!((binomial_upper_tail(16, 14, p) - 0.8).abs() < 1e-9, "{mde}");
        assert!((mde / 0.33 - 1.30).abs() < 0.005, "{mde}");
        assert!((sign_min_detectable(16, 1.0, 0.05 / 12.0, 0.8) - 1.63).abs() < 0.005);
        assert!(sign_min_detectable(16, 1.0, 0.05, 1.0).is_nan());
        // Large n: linear time, and the tail of a fair coin at its mean.
        let t = binomial_upper_tail(20_000, 10_000, 0.5);
        assert!((t - 0.5 - 0.5 * 0.005641).abs() < 1e-5, "{t}");
    }

    /// A complete claim's verdict does not depend on its family's interim looks: they enter
    /// Holm at p = 1. A significant sign test whose mean lies on the other side is no verdict.
    #[test]
    fn interim_claims_do_not_move_complete_ones() {
        let rule = Rule {
            planned: 16,
            ..Rule::default()
        };
        // A: 15 of 16 above 0 (p = 2·17/2¹⁶); B, C: six seeds each.
        let a: Vec<f64> = (0..16)
            .map(|k| if k < 15 { 1.0 + k as f64 } else { -1.0 })
            .collect();
        let judge = |b: &[f64]| {
            let fam = [
                ClaimData {
                    untested: 0,
                    diffs: &a,
                    null: 0.0,
                },
                ClaimData {
                    untested: 0,
                    diffs: b,
                    null: 0.0,
                },
                ClaimData {
                    untested: 0,
                    diffs: b,
                    null: 0.0,
                },
            ];
            rule.judge(&fam)
        };
        let flat = [1.0, -1.0, 2.0, -2.0, 3.0, -3.0];
        let strong = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        // One seed: no spread yet, but interim all the same, so in m (it was left out, and
        // a complete claim moved when another claim got its second seed).
        let (x, y, one) = (judge(&flat), judge(&strong), judge(&[2.0]));
        assert_eq!(x[0].outcome, Outcome::Holds);
        assert_eq!((x[0].outcome, x[0].p_holm), (y[0].outcome, y[0].p_holm));
        assert_eq!((x[0].outcome, x[0].p_holm), (one[0].outcome, one[0].p_holm));
        assert!((x[0].p_holm - 3.0 * 2.0 * 17.0 / 65536.0).abs() < 1e-15);
        assert_eq!(
            (y[1].outcome, one[1].outcome),
            (Outcome::Interim, Outcome::Interim)
        );
        assert_eq!(one[0].family_tests, 3);
        // 15 of 16 above 0 but one far below: the median says better, the mean worse.
        let mut d = vec![0.1; 16];
        d[0] = -10.0;
        let j = &rule.judge(&[ClaimData {
            untested: 0,
            diffs: &d,
            null: 0.0,
        }])[0];
        assert_eq!(j.outcome, Outcome::Inconclusive);
        assert!(j.median_and_mean_disagree && j.p_holm < 0.05);
        // +0.0 and −0.0 are no spread.
        let z = [0.0, -0.0, 0.0];
        let j = &Rule {
            planned: 3,
            ..Rule::default()
        }
        .judge(&[ClaimData {
            untested: 0,
            diffs: &z,
            null: 0.0,
        }])[0];
        assert_eq!(j.outcome, Outcome::NoVerdict);
    }
}
