//! Where a render's discrete decisions lie near their thresholds (SPEC.md §8.1): the pixels
//! and Gaussians at which a *correct* float32 port may decide the other way, so that a
//! port harness can set them aside instead of failing a correct port (or loosening every
//! tolerance until a wrong one passes).
//!
//! The forward pass takes four discrete decisions per (pixel, splat) — σ < 0, α < 1/255,
//! `T·(1 − α) ≤ 1e-4`, the depth order — and one kink, the α clamp, where the forward is
//! continuous but the backward switches the opacity and geometry gradients off. A port
//! whose α differs from ours by a relative δ (another `exp`, another summation order, FMA)
//! decides each of them the same way unless the value lies within about δ of the
//! threshold. [`decisions`] replays the render's blend, bit for bit (the same splats, the
//! same scalar arithmetic as every kernel form, the same lists plus the Gaussians just
//! under the opacity cull), and records per pixel how
//! close each decision came (relative margins) and flags the pixels within
//! [`Margins`]; per Gaussian it flags the projection's decisions (opacity cull, near
//! plane, Jacobian guard) within their margins.
//!
//! The projection itself is a source of error only where float32 cannot resolve a
//! Gaussian's footprint: [`conic_rounding`] bounds how far rounding can move its conic
//! (a few units of roundoff for ordinary Gaussians, up to the aspect ratio for a needle
//! lying along a pixel axis or pointing at the camera). That bound widens the Gaussian's σ
//! error where it exceeds the `sigma` margin, and past the `conic` margin the Gaussian and
//! the pixels it reaches are flagged beyond float32.
//!
//! A Gaussian our projection culls for an opacity just under 1/255 may be kept by a port;
//! the replay therefore projects with the threshold lowered by the α margin, so such a
//! Gaussian's pixels are seen (its α there is under 1/255 in our arithmetic: a skip, as
//! in the render, and a flag where it comes within the margin). The replay costs one
//! scalar walk of the tile lists: a diagnostic, not a render path.

use super::backward::wide::{Factor64, factor64};
use super::composite::{SplatAlpha, splat_alpha, splat_sigma};
use super::project::{
    ALPHA_THRESHOLD, CameraF32, EPS2D, FAR_PLANE, JACOBIAN_GUARD, NEAR_PLANE, Splat,
};
use super::tile::TILE_SIZE;
use super::{RenderOptions, RenderPlan, RenderReport};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gaussian::Gaussians;
use rayon::prelude::*;

/// Pixel flag: some splat's α lies within the α margin of the 1/255 threshold.
pub const PIXEL_ALPHA_THRESHOLD: u8 = 1;
/// Pixel flag: some `T·(1 − α)` lies within the transmittance margin of the 1e-4 stop.
pub const PIXEL_TRANSMITTANCE_STOP: u8 = 2;
/// Pixel flag: two consecutive blended splats (or the last blended one and the splat that
/// stopped the walk) have depths within the tie margin but not bit-equal: a port may order
/// them otherwise. Bit-equal depths are ordered by Gaussian index on both sides.
pub const PIXEL_DEPTH_TIE: u8 = 4;
/// Pixel flag: some blended splat's unclamped `o·exp(−σ)` lies within the α margin of the
/// clamp: the forward is continuous there, the backward's opacity and geometry gradients
/// are not.
pub const PIXEL_ALPHA_CLAMP: u8 = 8;
/// Pixel flag: some splat's σ is within rounding of 0 (the `σ < 0` skip may flip).
pub const PIXEL_SIGMA_SIGN: u8 = 16;
/// Pixel note (not a decision): some blended splat's α is at the clamp.
pub const PIXEL_CLAMPED: u8 = 32;
/// Pixel flag (backward only): the transmittance the backward recovers by dividing by
/// `1 − α` (gsplat's formulation, and ours) carries a propagated relative error above the
/// recovery margin: an α near the clamp amplifies α's error by `α/(1 − α)` (up to 999
/// under gsplat's 0.999), so two correct implementations' gradients from this pixel
/// differ by more than the gradient tolerance.
pub const PIXEL_RECOVERY: u8 = 64;
/// Pixel flag: a splat beyond float32 (its Gaussian is flagged
/// [`GAUSSIAN_ILL_CONDITIONED`]) passes the α test here: no float32 evaluation of its
/// projection, ours included, resolves its footprint to the comparison's tolerance.
pub const PIXEL_ILL_CONDITIONED: u8 = 128;

/// The flags that make a pixel's forward outputs ambiguous.
pub const PIXEL_FORWARD_FLAGS: u8 = PIXEL_ALPHA_THRESHOLD
    | PIXEL_TRANSMITTANCE_STOP
    | PIXEL_DEPTH_TIE
    | PIXEL_SIGMA_SIGN
    | PIXEL_ILL_CONDITIONED;
/// The flags that make a pixel's contribution to the gradients ambiguous.
pub const PIXEL_BACKWARD_FLAGS: u8 = PIXEL_FORWARD_FLAGS | PIXEL_ALPHA_CLAMP | PIXEL_RECOVERY;

