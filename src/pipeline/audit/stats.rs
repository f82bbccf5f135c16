//! The statistics of the audit's verdicts (SPEC.md §21.2): confidence intervals of a mean
//! paired difference over seeds (Student's t for few seeds, a seeded BCa bootstrap from
//! [`Rule::bootstrap_from`] seeds), Holm's step-down correction within a family of claims,
//! and the minimum effect a test detects with a given power (noncentral t).
//!
//! Written from the definitions: the t distribution's CDF by its finite trigonometric
//! series for integer degrees of freedom (Abramowitz & Stegun 26.7.3–4), the normal CDF by
//! the error function's series and continued fraction (A&S 7.1.6, 7.1.14), BCa by Efron
//! (1987, "Better bootstrap confidence intervals", JASA 82:171), Holm (1979, "A simple
//! sequentially rejective multiple test procedure", Scand. J. Statist. 6:65). No allocation
//! but the bootstrap's replicate array; single-threaded, so the same bits for any thread
//! count.

use crate::rng::Uniform;
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

/// ln Γ(ν/2) for a positive integer ν, exactly summed: Γ(k) = (k−1)!,
/// Γ(k + ½) = √π·(1·3···(2k−1))/2ᵏ.
fn ln_gamma_half(nu: u32) -> f64 {
    let (mut s, mut z) = if nu.is_multiple_of(2) {
        (0.0, 1.0)
    } else {
        (0.5 * PI.ln(), 0.5)
    };
    while z < nu as f64 / 2.0 - 0.25 {
        s += z.ln();
        z += 1.0;
    }
    s
}

/// What a test's p-values come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Student's t: interval `m ± t(1−α/2, n−1)·sd/√n`.
    StudentT,
    /// Student's t and Efron's bias-corrected and accelerated (BCa) percentile bootstrap
    /// over the seeds, each p-value the larger of the two: a verdict needs both. (The BCa
    /// alone is not calibrated at these sizes: measured false verdicts 4–10 % per side at
    /// n = 10–20 where 2.5 % is stated, SPEC.md §21.2.)
    StudentTAndBca,
}

/// The test of a mean paired difference against a null value.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Test {
    pub n: usize,
    pub mean: f64,
    /// Sample standard deviation (n − 1).
    pub sd: f64,
    pub method: Method,
    /// The two-sided `1 − α` t interval.
    pub lo: f64,
    pub hi: f64,
    /// The two-sided `1 − α` BCa interval (with [`Method::StudentTAndBca`]).
    pub bca: Option<[f64; 2]>,
    /// One-sided p-values of the null value `θ₀`: `p_above` of H₀ "Δ ≤ θ₀" (small when Δ
    /// is above it), `p_below` of H₀ "Δ ≥ θ₀".
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
    /// From this many seeds a verdict also needs the BCa bootstrap's p-value
    /// ([`Method::StudentTAndBca`]).
    pub bootstrap_from: usize,
    /// Bootstrap replicates.
    pub replicates: usize,
}

impl Default for Rule {
    fn default() -> Rule {
        Rule {
            alpha: 0.05,
            margin: 0.2,
            power: 0.8,
            bootstrap_from: 10,
            replicates: 10_000,
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
}

impl Outcome {
    pub fn word(self) -> &'static str {
        match self {
            Outcome::Holds => "holds",
            Outcome::Contradicted => "contradicted",
            Outcome::Inconclusive => "inconclusive",
        }
    }
}

/// One claim of a family: its paired differences, the null value of its test (0 for "the
/// full method is better", `−margin` for "does not hurt") and its bootstrap seed.
#[derive(Clone, Debug)]
pub struct ClaimData<'a> {
    pub diffs: &'a [f64],
    pub null: f64,
    pub seed: u64,
}

/// A claim's judgement within its family.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Judgement {
    pub outcome: Outcome,
    /// `None` with fewer than two finite differences (no spread, no test).
    pub test: Option<Test>,
    /// Holm-adjusted two-sided p-value of the null value.
    pub p_holm: f64,
    /// Claims with a test in the family (Holm's `m`).
    pub family_tests: usize,
}