/// Gaussian flag: its opacity lies within the α margin of the 1/255 cull.
pub const GAUSSIAN_OPACITY_CULL: u8 = 1;
/// Gaussian flag: its camera z lies within the depth margin of the near or far plane.
pub const GAUSSIAN_DEPTH_CULL: u8 = 2;
/// Gaussian flag: its `x/z` or `y/z` lies within the α margin of the Jacobian guard's
/// clamp (SPEC.md §5.1): the mean's gradient has a kink there.
pub const GAUSSIAN_JACOBIAN_CLAMP: u8 = 4;
/// Gaussian flag: its conic's float32 error bound `CONIC_ROUNDING·u·κ`
/// ([`conic_rounding`]) exceeds the conic margin: beyond float32.
pub const GAUSSIAN_ILL_CONDITIONED: u8 = 8;

/// A float32 evaluation of the projection (ours, or a port's by the same cancellation-free
/// form) gives a conic whose entries lie within `CONIC_ROUNDING·u·κ` of the exact ones
/// (relative; B relative to `√(A·C)`), `u = 2⁻²⁴` and κ from [`conic_rounding`]:
/// measured ≤ 2.8 on 26 000 ordinary and needle Gaussians (test
/// `ill_conditioned_conics_match_an_f64_projection`) and ≤ 2.4 on `unseen.testing`'s five
/// families; ×2 for two implementations, rounded up.
pub const CONIC_ROUNDING: f64 = 8.0;

/// How far a correct float32 port's values may lie from ours: a decision whose value is
/// within this distance of its threshold counts as ambiguous. A splat's α at a pixel may
/// differ by the relative `e_α = sigma·|σ|₊ + alpha`, `|σ|₊` the sum of the magnitudes of
/// σ's terms (σ's error grows with them; where they vanish only `exp` and the product with
/// the opacity round).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Margins {
    /// Relative error of σ. Default 2e-5: SPEC.md §8 measured that f32 and f64 (Dr.Jit)
    /// take other branches of α ≥ 1/255 only within 2e-5 (relative) of it, i.e. σ within
    /// 2e-5 absolute at σ = ln 255 ≈ 5.5 (3.6e-6 relative); two f32 implementations are
    /// each that far from f64 (×2), with a safety factor of 2.5 for near-plane scenes,
    /// whose projection rounds more.
    pub sigma: f32,
    /// Relative error of α where σ ≈ 0, of the opacity against its 1/255 cull, and of
    /// `x/z`, `y/z` against the Jacobian guard: 1e-6 (8 ulps: `exp`, the sigmoid, one
    /// product, one quotient, each ≤ 2 ulps in either implementation).
    pub alpha: f32,
    /// `T·(1 − α)` against the stop, on top of T's propagated error (each blended splat
    /// adds `α/(1 − α)·e_α`, the factor `1 − α` carrying α's error amplified near the
    /// clamp, plus 2⁻²³ for the product's rounding): 1e-5.
    pub transmittance: f32,
    /// Relative error of the projected mean's pixel coordinates: 2.4e-7 (2 f32 ulps, one
    /// per implementation; measured: a 10k-Gaussian 256×256 scene's means2d are within
    /// 1 ulp of their f64 value). A splat of conic `(A, B, C)` then moves σ by
    /// `|A·dx + B·dy|·δmx + |B·dx + C·dy|·δmy`: 2e-5 for a tight splat around pixel 170.
    pub mean2d: f32,
    /// Two depths `z₁ ≤ z₂` tie when `z₂ − z₁ ≤ depth·z₂`: 5e-7 (4 f32 ulps; `R·μ + t`
    /// in another order or with FMA moves z by a few ulps of its terms, which are of z's
    /// size unless the camera sits far from the origin). Also the margin of z against the
    /// near and far planes.
    pub depth: f32,
    /// The largest relative error of the transmittance the backward recovers, `Σ α/(1 −
    /// α)·alpha` over the blended splats (α's own rounding amplified by the division by
    /// `1 − α`; the σ part of `e_α` is a bound for rare threshold flips, not the typical
    /// error), at which a pixel still feeds the gradient comparison: 4e-4, ten times the
    /// gradient tolerance of unseen.testing (`GRAD_RTOL`): a pixel's share of a Gaussian's
    /// gradient is rarely more than a tenth of it. So a pixel is left out once its
    /// splats reach `Σ α/(1 − α) > 400`: only an α above 0.9975 gets there (gsplat's
    /// clamp allows it; two αs of 0.99 already stop the walk, so under `inria` the sum
    /// stays below ≈ 198).
    pub recovery: f32,
    /// How far the conic's rounding may move a splat's α at a pixel (relative: σ's error by
    /// [`ConicRounding::sigma_error`]) before the pixel counts as beyond float32 and is set
    /// aside: 1e-3. Below it the bound joins the pixel's α error, which the comparison
    /// allows for (at 1e-3 that is at most 1e-3 of the pixel's value, 100× a colour's
    /// tolerance: past it an allowance would hide real mistakes). A Gaussian whose entry
    /// bound `CONIC_ROUNDING·u·κ_geo` exceeds it is flagged.
    pub conic: f32,
}

impl Default for Margins {
    fn default() -> Self {
        Margins {
            sigma: 2e-5,
            alpha: 1e-6,
            mean2d: 2.4e-7,
            recovery: 4e-4,
            transmittance: 1e-5,
            depth: 5e-7,
            conic: 1e-3,
        }
    }
}

impl Margins {
    /// The relative error bound of a port's α (the absolute error of σ, plus α's own
    /// rounding) where σ's terms have the magnitude `terms` (`½(|A|·dx² + |C|·dy²) +
    /// |B·dx·dy|`, which is σ unless `B·dx·dy` cancels part of it, as across elongated
    /// splats) and the mean's rounding moves σ by `shift` (`|∂σ/∂mx|·mean2d·|mx| +
    /// |∂σ/∂my|·mean2d·|my|`): `sigma·terms + shift + alpha`.
    pub fn alpha_error(&self, terms: f32, shift: f32) -> f32 {
        self.sigma * terms + shift + self.alpha
    }

    fn check(&self) -> Result<()> {
        for (name, v) in [
            ("sigma", self.sigma),
            ("alpha", self.alpha),
            ("mean2d", self.mean2d),
            ("transmittance", self.transmittance),
            ("depth", self.depth),
            ("recovery", self.recovery),
            ("conic", self.conic),
        ] {
            if !(v.is_finite() && (0.0..0.01).contains(&v)) {
                return Err(Error::invalid(format!(
                    "decision margin {name} = {v} is not in [0, 0.01)"
                )));
            }
        }
        Ok(())
    }
}

/// Per pixel and per Gaussian: how close each decision came, and the flags.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Decisions {
    pub width: usize,
    pub height: usize,
    /// Per pixel, row-major: `PIXEL_*` bits.
    pub pixel_flags: Vec<u8>,
    /// Per pixel: the smallest `|α/threshold − 1| − e_α` over the splats the pixel
    /// evaluated (until its stop); +∞ when it evaluated none (≤ 0: within the error).
    pub alpha_margin: Vec<f32>,
    /// Per pixel: the smallest `|T·(1 − α)/stop − 1|` over the splats that passed the α
    /// test, minus the running bound of T's relative error there (negative: within it).
    pub transmittance_margin: Vec<f32>,
    /// Per pixel: the smallest relative depth gap `(z₂ − z₁)/z₂` between consecutive
    /// blended splats (and the stopping one), minus the tie margin; +∞ when fewer than two.
    pub depth_margin: Vec<f32>,
    /// Per pixel: the smallest `|o·exp(−σ)/clamp − 1| − e_α` over the blended splats.
    pub clamp_margin: Vec<f32>,
    /// Per pixel: a first-order bound of how far a port's alpha may lie from ours when its
    /// splat αs differ by `e_α`: `Σ_k T_k·α_k·e_α,k` over the blended splats (the
    /// derivative of `1 − T` with respect to `ln α_k` is `T_final·α_k/(1 − α_k) ≤
    /// T_k·α_k`).
    pub alpha_error: Vec<f32>,
    /// Per pixel: the same bound for each rgb channel: `alpha_error` times the largest
    /// colour channel among the blended splats and the background (`∂C/∂α_k =
    /// T_k·(c_k − S_k)`, `S_k` the normalised colour behind k, both within [0, that max]).
    pub rgb_error: Vec<f32>,
    /// Per pixel: the same bound for the accumulated depth D: `alpha_error` times the
    /// largest depth among the blended splats (`∂D/∂α_k = T_k·(z_k − S^z_k)`).
    pub depth_error: Vec<f32>,
    /// Per Gaussian: `GAUSSIAN_*` bits.
    pub gaussian_flags: Vec<u8>,
    /// Per Gaussian: κ of [`conic_rounding`] (how many units of rounding a float32
    /// conic may be off by), and the condition number `λ_max/λ_min` of its dilated 2D
    /// covariance (what the textbook `a·c − b²` form loses: its conic is good only while
    /// `u·cond` is small); both 0 where the projection culls the Gaussian.
    pub conic_amplification: Vec<f32>,
    pub condition: Vec<f32>,
    /// The margins the flags were set with.
    pub margins: Margins,
}

/// What one pixel's walk found.
#[derive(Clone, Copy)]
struct PixelWalk {
    flags: u8,
    /// `Σ T_k·α_k·e_α,k` and the largest colour channel (with the background).
    sensitivity: f32,
    color_max: f32,
    /// The largest depth among the blended splats.
    depth_max: f32,
    alpha: f32,
    transmittance: f32,
    depth: f32,
    clamp: f32,
}

impl PixelWalk {
    const EMPTY: PixelWalk = PixelWalk {
        flags: 0,
        sensitivity: 0.0,
        color_max: 0.0,
        depth_max: 0.0,
        alpha: 0.0,
        transmittance: 0.0,
        depth: 0.0,
        clamp: 0.0,
    };
}