impl Rule {
    /// The test of `d` (finite values) against `null`: Student's t, and from
    /// [`Rule::bootstrap_from`] values also the BCa bootstrap (seeded by `seed`), each
    /// p-value the larger of the two. `None` below two values.
    pub fn test(&self, d: &[f64], null: f64, seed: u64) -> Option<Test> {
        let n = d.len();
        if n < 2 {
            return None;
        }
        let nf = n as f64;
        let mean = d.iter().sum::<f64>() / nf;
        let ss: f64 = d.iter().map(|x| (x - mean) * (x - mean)).sum();
        let sd = (ss / (nf - 1.0)).sqrt();
        if sd == 0.0 || !sd.is_finite() {
            // Every seed gave the same difference (or the spread overflows): nothing to
            // measure the mean against, so no verdict either way.
            return Some(Test {
                n,
                mean,
                sd,
                method: Method::StudentT,
                lo: mean,
                hi: mean,
                bca: None,
                p_above: 1.0,
                p_below: 1.0,
            });
        }
        let se = sd / nf.sqrt();
        let q = student_t_quantile(1.0 - self.alpha / 2.0, (n - 1) as u32);
        let below = student_t_cdf((mean - null) / se, (n - 1) as u32);
        let mut test = Test {
            n,
            mean,
            sd,
            method: Method::StudentT,
            lo: mean - q * se,
            hi: mean + q * se,
            bca: None,
            p_above: 1.0 - below,
            p_below: below,
        };
        if n >= self.bootstrap_from {
            let (interval, p_above) = self.bca(d, mean, ss, null, seed);
            // A bootstrap that could not be computed (an overflowing spread) agrees with
            // nothing.
            let p_above = if p_above.is_nan() { 1.0 } else { p_above };
            test.method = Method::StudentTAndBca;
            test.bca = Some(interval);
            test.p_above = test.p_above.max(p_above);
            test.p_below = test.p_below.max(1.0 - p_above);
        }
        Some(test)
    }

    /// The BCa interval of the mean of `d` and the one-sided p-value of H₀ "Δ ≤ null"
    /// (the nominal lower-tail level at which the interval's lower end is `null`).
    fn bca(&self, d: &[f64], mean: f64, ss: f64, null: f64, seed: u64) -> ([f64; 2], f64) {
        let n = d.len();
        let b = self.replicates;
        let mut u = Uniform::new(seed);
        let mut reps: Vec<f64> = (0..b)
            .map(|_| (0..n).map(|_| d[u.below(n as u32) as usize]).sum::<f64>() / n as f64)
            .collect();
        reps.sort_by(f64::total_cmp);
        // Fraction of replicates below x (ties count half), kept inside (0, 1).
        let frac = |x: f64| {
            let below = reps.partition_point(|&r| r < x);
            let not_above = reps.partition_point(|&r| r <= x);
            let f = (below as f64 + 0.5 * (not_above - below) as f64) / b as f64;
            f.clamp(0.5 / b as f64, 1.0 - 0.5 / b as f64)
        };
        let z0 = normal_quantile(frac(mean));
        // Acceleration by the jackknife of the mean: θ̄ − θ₍ᵢ₎ = (dᵢ − m)/(n − 1).
        let cube: f64 = d.iter().map(|x| (x - mean).powi(3)).sum();
        let a = cube / (6.0 * ss.powf(1.5));
        // The replicate quantile at BCa's adjusted level for nominal z.
        let endpoint =
            |z: f64| quantile_sorted(&reps, normal_cdf(z0 + (z0 + z) / (1.0 - a * (z0 + z))));
        let zq = normal_quantile(1.0 - self.alpha / 2.0);
        // The nominal level at which the lower endpoint is the null value: with
        // w = Φ⁻¹(fraction below θ₀), z0 + u/(1 − a·u) = w for u = z0 + z. The fraction is
        // not clamped here: a null beyond every replicate takes the limit w = ∓∞ (else
        // the p-value would have a floor of ~1/B that no Holm level below it could
        // clear), and where `1 + a·c ≤ 0` no nominal level reaches the null: p is 0 or 1.
        let below = reps.partition_point(|&r| r < null);
        let not_above = reps.partition_point(|&r| r <= null);
        let q = (below as f64 + 0.5 * (not_above - below) as f64) / b as f64;
        let w = if q <= 0.0 {
            f64::NEG_INFINITY
        } else if q >= 1.0 {
            f64::INFINITY
        } else {
            normal_quantile(q)
        };
        let c = w - z0;
        let denominator = 1.0 + a * c;
        let p = if denominator <= 0.0 {
            if c < 0.0 { 0.0 } else { 1.0 }
        } else if c.is_infinite() {
            // c/(1 + a·c) → 1/a (or c itself when a = 0).
            let u = if a != 0.0 { 1.0 / a } else { c };
            normal_cdf(u - z0)
        } else {
            normal_cdf(c / denominator - z0)
        };
        ([endpoint(-zq), endpoint(zq)], p)
    }