/// A listed splat with what its walk needs per pixel, gathered once per tile: `ln` of its
/// opacity (f64) and its Gaussian's σ-error bound ([`ConicRounding::sigma_error`]).
/// With it, f32 constants (each rounded up) of a cheap lower bound of the splat's α margin
/// where σ is large: there `|lg| ≥ σ − (ln o − ln thr)`, and by Cauchy–Schwarz the σ-error
/// bound is at most `k·|w|² + relative·σ`, `|w|² ≤ (|A|·|dx| + |B|·|dy|)² + (|B|·|dx| +
/// |C|·|dy|)²` (the exact conic's entries).
#[derive(Clone, Copy)]
struct Staged {
    splat: Splat,
    /// `ln o − ln thr + 1e-4`: from this σ on, `o·exp(−σ)` is under the threshold by more
    /// than `exp`'s and the product's rounding.
    sigma_cut: f32,
    /// `ln o − ln thr`.
    ln_ratio: f32,
    conic_abs: [f32; 3],
    /// `|row_scale|·Σ_k s_k·|F_k|`.
    k: f32,
    relative: f32,
    ln_opacity: f64,
    bound: Option<SigmaBound>,
}

/// The relative slack of the skip's bound over the rounding of its f32 evaluation and of
/// the margin it bounds (each a few units of 2⁻²⁴ of their largest term).
const SKIP_SLACK: f32 = 1e-5;

/// `x` rounded up to f32 (NaN stays NaN).
fn up(x: f64) -> f32 {
    let y = x as f32;
    if f64::from(y) < x { y.next_up() } else { y }
}

impl Staged {
    fn new(splat: Splat, ln_thr: f64, bound: Option<SigmaBound>) -> Staged {
        let ln_opacity = f64::from(splat.opacity).ln();
        let ratio = ln_opacity - ln_thr;
        let (conic_abs, k, relative) = bound.map_or(([0.0; 3], 0.0, 0.0), |b| {
            let cols: f64 = (0..3).map(|c| b.s[c] * b.f[0][c].hypot(b.f[1][c])).sum();
            (
                b.conic.map(|v| up(v.abs())),
                up(b.row_scale[0].hypot(b.row_scale[1]) * cols),
                up(b.relative),
            )
        });
        Staged {
            splat,
            sigma_cut: up(ratio + 1e-4),
            ln_ratio: up(ratio),
            conic_abs,
            k,
            relative,
            ln_opacity,
            bound,
        }
    }
}

/// The magnitude of σ's terms at offset `(dx, dy)`: `½(|A|·dx² + |C|·dy²) + |B·dx·dy|`
/// (σ itself unless `B·dx·dy` cancels part of it); σ's rounding scales with it.
fn sigma_terms(s: &Splat, dx: f32, dy: f32) -> f32 {
    0.5 * (s.conic[0].abs() * dx * dx + s.conic[2].abs() * dy * dy) + (s.conic[1] * dx * dy).abs()
}

/// `ln(o·exp(−σ)/thr)`, the distance of a splat's unclamped α from the threshold in units
/// of σ, in f64: a port whose σ differs by `err` (the relative α error `e_α`) decides the
/// α test the other way only where it is within `±err`. Its first-order form `|α/thr − 1|`
/// would flag every pixel where `err ≥ 1`, which far out on a large splat (σ ≫ 1, α ≈ 0
/// on both sides) is no decision at all.
/// `ln_opacity` and `ln_thr` are `ln` of the f32 opacity and threshold in f64, computed once
/// per splat and per call.
fn log_gap(ln_opacity: f64, sigma: f32, ln_thr: f64) -> f32 {
    (ln_opacity - f64::from(sigma) - ln_thr) as f32
}

/// `|v/t − 1|` in f64 (exact enough for a margin, and no overflow).
fn rel(v: f32, t: f32) -> f32 {
    (f64::from(v) / f64::from(t) - 1.0).abs() as f32
}

/// Replay the blend of `scene` from `cam` under `opts` (default cut-offs only, as the
/// backward) and report its near decisions.
pub fn decisions(
    scene: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
    margins: &Margins,
) -> Result<Decisions> {
    margins.check()?;
    if opts.cutoffs != super::Cutoffs::GSPLAT {
        return Err(Error::invalid(format!(
            "decision diagnostics use gsplat's cut-offs only (asked for {:?})",
            opts.cutoffs
        )));
    }
    super::check_options(scene, opts)?;
    cam.validate()?;
    let (w, h) = (cam.width as usize, cam.height as usize);
    // The render's own plan (its SH degree gives the same colours), projected with the
    // opacity cull lowered by twice the α error at σ = 0 (a culled Gaussian reaches
    // 1/255 in a port only where σ ≈ 0): Gaussians just under 1/255 are listed too
    // (every listed splat's α is still tested against 1/255 in the walk, as in the render).
    let plan = RenderPlan::new(scene, opts);
    let relaxed = RenderPlan {
        cutoffs: super::Cutoffs {
            inv_alpha_threshold: 255.0 / (1.0 - 2.0 * margins.alpha),
            ..plan.cutoffs
        },
        ..plan
    };
    let mut report = RenderReport::default();
    let p = super::project::project(scene, cam, &relaxed, opts, &mut report);
    let bins = super::tile::bin(&p, w, h, opts.kernel);
    let camf = CameraF32::new(cam);
    // Per visible Gaussian: how float32 rounding may move its conic (f64, from its inputs).
    let rounding: Vec<Option<ConicRounding>> = (0..scene.len())
        .into_par_iter()
        .map(|i| (p.radii[i] != [0, 0]).then(|| conic_rounding(scene, i, &camf)))
        .collect();
    let unit = f64::from(f32::EPSILON) / 2.0;
    let (thr, stop, clamp) = (
        ALPHA_THRESHOLD,
        plan.cutoffs.transmittance_stop,
        plan.conventions.max_alpha(),
    );
    let m = *margins;
    let bg_max = opts.background.iter().fold(0.0f32, |a, &b| a.max(b.abs()));
    let ln_thr = f64::from(thr).ln();
    // One pixel's walk over its tile's list, staged (`Staged`, in list order).
    let walk = |list: &[Staged], i: usize, j: usize| -> PixelWalk {
        let (px, py) = (j as f32 + 0.5, i as f32 + 0.5);
        let mut out = PixelWalk {
            flags: 0,
            sensitivity: 0.0,
            color_max: bg_max,
            depth_max: 0.0,
            alpha: f32::INFINITY,
            transmittance: f32::INFINITY,
            depth: f32::INFINITY,
            clamp: f32::INFINITY,
        };
        let mut tr = 1.0f32;
        // Running bound of T's relative error against a port's.
        let mut t_err = 0.0f64;
        let mut prev_depth: Option<f32> = None;
        // `Σ α/(1 − α)` over the blended splats: how much the backward's division by
        // `1 − α` amplifies α's own rounding in the recovered transmittance.
        let mut amplification = 0.0f64;
        for (k, st) in list.iter().enumerate() {
            let s = &st.splat;
            let (dx, dy) = (s.mean[0] - px, s.mean[1] - py);
            let sigma = splat_sigma(s, dx, dy);
            // σ's rounding: a few ulps of the sum of its terms' magnitudes.
            let scale = sigma_terms(s, dx, dy);
            // (σ = 0 with no terms is the exact centre: 0 in any implementation.)
            if scale > 0.0 && sigma.abs() <= 8.0 * f32::EPSILON * scale {
                out.flags |= PIXEL_SIGMA_SIGN;
            }
            if sigma < 0.0 {
                continue;
            }
            let shift = m.mean2d
                * ((s.conic[0] * dx + s.conic[1] * dy).abs() * s.mean[0].abs()
                    + (s.conic[1] * dx + s.conic[2] * dy).abs() * s.mean[1].abs());
            let ea = m.alpha_error(scale, shift);
            // Far out on the splat (α certainly under 1/255, a skip): when a lower bound of
            // its α margin `|lg| − err` exceeds the pixel's smallest so far and 0, the splat
            // changes nothing (no flag, no minimum) and its f64 terms are not evaluated.
            if sigma >= st.sigma_cut {
                let (adx, ady) = (dx.abs(), dy.abs());
                let w0 = st.conic_abs[0] * adx + st.conic_abs[1] * ady;
                let w1 = st.conic_abs[1] * adx + st.conic_abs[2] * ady;
                let e = ea + (st.k * (w0 * w0 + w1 * w1) + st.relative * sigma);
                let low = (sigma - st.ln_ratio) - e - SKIP_SLACK * (sigma + st.ln_ratio.abs() + e);
                if low > out.alpha.max(0.0) {
                    continue;
                }
            }
            let SplatAlpha { a, alpha, .. } = splat_alpha(s, dx, dy, clamp);
            let conic_err = conic_sigma_error(&st.bound, dx, dy, sigma);
            let err = ea + conic_err;
            let lg = log_gap(st.ln_opacity, sigma, ln_thr);
            if conic_err > m.conic && lg >= -err {
                out.flags |= PIXEL_ILL_CONDITIONED;
            }
            let am = lg.abs() - err;
            out.alpha = out.alpha.min(am);
            if am <= 0.0 {
                out.flags |= PIXEL_ALPHA_THRESHOLD;
            }
            if alpha < thr {
                continue;
            }
            let nt = tr * (1.0 - alpha);
            let bound = t_err + f64::from(alpha / (1.0 - alpha)) * f64::from(err);
            let tm = rel(nt, stop) - bound as f32 - m.transmittance;
            out.transmittance = out.transmittance.min(tm);
            if tm <= 0.0 {
                out.flags |= PIXEL_TRANSMITTANCE_STOP;
            }
            // Bit-equal depths are no tie: both sides order them by Gaussian index (the
            // documented order, SPEC.md §5.3); only a gap within rounding is ambiguous.
            if let Some(z) = prev_depth.filter(|z| z.to_bits() != s.depth.to_bits()) {
                let (lo, hi) = if z <= s.depth {
                    (z, s.depth)
                } else {
                    (s.depth, z)
                };
                let gap = ((f64::from(hi) - f64::from(lo)) / f64::from(hi).abs()) as f32;
                let dm = gap - m.depth;
                out.depth = out.depth.min(dm);
                if dm <= 0.0 {
                    out.flags |= PIXEL_DEPTH_TIE;
                }
            }
            if nt <= stop {
                // A port that orders a following splat of (nearly) the same depth first
                // blends it before deciding on this one: a tie with any that follows
                // within the margin and passes the α test (lists are sorted by depth).
                for nst in &list[k + 1..] {
                    let n = &nst.splat;
                    let gap = (f64::from(n.depth) - f64::from(s.depth)) / f64::from(n.depth);
                    if gap > f64::from(m.depth) {
                        break;
                    }
                    if n.depth.to_bits() == s.depth.to_bits() {
                        continue; // follows in index order on both sides
                    }
                    let (ndx, ndy) = (n.mean[0] - px, n.mean[1] - py);
                    let na = splat_alpha(n, ndx, ndy, clamp);
                    let nerr = m.alpha_error(sigma_terms(n, ndx, ndy), 0.0)
                        + conic_sigma_error(&nst.bound, ndx, ndy, na.sigma);
                    if na.sigma >= 0.0 && log_gap(nst.ln_opacity, na.sigma, ln_thr) >= -nerr {
                        out.flags |= PIXEL_DEPTH_TIE;
                        out.depth = out.depth.min(gap as f32 - m.depth);
                    }
                }
                break;
            }
            let cm = rel(a, clamp) - err;
            out.clamp = out.clamp.min(cm);
            if cm <= 0.0 {
                out.flags |= PIXEL_ALPHA_CLAMP;
            }
            if a >= clamp {
                out.flags |= PIXEL_CLAMPED;
            }
            out.sensitivity += tr * alpha * err;
            amplification += f64::from(alpha / (1.0 - alpha));
            out.color_max = out
                .color_max
                .max(s.color[0].max(s.color[1]).max(s.color[2]));
            out.depth_max = out.depth_max.max(s.depth);
            tr = nt;
            t_err = bound + f64::from(f32::EPSILON);
            prev_depth = Some(s.depth);
        }
        if amplification * f64::from(m.alpha) > f64::from(m.recovery) {
            out.flags |= PIXEL_RECOVERY;
        }
        out
    };
    // Tile by tile (its list staged once, contiguous, for its 256 pixels), each band of
    // tile rows filling its own rows of the row-major result: every pixel's walk is
    // independent of the others and of the thread count.
    let mut walks: Vec<PixelWalk> = vec![PixelWalk::EMPTY; w * h];
    walks
        .par_chunks_mut(TILE_SIZE * w.max(1))
        .enumerate()
        .for_each_init(Vec::new, |staged: &mut Vec<Staged>, (ty, band)| {
            for tx in 0..bins.tiles_x {
                staged.clear();
                staged.extend(bins.tile(ty * bins.tiles_x + tx).iter().map(|&gid| {
                    let s = p.splats[gid as usize];
                    Staged::new(s, ln_thr, rounding[gid as usize].map(|r| r.bound))
                }));
                let rows = band.len() / w;
                for di in 0..rows {
                    for j in tx * TILE_SIZE..((tx + 1) * TILE_SIZE).min(w) {
                        band[di * w + j] = walk(staged, ty * TILE_SIZE + di, j);
                    }
                }
            }
        });
    let mut gaussian_flags = gaussian_decisions(scene, cam, &m);
    for (f, r) in gaussian_flags.iter_mut().zip(&rounding) {
        if r.is_some_and(|r| CONIC_ROUNDING * unit * r.geometric > f64::from(m.conic)) {
            *f |= GAUSSIAN_ILL_CONDITIONED;
        }
    }
    let field = |get: fn(&ConicRounding) -> f64| -> Vec<f32> {
        rounding
            .iter()
            .map(|r| r.as_ref().map_or(0.0, |r| get(r) as f32))
            .collect()
    };
    Ok(Decisions {
        width: w,
        height: h,
        pixel_flags: walks.iter().map(|p| p.flags).collect(),
        alpha_margin: walks.iter().map(|p| p.alpha).collect(),
        transmittance_margin: walks.iter().map(|p| p.transmittance).collect(),
        depth_margin: walks.iter().map(|p| p.depth).collect(),
        clamp_margin: walks.iter().map(|p| p.clamp).collect(),
        alpha_error: walks.iter().map(|p| p.sensitivity).collect(),
        rgb_error: walks.iter().map(|p| p.sensitivity * p.color_max).collect(),
        depth_error: walks.iter().map(|p| p.sensitivity * p.depth_max).collect(),
        gaussian_flags,
        conic_amplification: field(|r| r.amplification),
        condition: field(|r| r.condition),
        margins: m,
    })
}