    /// Judge a family of claims: each claim's test of its null value, Holm's step-down
    /// correction of the two-sided p-values over the claims with a test, and the outcome:
    /// *holds* where the adjusted p is below α and Δ is above the null value,
    /// *contradicted* where it is below α and Δ is below, *inconclusive* otherwise.
    pub fn judge(&self, family: &[ClaimData]) -> Vec<Judgement> {
        let tests: Vec<Option<Test>> = family
            .iter()
            .map(|c| self.test(c.diffs, c.null, c.seed))
            .collect();
        let raw: Vec<f64> = tests
            .iter()
            .map(|t| t.map_or(f64::NAN, |t| t.p_two_sided()))
            .collect();
        let adjusted = holm(&raw);
        let m = raw.iter().filter(|p| !p.is_nan()).count().max(1);
        family
            .iter()
            .zip(tests)
            .zip(adjusted)
            .map(|((c, test), p_holm)| {
                let outcome = match test {
                    Some(t) if p_holm < self.alpha && t.mean > c.null => Outcome::Holds,
                    Some(t) if p_holm < self.alpha && t.mean < c.null => Outcome::Contradicted,
                    _ => Outcome::Inconclusive,
                };
                Judgement {
                    outcome,
                    test,
                    p_holm,
                    family_tests: m,
                }
            })
            .collect()
    }
}

impl Judgement {
    /// The smallest true distance from the null value that the claim's test finds with
    /// the rule's power at the family's first Holm level `α/m`, for the measured sd (the t
    /// test's figure, also stated for bootstrap intervals). NaN without a test.
    pub fn min_detectable(&self, rule: &Rule) -> f64 {
        self.test.map_or(f64::NAN, |t| {
            min_detectable_effect(t.n, t.sd, rule.alpha / self.family_tests as f64, rule.power)
        })
    }
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

/// Power of the two-sided one-sample t test at level `alpha` with `n` samples when the
/// true mean is `lambda` standard errors from the null value, in the direction of the
/// claim: `P(T′ > t(1−α/2, n−1))` for the noncentral T′, by integrating
/// `Φ(λ − c·s)` against the density of `s = √(χ²ᵥ/ν)` (Simpson, ≥ 4 000 panels).
pub fn t_power(n: usize, lambda: f64, alpha: f64) -> f64 {
    assert!(n >= 2);
    let nu = (n - 1) as u32;
    let nuf = nu as f64;
    let c = student_t_quantile(1.0 - alpha / 2.0, nu);
    // Density of s: 2·(ν/2)^(ν/2)/Γ(ν/2) · s^(ν−1) · e^(−ν s²/2).
    let ln_k = std::f64::consts::LN_2 + 0.5 * nuf * (0.5 * nuf).ln() - ln_gamma_half(nu);
    let dens = |s: f64| {
        if s <= 0.0 {
            return if nu == 1 { ln_k.exp() } else { 0.0 };
        }
        (ln_k + (nuf - 1.0) * s.ln() - 0.5 * nuf * s * s).exp()
    };
    // The density is below e^(−40) of its peak beyond `top`; Φ(λ − c·s) turns from 1 to 0
    // over ~1/c in s, which the panels resolve with ≥ 20 points.
    let top = 1.0 + 9.0 / nuf.sqrt();
    let panels = (4000usize)
        .max((20.0 * c * top).ceil() as usize)
        .next_multiple_of(2);
    let h = top / panels as f64;
    let mut sum = 0.0;
    for i in 0..=panels {
        let s = i as f64 * h;
        let w = if i == 0 || i == panels {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        };
        sum += w * dens(s) * normal_cdf(lambda - c * s);
    }
    sum * h / 3.0
}

/// The smallest true mean difference (in the units of `sd`) the two-sided t test at level
/// `alpha` finds in the claimed direction with probability `power`, from `n` seeds whose
/// differences spread with standard deviation `sd`. NaN below two seeds.
pub fn min_detectable_effect(n: usize, sd: f64, alpha: f64, power: f64) -> f64 {
    if n < 2 || !sd.is_finite() {
        return f64::NAN;
    }
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    while t_power(n, hi, alpha) < power {
        hi *= 2.0;
        if hi > 1e6 {
            return f64::INFINITY;
        }
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if t_power(n, mid, alpha) < power {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi * sd / (n as f64).sqrt()
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

    /// With a known sd, the t test's power at λ = 0 is α/2 in the claimed direction, and
    /// for many seeds the minimum detectable effect tends to (z(1−α/2) + z(power))·sd/√n.
    #[test]
    fn power_and_minimum_detectable_effect() {
        assert!((t_power(5, 0.0, 0.05) - 0.025).abs() < 1e-7);
        assert!((t_power(2, 0.0, 0.05) - 0.025).abs() < 1e-6);
        let n = 2000;
        let mde = min_detectable_effect(n, 1.0, 0.05, 0.8);
        let z = (1.959963984540054 + 0.8416212335729143) / (n as f64).sqrt();
        assert!((mde / z - 1.0).abs() < 2e-3, "{mde} vs {z}");
    }
}