/// The projection's decisions per Gaussian, in f64 (only a flag's margin depends on them):
/// the opacity cull, the near and far planes, the Jacobian guard's clamp of `x/z`, `y/z`.
fn gaussian_decisions(scene: &Gaussians, cam: &Camera, m: &Margins) -> Vec<u8> {
    let r = cam.camera_from_world_rotation();
    let t = cam.camera_from_world_translation();
    let (w, h) = (f64::from(cam.width), f64::from(cam.height));
    let guard = f64::from(JACOBIAN_GUARD);
    let lim_x = (
        cam.cx / cam.fx + guard * 0.5 * w / cam.fx,
        (w - cam.cx) / cam.fx + guard * 0.5 * w / cam.fx,
    );
    let lim_y = (
        cam.cy / cam.fy + guard * 0.5 * h / cam.fy,
        (h - cam.cy) / cam.fy + guard * 0.5 * h / cam.fy,
    );
    let near = |v: f64, t: f64, margin: f32| ((v / t) - 1.0).abs() <= f64::from(margin);
    (0..scene.len())
        .into_par_iter()
        .map(|i| {
            let mut f = 0;
            let o = 1.0 / (1.0 + (-f64::from(scene.opacity_logits[i])).exp());
            if near(o, f64::from(ALPHA_THRESHOLD), m.alpha) {
                f |= GAUSSIAN_OPACITY_CULL;
            }
            let mu = scene.means[i].map(f64::from);
            let c = r * glam::DVec3::from(mu) + t;
            if near(c.z, f64::from(NEAR_PLANE), m.depth) || near(c.z, f64::from(FAR_PLANE), m.depth)
            {
                f |= GAUSSIAN_DEPTH_CULL;
            }
            if c.z > 0.0 {
                let (u, v) = (c.x / c.z, c.y / c.z);
                if near(-u, lim_x.0, m.alpha)
                    || near(u, lim_x.1, m.alpha)
                    || near(-v, lim_y.0, m.alpha)
                    || near(v, lim_y.1, m.alpha)
                {
                    f |= GAUSSIAN_JACOBIAN_CLAMP;
                }
            }
            f
        })
        .collect()
}

/// How far float32 rounding can move a Gaussian's conic, as a multiple of the unit
/// roundoff: `(1 + e_a + e_c + e_d + e_t)·e_q`, evaluated in f64 from the f32 inputs
/// (SPEC.md §8.1).
/// With `F = J·Q·diag(s)` (`Q = W·R`), every entry of `F`'s row `r` carries an absolute
/// rounding error of a few ulps of `|J_r|·s_k` (the rotation's entries are good to a few
/// ulps of 1), so the dilated variance `a = |F₀|² + ε` moves by `2·|F₀|·|J₀|·|s|` ulps:
/// relative, `e_a = |J₀|·|s|/√a` (likewise `e_c`; the covariance `b` relative to `√(a·c)`
/// by at most their sum). The determinant's minors `s_i·s_j·(Qᵀ·(J₀ × J₁))_k` carry a few
/// ulps of `s_i·s_j·|J₀ × J₁|` each: relative to the dilated determinant, `e_d =
/// 2·|J₀ × J₁|·Σ_k |μ_k|·s_i·s_j / det`. An ordinary Gaussian has each term of order 1; a
/// needle whose long axis projects (nearly) onto a pixel axis, or points (nearly) at the
/// camera, has one of them as large as its aspect ratio: no float32 evaluation of the
/// projection resolves its thin axis there. Two more sources scale every term: the
/// camera-space mean, whose coordinates carry a few ulps of their terms' magnitudes `m_a =
/// Σ_k |W_ak·μ_k| + |t_a|` (large against z near the plane, with the camera far from the
/// origin), moves J by `e_t = (2·m_z + m_x + m_y)/z`; and a quaternion whose squares are
/// f32 subnormals (`|q|² < 2⁻¹²⁶`) gives a rotation good only to `2⁻¹⁴⁹/|q|²`, `e_q =
/// max(1, 2⁻¹⁴⁹/(u·|q|²))` units of roundoff.
pub fn conic_rounding(scene: &Gaussians, i: usize, cam: &CameraF32) -> ConicRounding {
    let dot3 = |u: [f64; 3], v: [f64; 3]| (u[0] * v[0] + u[1] * v[1]) + u[2] * v[2];
    let m = scene.means[i].map(f64::from);
    let r = cam.r_cw.map(|row| row.map(f64::from));
    let t: [f64; 3] = std::array::from_fn(|a| {
        (r[a][0] * m[0] + r[a][1] * m[1]) + r[a][2] * m[2] + f64::from(cam.t_cw[a])
    });
    let q = scene.quats[i].map(f64::from);
    let qn = ((q[0] * q[0] + q[1] * q[1]) + (q[2] * q[2] + q[3] * q[3])).sqrt();
    let rot = crate::math::rotation_f64(q);
    let s = scene.log_scales[i].map(|v| f64::from(v).exp());
    let (fx, fy) = (f64::from(cam.fx), f64::from(cam.fy));
    let (w, h) = (f64::from(cam.width), f64::from(cam.height));
    let guard = f64::from(JACOBIAN_GUARD);
    let clamp = |u: f64, c: f64, f: f64, size: f64| {
        u.clamp(
            -(c / f + guard * 0.5 * size / f),
            (size - c) / f + guard * 0.5 * size / f,
        )
    };
    let z = t[2];
    let tx = z * clamp(t[0] / z, f64::from(cam.cx), fx, w);
    let ty = z * clamp(t[1] / z, f64::from(cam.cy), fy, h);
    let j = [
        [fx / z, 0.0, -fx * tx / (z * z)],
        [0.0, fy / z, -fy * ty / (z * z)],
    ];
    let Factor64 {
        f,
        jc,
        ss,
        minors: mu,
        ..
    } = factor64(&r, &rot, &j, s);
    let eps = f64::from(EPS2D);
    let (a, c) = (dot3(f[0], f[0]) + eps, dot3(f[1], f[1]) + eps);
    let det = dot3(mu, mu) + eps * (a + c - 2.0 * eps) + eps * eps;
    let norm = |v: [f64; 3]| dot3(v, v).sqrt();
    let terms = |a: usize| {
        (0..3).map(|k| (r[a][k] * m[k]).abs()).sum::<f64>() + f64::from(cam.t_cw[a]).abs()
    };
    let e_t = (2.0 * terms(2) + terms(0) + terms(1)) / z;
    let unit = f64::from(f32::EPSILON) / 2.0;
    let e_q = (2f64.powi(-149) / (unit * qn * qn)).max(1.0);
    let e_a = norm(j[0]) * norm(s) / a.sqrt();
    let e_c = norm(j[1]) * norm(s) / c.sqrt();
    let e_d = 2.0 * norm(jc) * (0..3).map(|k| mu[k].abs() * ss[k]).sum::<f64>() / det;
    let b = dot3(f[0], f[1]);
    let lmax = 0.5 * (a + c) + (0.25 * (a - c) * (a - c) + b * b).sqrt();
    let gamma = CONIC_ROUNDING * unit * e_q;
    ConicRounding {
        amplification: (1.0 + e_a + e_c + e_d + e_t) * e_q,
        geometric: (1.0 + e_a + e_c + e_d) * e_q,
        condition: lmax * lmax / det,
        bound: SigmaBound {
            conic: [c / det, -b / det, a / det],
            f,
            row_scale: [gamma * norm(j[0]), gamma * norm(j[1])],
            s,
            relative: gamma * (1.0 + e_d),
        },
    }
}

/// How float32 rounding may move one Gaussian's conic ([`conic_rounding`]).
#[derive(Clone, Copy, Debug)]
pub struct ConicRounding {
    /// κ: the conic's entries lie within `CONIC_ROUNDING·u·κ` (relative) of the exact ones.
    pub amplification: f64,
    /// κ without the camera-space mean's share `e_t`: that share scales σ as a whole, as
    /// two implementations' rounding of z does near the plane, which the `sigma` margin
    /// already allows (its ×2.5 for near-plane scenes); it neither widens a splat's error
    /// nor flags a Gaussian.
    pub geometric: f64,
    /// `λ_max/λ_min` of the dilated 2D covariance.
    pub condition: f64,
    bound: SigmaBound,
}

/// What [`ConicRounding::sigma_error`] reads.
#[derive(Clone, Copy, Debug)]
struct SigmaBound {
    /// The exact conic (in f64 from the f32 inputs): the bound's `w = conic·d` must not carry
    /// the f32 conic's own rounding, which across a needle is a spurious component along it.
    conic: [f64; 3],
    /// The factor `F = J·Q·diag(s)` (exact, in f64), the bound's `γ·|J_r|` per row (`γ =
    /// CONIC_ROUNDING·u·e_q`), the scales, and the relative part `γ·(1 + e_d)`.
    f: [[f64; 3]; 2],
    row_scale: [f64; 2],
    s: [f64; 3],
    relative: f64,
}

impl ConicRounding {
    /// A bound of how far the conic's rounding moves σ at the offset whose conic gradient
    /// is `w = conic·d`: σ = ½·dᵀ·(F·Fᵀ + ε)⁻¹·d moves by `−(wᵀ·δF)·(Fᵀ·w)` when F moves by
    /// δF, and each column k of δF is within `γ·|J_r|·s_k` per row r, so
    /// `|δσ| ≤ Σ_k (|w₀|·γ|J₀| + |w₁|·γ|J₁|)·s_k·|w·F_k| + γ·(1 + e_d)·σ` (the
    /// determinant's rounding scales σ as a whole; the mean's, `e_t`, see
    /// [`ConicRounding::geometric`]). Tighter than
    /// `ρ·|σ|₊` where it matters: across a needle near its centre `w·F_long ≈ 0`, so its
    /// long axis's rounding (a tilt of ~γ radians) counts only in proportion to the
    /// distance along it.
    pub fn sigma_error(&self, w: [f64; 2], sigma: f64) -> f64 {
        self.bound.sigma_error(w, sigma)
    }
}

impl SigmaBound {
    fn sigma_error(&self, w: [f64; 2], sigma: f64) -> f64 {
        let row = w[0].abs() * self.row_scale[0] + w[1].abs() * self.row_scale[1];
        let cols: f64 = (0..3)
            .map(|k| self.s[k] * (w[0] * self.f[0][k] + w[1] * self.f[1][k]).abs())
            .sum();
        row * cols + self.relative * sigma.abs()
    }
}

/// [`ConicRounding::sigma_error`] at offset `(dx, dy)` from the splat's centre (0 where the
/// Gaussian has no bound: it was culled).
fn conic_sigma_error(r: &Option<SigmaBound>, dx: f32, dy: f32, sigma: f32) -> f32 {
    r.as_ref().map_or(0.0, |r| {
        let [a, b, c] = r.conic;
        let (dx, dy) = (f64::from(dx), f64::from(dy));
        r.sigma_error([a * dx + b * dy, b * dx + c * dy], f64::from(sigma)) as f32
    })
}
