//! Backward of the projection (mirrors `raster::project`): from splat gradients to the raw
//! parameters. Per Gaussian and independent, so parallel and deterministic. All in f32,
//! the geometric chain and the SH direction derivative (forward-mode duals of the basis,
//! `Dual3<R>`) in lanes of Gaussians like the projection (`math::lanes`), the colour and SH
//! coefficient gradients one Gaussian at a time (they read the coefficients in memory order,
//! which lanes would gather and scatter).
//!
//! Chain (forward in `raster::project`):
//! `conic = Σ2d⁻¹` → `v_Σ2d = −Σ2d⁻¹·G·Σ2d⁻¹` with `G = [[vA, vB/2], [vB/2, vC]]`
//! (Σ2d⁻¹ as the forward computes it, from its cancellation-free determinant);
//! `Σ2d = F·Fᵀ (+0.3 I)` → `v_F = 2·V·F`; `F = P·diag(s)` → `v_P = v_F·diag(s)`, `v_s_k =
//! Σ_a v_F_ak·P_ak`, `v_log_s = v_s·s`; `P = J·Q` → `v_J = v_P·Qᵀ`, `v_Q = Jᵀ·v_P`;
//! `Q = W·R` → `v_R = Wᵀ·v_Q`;
//! `R(q̂)` → `v_q̂`; `q̂ = q/|q|` → `v_q = (v_q̂ − q̂(q̂·v_q̂))/|q|`;
//! `J(t)` with the clamp: a clamped `x/z` makes `tx = z·lim`, so its gradient goes to z;
//! `mean2d(t)`; `t = W·μ + t_w` → `v_μ = Wᵀ·v_t` plus the SH direction term;
//! `o = sigmoid(l)` → `v_l = v_o·o·(1 − o)`;
//! `c = max(Σ coeff·Y + 0.5, 0)` → coefficient gradients `Y·v_c` where the clamp is open.

use super::composite::SplatGrad;
use super::wide::{self, SUBNORMAL_INV_NORM, WIDE_CONDITION};
use crate::gaussian::{Gaussians, Param};
use crate::math::lanes::Lanes;
#[cfg(target_arch = "x86_64")]
use crate::math::lanes::{F32x8, F32x16};
use crate::math::sh::{Dual3, MAX_SH_COEFFS, ShScalar, num_coeffs, sh_basis};
use crate::raster::kernel::Kernel;
use crate::raster::plan::RenderPlan;
use crate::raster::project::{
    AHEAD, COPY, CameraF32, Culls, Geometry, MAX_REST, Projected, SPLAT_FLOATS, Splat, copy_padded,
    dot3, gather3, geometry_lanes, lanes_of, mat3_mul, prefetch_rows, sh_basis_lanes, transpose,
};

/// Field offsets (in f32) of a [`Splat`] and a [`SplatGrad`], which share their layout.
const MEAN: usize = 0;
const CONIC: usize = 2;
const OPACITY: usize = 5;
const COLOR: usize = 6;
const DEPTH: usize = 9;
const _: () = {
    use std::mem::offset_of;
    assert!(offset_of!(Splat, mean) == 4 * MEAN && offset_of!(SplatGrad, mean2d) == 4 * MEAN);
    assert!(offset_of!(Splat, conic) == 4 * CONIC && offset_of!(SplatGrad, conic) == 4 * CONIC);
    assert!(offset_of!(Splat, opacity) == 4 * OPACITY);
    assert!(offset_of!(SplatGrad, opacity) == 4 * OPACITY);
    assert!(offset_of!(Splat, color) == 4 * COLOR && offset_of!(SplatGrad, color) == 4 * COLOR);
    assert!(offset_of!(Splat, depth) == 4 * DEPTH && offset_of!(SplatGrad, depth) == 4 * DEPTH);
};

/// Which raw parameter groups need gradients. Skipped groups come back as zeros and cost
/// nothing: SH-only requests skip the whole geometric chain.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GradGroups {
    pub means: bool,
    pub log_scales: bool,
    pub quats: bool,
    pub opacities: bool,
    pub sh_dc: bool,
    pub sh_rest: bool,
    pub background: bool,
}

impl GradGroups {
    pub const ALL: GradGroups = GradGroups {
        means: true,
        log_scales: true,
        quats: true,
        opacities: true,
        sh_dc: true,
        sh_rest: true,
        background: true,
    };
    /// Only the higher SH coefficients (what the QA-Mask fine-tune trains).
    pub const SH_REST: GradGroups = GradGroups {
        means: false,
        log_scales: false,
        quats: false,
        opacities: false,
        sh_dc: false,
        sh_rest: true,
        background: false,
    };
    /// Does any group need the screen-space (mean2d / conic / opacity) gradients?
    pub fn geometry(&self) -> bool {
        self.means || self.log_scales || self.quats || self.opacities
    }
}

/// Gradients of the raw parameters, in the layout of [`Gaussians`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gradients {
    pub means: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    pub quats: Vec<[f32; 4]>,
    pub opacity_logits: Vec<f32>,
    pub sh_dc: Vec<[f32; 3]>,
    /// `(N, K−1, 3)` like [`Gaussians::sh_rest`].
    pub sh_rest: Vec<f32>,
    pub background: [f32; 3],
    /// dL/d mean2d in pixels (what the splat gradients say), per Gaussian.
    pub means2d: Vec<[f32; 2]>,
    /// dL/d mean2d in INRIA's NDC units (`pixels × (W/2, H/2)`), for densification.
    pub means2d_ndc: Vec<[f32; 2]>,
}

/// The parameters the projection backward reads, of Gaussians `base ..` (a whole set, or
/// one chunk of it): entry `i` of each slice is Gaussian `base + i`.
#[derive(Clone, Copy, Debug)]
pub struct ParamView<'a> {
    pub means: &'a [[f32; 3]],
    pub log_scales: &'a [[f32; 3]],
    pub quats: &'a [[f32; 4]],
    pub opacity_logits: &'a [f32],
    /// `rest_per` values per Gaussian, laid out like [`Gaussians::sh_rest`].
    pub sh_rest: &'a [f32],
    pub rest_per: usize,
    pub base: usize,
}

impl<'a> ParamView<'a> {
    /// All of `g`.
    pub fn of(g: &'a Gaussians) -> Self {
        ParamView {
            means: &g.means,
            log_scales: &g.log_scales,
            quats: &g.quats,
            opacity_logits: &g.opacity_logits,
            sh_rest: &g.sh_rest,
            rest_per: g.rest_per_channel() * 3,
            base: 0,
        }
    }
}

/// The gradients of one chunk of Gaussians, laid out like their parameters (entry `k` is
/// the chunk's Gaussian `k`), as [`project_backward_apply`] hands them over.
pub struct ChunkGrads<'a> {
    /// The blend backward's gradients of the chunk's splats (screen-space means among them)
    /// and the forward's radii (`(0, 0)`: culled), entry `k` for Gaussian `k`.
    pub splats: &'a [SplatGrad],
    pub radii: &'a [[i32; 2]],
    pub means: &'a [[f32; 3]],
    pub log_scales: &'a [[f32; 3]],
    pub quats: &'a [[f32; 4]],
    pub opacity_logits: &'a [f32],
    pub sh_dc: &'a [[f32; 3]],
    pub sh_rest: &'a [f32],
}

impl ChunkGrads<'_> {
    /// The flat gradient of one parameter group (the layout of [`Gaussians::param`]).
    pub fn param(&self, p: Param) -> &[f32] {
        match p {
            Param::Means => self.means.as_flattened(),
            Param::ShDc => self.sh_dc.as_flattened(),
            Param::ShRest => self.sh_rest,
            Param::OpacityLogits => self.opacity_logits,
            Param::LogScales => self.log_scales.as_flattened(),
            Param::Quats => self.quats.as_flattened(),
        }
    }
}

/// Where [`project_backward_apply`] delivers a chunk's gradients: the chunk's parameters
/// (read by the backward) and what to do with its gradients (an optimizer step, say), so
/// the gradients of a whole scene are never stored.
pub trait GradSink: Send {
    /// The parameters of the chunk (`base`: its first Gaussian).
    fn params(&self) -> ParamView<'_>;
    /// Take the chunk's gradients, after the backward has read its parameters.
    fn take(&mut self, grads: &ChunkGrads);
}

/// Gaussians per parallel chunk of the projection backward: a fixed partition.
pub const CHUNK: usize = 1024;

/// One chunk of the outputs (entry `k` is Gaussian `first + k`); `rest` holds `rest_per`
/// values per Gaussian.
struct OutChunk<'a> {
    means: &'a mut [[f32; 3]],
    log_scales: &'a mut [[f32; 3]],
    quats: &'a mut [[f32; 4]],
    opacity: &'a mut [f32],
    sh_dc: &'a mut [[f32; 3]],
    rest: &'a mut [f32],
    rest_per: usize,
}

/// The backward of Gaussians `first .. first + R::N`, one per lane, into entries
/// `k .. k + R::N` of `out`, every entry of them (the buffers are reused): lanes the forward
/// culled (radii `(0, 0)`) get +0.0, a lane whose geometry the forward culled gets only its
/// SH gradients, skipped groups and coefficients above the plan's degree +0.0. The `f32` instance is the reference form; every lane of a wider instance
/// equals it bit for bit (`projection_backward_simd_matches_scalar_bitwise`).
#[inline(always)]
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)] // a, b index matrices
fn backward_block<R: Lanes>(
    g: &ParamView,
    first: usize,
    cam: &CameraF32,
    degree: u32,
    groups: &GradGroups,
    sg: &[SplatGrad],
    splats: &[Splat],
    radii: &[[i32; 2]],
    out: &mut OutChunk,
    k: usize,
) {
    let n = R::N;
    out.zero(k, n);
    let visible: [bool; 16] = std::array::from_fn(|l| l < n && radii[first + l] != [0, 0]);
    if !visible.contains(&true) {
        return;
    }
    let k_used = num_coeffs(degree) - 1;
    // Offset of the block in the view's slices.
    let at = first - g.base;
    let mean = gather3::<R>(&g.means[at..at + n]);
    let c = R::splat;
    let zero = c(0.0);
    // The forward's basis, by the forward's own code (lanes give the scalar bits).
    let basis = sh_basis_lanes(mean, cam, degree);
    // The splats' gradients and the forward's colours, field by field.
    let mut grad = [zero; SPLAT_FLOATS];
    R::load_columns(SplatGrad::floats(&sg[..n]), SPLAT_FLOATS, &mut grad);
    let mut colour = [zero; 3];
    let fwd_floats = Splat::floats(&splats[first..first + n]);
    R::load_columns(&fwd_floats[COLOR..], SPLAT_FLOATS, &mut colour);
    let vis = R::gather(|l| if visible[l] { 1.0 } else { 0.0 }).gt(zero);
    // The colour gradient where the forward's clamp was open (colour > 0 ⇔ the SH sum
    // > 0) in a visible lane, else 0; the products of culled lanes are selected to the +0.0
    // their entries already hold.
    // Explicit arrays, not `array::from_fn`/`map` with closures: those may stay out of
    // line, compiled without the instruction set (`math::lanes`).
    let mut v = [zero; 3];
    for ch in 0..3 {
        v[ch] = R::select(colour[ch].gt(zero) & vis, grad[COLOR + ch], zero);
    }
    if groups.sh_dc {
        let mut cols = [zero; 3];
        for ch in 0..3 {
            cols[ch] = R::select(vis, basis[0] * v[ch], zero);
        }
        R::store_columns(&cols, out.sh_dc[k..k + n].as_flattened_mut(), 3);
    }
    // The coefficient gradients `Y_k·v_c`, column by column in the rows' layout, sixteen
    // columns per transposed store.
    if groups.sh_rest {
        let stride = out.rest_per;
        let dst = &mut out.rest[k * stride..(k + n) * stride];
        let total = 3 * k_used;
        let mut cols = [zero; 16];
        let mut c0 = 0;
        while c0 < total {
            let width = (total - c0).min(16);
            for (q, col) in cols.iter_mut().enumerate().take(width) {
                let (j, ch) = ((c0 + q) / 3, (c0 + q) % 3);
                *col = R::select(vis, basis[j + 1] * v[ch], zero);
            }
            R::store_columns(&cols[..width], &mut dst[c0..], stride);
            c0 += 16;
        }
    }
    // The weights `w_k = Σ_c coeff_kc·v_c` of the direction term, the coefficients loaded
    // as the forward loads them (eight per step), and where a colour gradient flows.
    let mut w = [zero; MAX_SH_COEFFS - 1];
    let mut flows = R::all_false();
    if groups.means {
        let stride = g.rest_per;
        let rest = &g.sh_rest[at * stride..(at + n) * stride];
        let mut cols = [zero; 24];
        let mut j0 = 0;
        while j0 < k_used {
            let jn = (k_used - j0).min(8);
            R::load_columns(&rest[3 * j0..], stride, &mut cols[..3 * jn]);
            for j in 0..jn {
                let cf = &cols[3 * j..3 * j + 3];
                w[j0 + j] = (cf[0] * v[0] + cf[1] * v[1]) + cf[2] * v[2];
            }
            j0 += 8;
        }
        // `v ≠ 0` (NaN included): not both `≥ 0` and `≤ 0`.
        for vc in v {
            flows = flows | !(vc.ge(zero) & vc.le(zero));
        }
    }
    if !groups.geometry() {
        return;
    }
    // The forward quantities the chain needs, recomputed by the forward's own code; a lane
    // it culls there was culled in the forward too (radii are (0, 0)).
    let q = R::load_dense::<4>(g.quats[at..at + n].as_flattened());
    let ls = gather3::<R>(&g.log_scales[at..at + n]);
    let mut culls = Culls::new();
    let geo = geometry_lanes(mean, q, ls, cam, &mut culls);
    let geo_ok = lanes_of(R::select(culls.ok, c(1.0), zero));
    let ([a_, b_, c_], det) = geo.dilated();
    let Geometry {
        t: [x, y, _],
        qh,
        inv_qn,
        s,
        q_cam,
        rz,
        tx,
        ty,
        x_clamped,
        y_clamped,
        j,
        p,
        f,
        ..
    } = geo;
    let rz2 = rz * rz;
    // Gaussians beyond float32 (a 2D condition above `WIDE_CONDITION`, or a quaternion
    // whose squares are subnormal: `|q|² < 2⁻¹²⁶` ⇔ `1/|q| > 2⁶³`): the chain to the
    // camera-space mean, the scales and the quaternion in f64 (`wide`), selected below.
    let beyond =
        ((a_ + c_) * (a_ + c_)).gt(c(WIDE_CONDITION) * det) | inv_qn.gt(c(SUBNORMAL_INV_NORM));
    let wide_mask = beyond & vis & culls.ok;
    let wide_bits = R::bits(wide_mask);
    // Per lane: v_t (3), v_log_scale (3), v_quat (4); only where some lane is beyond.
    let wide_out = (wide_bits != 0).then(|| {
        let mut out = [[0f32; 10]; 16];
        let s_l = [lanes_of(s[0]), lanes_of(s[1]), lanes_of(s[2])];
        let (cx_bits, cy_bits) = (R::bits(x_clamped), R::bits(y_clamped));
        for l in (0..n).filter(|&l| wide_bits >> l & 1 == 1) {
            let sgl = &sg[l];
            let gr = wide::adjoint(
                &wide::WideInput {
                    mean: g.means[at + l],
                    quat: g.quats[at + l],
                    s: [s_l[0][l], s_l[1][l], s_l[2][l]],
                    clamped: [cx_bits >> l & 1 == 1, cy_bits >> l & 1 == 1],
                    v_mean2d: sgl.mean2d,
                    v_conic: sgl.conic,
                    v_depth: sgl.depth,
                },
                cam,
            );
            let o = &mut out[l];
            o[..3].copy_from_slice(&gr.v_t);
            o[3..6].copy_from_slice(&gr.v_log_scale);
            o[6..].copy_from_slice(&gr.v_quat);
        }
        out
    });
    let wide_lanes = |i: usize, v: R| match &wide_out {
        None => v,
        Some(out) => R::select(wide_mask, R::gather(|l| out[l][i]), v),
    };
    let inv_det = c(1.0) / det;
    let ci = [[c_ * inv_det, -b_ * inv_det], [-b_ * inv_det, a_ * inv_det]];
    // v_Σ2d = −Σ⁻¹·G·Σ⁻¹ with G the symmetric gradient of the conic.
    let half_b = c(0.5) * grad[CONIC + 1];
    let gm = [[grad[CONIC], half_b], [half_b, grad[CONIC + 2]]];
    let mut tmp = [[zero; 2]; 2];
    for a in 0..2 {
        for b in 0..2 {
            tmp[a][b] = ci[a][0] * gm[0][b] + ci[a][1] * gm[1][b];
        }
    }
    let mut v_cov = [[zero; 2]; 2];
    for a in 0..2 {
        for b in 0..2 {
            v_cov[a][b] = -(tmp[a][0] * ci[0][b] + tmp[a][1] * ci[1][b]);
        }
    }
    // Σ2d = F·Fᵀ → v_F = 2·V·F; F = P·diag(s) → v_P = v_F·diag(s); P = J·Q → v_J = v_P·Qᵀ
    // (V symmetric).
    let mut v_f = [[zero; 3]; 2];
    let mut v_p = [[zero; 3]; 2];
    for a in 0..2 {
        for k in 0..3 {
            v_f[a][k] = c(2.0) * (v_cov[a][0] * f[0][k] + v_cov[a][1] * f[1][k]);
            v_p[a][k] = v_f[a][k] * s[k];
        }
    }
    let mut v_j = [[zero; 3]; 2];
    for a in 0..2 {
        for i in 0..3 {
            v_j[a][i] = dot3(v_p[a], q_cam[i]);
        }
    }
    // Camera-space mean.
    let (fx, fy) = (c(cam.fx), c(cam.fy));
    let v_m2d = [grad[MEAN], grad[MEAN + 1]];
    let mut v_t = [
        v_m2d[0] * fx * rz,
        v_m2d[1] * fy * rz,
        -(v_m2d[0] * fx * x + v_m2d[1] * fy * y) * rz2 + grad[DEPTH],
    ];
    let v_tx = v_j[0][2] * (c(-cam.fx) * rz2);
    let v_ty = v_j[1][2] * (c(-cam.fy) * rz2);
    v_t[2] = v_t[2]
        + (v_j[0][0] * (c(-cam.fx) * rz2)
            + v_j[1][1] * (c(-cam.fy) * rz2)
            + v_j[0][2] * (c(2.0 * cam.fx) * tx * rz2 * rz)
            + v_j[1][2] * (c(2.0 * cam.fy) * ty * rz2 * rz));
    // A clamped x/z makes tx = z·lim: its gradient goes to z.
    v_t[2] = R::select(x_clamped, v_t[2] + v_tx * (tx * rz), v_t[2]);
    v_t[0] = R::select(x_clamped, v_t[0], v_t[0] + v_tx);
    v_t[2] = R::select(y_clamped, v_t[2] + v_ty * (ty * rz), v_t[2]);
    v_t[1] = R::select(y_clamped, v_t[1], v_t[1] + v_ty);
    for a in 0..3 {
        v_t[a] = wide_lanes(a, v_t[a]);
    }
    let mut r = [[zero; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            r[a][b] = c(cam.r_cw[a][b]);
        }
    }
    if groups.means {
        let mut v_mu = [zero; 3];
        for a in 0..3 {
            v_mu[a] = (r[0][a] * v_t[0] + r[1][a] * v_t[1]) + r[2][a] * v_t[2];
        }
        // The colour depends on the mean through dir = (μ − C)/|μ − C|: the derivative of
        // Σ_k w_k·Y_k(dir) by forward-mode duals of the basis, then through the
        // normalization (only where some colour gradient flows).
        if degree > 0 {
            let d = [
                mean[0] - c(cam.center[0]),
                mean[1] - c(cam.center[1]),
                mean[2] - c(cam.center[2]),
            ];
            let len = dot3(d, d).sqrt();
            let dir = [d[0] / len, d[1] / len, d[2] / len];
            let mut yk = [Dual3::<R>::c(0.0); MAX_SH_COEFFS];
            let (ux, uy) = (Dual3::var(dir[0], 0), Dual3::var(dir[1], 1));
            sh_basis(degree, ux, uy, Dual3::var(dir[2], 2), &mut yk);
            let mut v_dir = [zero; 3];
            for kk in 1..=k_used {
                let wk = w[kk - 1];
                for a in 0..3 {
                    v_dir[a] = v_dir[a] + wk * yk[kk].d[a];
                }
            }
            let dd = dot3(dir, v_dir);
            for a in 0..3 {
                let v = v_mu[a] + (v_dir[a] - dir[a] * dd) / len;
                v_mu[a] = R::select(flows, v, v_mu[a]);
            }
        }
        let v = [lanes_of(v_mu[0]), lanes_of(v_mu[1]), lanes_of(v_mu[2])];
        for l in 0..n {
            if visible[l] && geo_ok[l] != 0.0 {
                out.means[k + l] = [v[0][l], v[1][l], v[2][l]];
            }
        }
    }
    if groups.opacities {
        let [logit] = R::load_dense::<1>(&g.opacity_logits[at..at + n]);
        let o = c(1.0) / (c(1.0) + (-logit).exp()); // fastexp::sigmoid
        let v = lanes_of(grad[OPACITY] * o * (c(1.0) - o));
        for l in 0..n {
            if visible[l] && geo_ok[l] != 0.0 {
                out.opacity[k + l] = v[l];
            }
        }
    }
    if groups.log_scales || groups.quats {
        if groups.log_scales {
            // F = P·diag(s): v_s_k = Σ_a v_F[a][k]·P[a][k]; v_log_s = v_s·s.
            let mut v_ls = [zero; 3];
            for e in 0..3 {
                v_ls[e] = wide_lanes(3 + e, (v_f[0][e] * p[0][e] + v_f[1][e] * p[1][e]) * s[e]);
            }
            let v = [lanes_of(v_ls[0]), lanes_of(v_ls[1]), lanes_of(v_ls[2])];
            for l in 0..n {
                if visible[l] && geo_ok[l] != 0.0 {
                    out.log_scales[k + l] = [v[0][l], v[1][l], v[2][l]];
                }
            }
        }
        if groups.quats {
            // P = J·Q → v_Q = Jᵀ·v_P; Q = W·R → v_R = Wᵀ·v_Q.
            let mut v_q = [[zero; 3]; 3];
            for i in 0..3 {
                for k in 0..3 {
                    v_q[i][k] = j[0][i] * v_p[0][k] + j[1][i] * v_p[1][k];
                }
            }
            let vr = mat3_mul(&transpose(&r), &v_q);
            let [w_, x_, y_, z_] = qh;
            let two = c(2.0);
            let vq = [
                two * (-z_ * vr[0][1] + y_ * vr[0][2] + z_ * vr[1][0]
                    - x_ * vr[1][2]
                    - y_ * vr[2][0]
                    + x_ * vr[2][1]),
                two * (y_ * vr[0][1] + z_ * vr[0][2] + y_ * vr[1][0]
                    - two * x_ * vr[1][1]
                    - w_ * vr[1][2]
                    + z_ * vr[2][0]
                    + w_ * vr[2][1]
                    - two * x_ * vr[2][2]),
                two * (c(-2.0) * y_ * vr[0][0]
                    + x_ * vr[0][1]
                    + w_ * vr[0][2]
                    + x_ * vr[1][0]
                    + z_ * vr[1][2]
                    - w_ * vr[2][0]
                    + z_ * vr[2][1]
                    - two * y_ * vr[2][2]),
                two * (c(-2.0) * z_ * vr[0][0] - w_ * vr[0][1] + x_ * vr[0][2] + w_ * vr[1][0]
                    - two * z_ * vr[1][1]
                    + y_ * vr[1][2]
                    + x_ * vr[2][0]
                    + y_ * vr[2][1]),
            ];
            let dot = (qh[0] * vq[0] + qh[1] * vq[1]) + (qh[2] * vq[2] + qh[3] * vq[3]);
            let v = [
                lanes_of(wide_lanes(6, (vq[0] - qh[0] * dot) * inv_qn)),
                lanes_of(wide_lanes(7, (vq[1] - qh[1] * dot) * inv_qn)),
                lanes_of(wide_lanes(8, (vq[2] - qh[2] * dot) * inv_qn)),
                lanes_of(wide_lanes(9, (vq[3] - qh[3] * dot) * inv_qn)),
            ];
            for l in 0..n {
                if visible[l] && geo_ok[l] != 0.0 {
                    out.quats[k + l] = [v[0][l], v[1][l], v[2][l], v[3][l]];
                }
            }
        }
    }
}

impl OutChunk<'_> {
    /// Zero entries `k .. k + n` (in cache just before the block writes them: no pass over
    /// the whole arrays).
    #[inline(always)]
    fn zero(&mut self, k: usize, n: usize) {
        self.means[k..k + n].fill([0.0; 3]);
        self.log_scales[k..k + n].fill([0.0; 3]);
        self.quats[k..k + n].fill([0.0; 4]);
        self.opacity[k..k + n].fill(0.0);
        self.sh_dc[k..k + n].fill([0.0; 3]);
        self.rest[k * self.rest_per..(k + n) * self.rest_per].fill(0.0);
    }
}

/// The inputs of one block of the visible Gaussians of a chunk, copied side by side so
/// that [`backward_block`] reads them as consecutive Gaussians; `slot[l]` is lane `l`'s
/// entry in the chunk.
struct Staged {
    slot: [usize; 16],
    means: [[f32; 3]; 16],
    log_scales: [[f32; 3]; 16],
    quats: [[f32; 4]; 16],
    logits: [f32; 16],
    rest: [f32; 16 * MAX_REST],
    splats: [Splat; 16],
    radii: [[i32; 2]; 16],
    sg: [SplatGrad; 16],
}

/// The outputs of one staged block, entry `l` for lane `l`.
struct StagedOut {
    means: [[f32; 3]; 16],
    log_scales: [[f32; 3]; 16],
    quats: [[f32; 4]; 16],
    opacity: [f32; 16],
    sh_dc: [[f32; 3]; 16],
    rest: [f32; 16 * MAX_REST],
}

/// [`backward_block`] over a chunk, `R::N` consecutive Gaussians at a time where the
/// forward culled none of them; elsewhere (about half of a scene's Gaussians are culled
/// from a training view: off screen or behind the camera, and in a block of sixteen one
/// of them almost always is) the entries are zeroed and only the visible Gaussians are
/// staged side by side ([`Staged`]), `R::N` per block, their gradients copied to their
/// entries; a partly filled staged block's other lanes hold earlier inputs (or zeros),
/// whose outputs are not copied. A lane's result depends only on its own inputs, so this
/// gives the bits of every Gaussian's own block (and of the scalar form).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn backward_range<R: Lanes>(
    g: &ParamView,
    first: usize,
    cam: &CameraF32,
    degree: u32,
    groups: &GradGroups,
    sg: &[SplatGrad],
    fwd: &Projected,
    out: &mut OutChunk,
) {
    let n = out.means.len();
    // Staged rows are padded to whole copy chunks (the block reads only a row's first
    // `3·k_used ≤ rest_per` values, so the stride may be wider).
    let (rest_in, rest_out) = (g.rest_per, out.rest_per);
    let (pad_in, pad_out) = (
        rest_in.div_ceil(COPY) * COPY,
        rest_out.div_ceil(COPY) * COPY,
    );
    assert!(
        pad_in <= MAX_REST && pad_out <= MAX_REST,
        "{rest_in} / {rest_out} rest values per Gaussian: more than SH degree 5 has"
    );
    let mut st = Staged {
        slot: [0; 16],
        means: [[0.0; 3]; 16],
        log_scales: [[0.0; 3]; 16],
        quats: [[0.0; 4]; 16],
        logits: [0.0; 16],
        rest: [0.0; 16 * MAX_REST],
        splats: [Splat::default(); 16],
        radii: [[0; 2]; 16],
        sg: [SplatGrad::default(); 16],
    };
    let mut so = StagedOut {
        means: [[0.0; 3]; 16],
        log_scales: [[0.0; 3]; 16],
        quats: [[0.0; 4]; 16],
        opacity: [0.0; 16],
        sh_dc: [[0.0; 3]; 16],
        rest: [0.0; 16 * MAX_REST],
    };
    // Staged entries are copied out in ascending order, each before any later entry gets
    // a value other than zero: a row's copy may spill zeros onto the head of the next
    // entries' rows (see `run_staged`). So every staged block runs before the next direct
    // block; a later mixed block may only have been zeroed (`out.zero`) by then.
    let mut used = 0;
    // Mixed blocks whose survivors' rows were asked for and are not yet staged (block
    // start, survivor bits), oldest first: staged `AHEAD` mixed blocks later, so that the
    // rows have arrived by then; all of them before a direct block (the order above).
    let mut pending = [(0usize, 0u32); AHEAD];
    let (mut head, mut queued) = (0usize, 0usize);
    let mut k = 0;
    while k < n {
        let width = R::N.min(n - k);
        let visible = |l: usize| fwd.radii[first + k + l] != [0, 0];
        if width == R::N && (0..width).all(visible) {
            for q in 0..queued {
                let (k0, ok0) = pending[(head + q) % AHEAD];
                stage_block::<R>(
                    g, first, k0, ok0, cam, degree, groups, sg, fwd, &mut st, &mut used, &mut so,
                    out, pad_in, pad_out,
                );
            }
            (head, queued) = (0, 0);
            if used > 0 {
                run_staged::<R>(
                    &st, used, &mut so, out, cam, degree, groups, pad_in, pad_out,
                );
                used = 0;
            }
            backward_block::<R>(
                g,
                first + k,
                cam,
                degree,
                groups,
                &sg[first + k..],
                &fwd.splats,
                &fwd.radii,
                out,
                k,
            );
            k += width;
            continue;
        }
        out.zero(k, width);
        let ok = (0..width)
            .filter(|&l| visible(l))
            .fold(0, |m, l| m | 1 << l);
        if ok != 0 {
            prefetch_rows(g.sh_rest, rest_in, first + k - g.base, ok, pad_in);
            if queued == AHEAD {
                let (k0, ok0) = pending[head];
                stage_block::<R>(
                    g, first, k0, ok0, cam, degree, groups, sg, fwd, &mut st, &mut used, &mut so,
                    out, pad_in, pad_out,
                );
                queued -= 1;
                head = (head + 1) % AHEAD;
            }
            pending[(head + queued) % AHEAD] = (k, ok);
            queued += 1;
        }
        k += width;
    }
    for q in 0..queued {
        let (k0, ok0) = pending[(head + q) % AHEAD];
        stage_block::<R>(
            g, first, k0, ok0, cam, degree, groups, sg, fwd, &mut st, &mut used, &mut so, out,
            pad_in, pad_out,
        );
    }
    if used > 0 {
        run_staged::<R>(
            &st, used, &mut so, out, cam, degree, groups, pad_in, pad_out,
        );
    }
}

/// Stage the survivors `ok` of the block at entry `k` after the `used` already staged,
/// running the staged block whenever it is full ([`backward_range`]).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn stage_block<R: Lanes>(
    g: &ParamView,
    first: usize,
    k: usize,
    ok: u32,
    cam: &CameraF32,
    degree: u32,
    groups: &GradGroups,
    sg: &[SplatGrad],
    fwd: &Projected,
    st: &mut Staged,
    used: &mut usize,
    so: &mut StagedOut,
    out: &mut OutChunk,
    pad_in: usize,
    pad_out: usize,
) {
    let rest_in = g.rest_per;
    let mut left = ok;
    while left != 0 {
        let l = left.trailing_zeros() as usize;
        left &= left - 1;
        let (i, at, u) = (first + k + l, first + k + l - g.base, *used);
        st.slot[u] = k + l;
        st.means[u] = g.means[at];
        st.log_scales[u] = g.log_scales[at];
        st.quats[u] = g.quats[at];
        st.logits[u] = g.opacity_logits[at];
        copy_padded(
            &mut st.rest[u * pad_in..(u + 1) * pad_in],
            &g.sh_rest[at * rest_in..],
            rest_in,
        );
        st.splats[u] = fwd.splats[i];
        st.radii[u] = fwd.radii[i];
        st.sg[u] = sg[i];
        *used = u + 1;
        if *used == R::N {
            run_staged::<R>(st, R::N, so, out, cam, degree, groups, pad_in, pad_out);
            *used = 0;
        }
    }
}

/// [`backward_block`] on a staged block, its first `used` lanes' gradients copied to their
/// chunk entries. A function, not a closure: a closure in a `#[target_feature]` function is
/// compiled without the feature and would call every vector intrinsic out of line.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn run_staged<R: Lanes>(
    st: &Staged,
    used: usize,
    so: &mut StagedOut,
    out: &mut OutChunk,
    cam: &CameraF32,
    degree: u32,
    groups: &GradGroups,
    pad_in: usize,
    pad_out: usize,
) {
    let view = ParamView {
        means: &st.means[..R::N],
        log_scales: &st.log_scales[..R::N],
        quats: &st.quats[..R::N],
        opacity_logits: &st.logits[..R::N],
        sh_rest: &st.rest[..R::N * pad_in],
        rest_per: pad_in,
        base: 0,
    };
    let mut o = OutChunk {
        means: &mut so.means[..R::N],
        log_scales: &mut so.log_scales[..R::N],
        quats: &mut so.quats[..R::N],
        opacity: &mut so.opacity[..R::N],
        sh_dc: &mut so.sh_dc[..R::N],
        rest: &mut so.rest[..R::N * pad_out],
        rest_per: pad_out,
    };
    backward_block::<R>(
        &view, 0, cam, degree, groups, &st.sg, &st.splats, &st.radii, &mut o, 0,
    );
    // Lanes in ascending entry order: a row's padding spills zeros (the staged row's
    // values past `rest_per`: the block zeroed them and writes at most `rest_per`) onto the
    // head of the next entries' rows, which are zero already or are written after it.
    let rest_out = out.rest_per;
    for l in 0..used {
        let k = st.slot[l];
        out.means[k] = so.means[l];
        out.log_scales[k] = so.log_scales[l];
        out.quats[k] = so.quats[l];
        out.opacity[k] = so.opacity[l];
        out.sh_dc[k] = so.sh_dc[l];
        let row = &so.rest[l * pad_out..(l + 1) * pad_out];
        let dst = &mut out.rest[k * rest_out..];
        if dst.len() >= pad_out {
            copy_padded(&mut dst[..pad_out], row, pad_out);
        } else {
            dst[..rest_out].copy_from_slice(&row[..rest_out]);
        }
    }
}

/// [`backward_range`] eight Gaussians per instruction.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn backward_range_avx2(
    g: &ParamView,
    first: usize,
    cam: &CameraF32,
    degree: u32,
    groups: &GradGroups,
    sg: &[SplatGrad],
    fwd: &Projected,
    out: &mut OutChunk,
) {
    backward_range::<F32x8>(g, first, cam, degree, groups, sg, fwd, out)
}

/// [`backward_range`] sixteen Gaussians per instruction.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
unsafe fn backward_range_avx512(
    g: &ParamView,
    first: usize,
    cam: &CameraF32,
    degree: u32,
    groups: &GradGroups,
    sg: &[SplatGrad],
    fwd: &Projected,
    out: &mut OutChunk,
) {
    backward_range::<F32x16>(g, first, cam, degree, groups, sg, fwd, out)
}

/// Backward of [`crate::raster::project::project`] for every Gaussian the forward did not
/// cull (culled Gaussians, radii `(0, 0)` in the projection, get exactly zero).
/// `kernel` chooses the lane width as the projection does (sixteen Gaussians per AVX-512F
/// instruction, eight per AVX2 instruction, or one); all give the same bits.
pub fn project_backward(
    g: &Gaussians,
    cam: &CameraF32,
    fwd: &Projected,
    plan: &RenderPlan,
    groups: &GradGroups,
    splat_grads: &[SplatGrad],
    kernel: Kernel,
) -> Gradients {
    let mut out = Gradients::default();
    project_backward_into(g, cam, fwd, plan, groups, splat_grads, kernel, &mut out);
    out
}

/// [`project_backward`] into `out`, whose arrays are resized and overwritten (every entry
/// is written once, zeros included: no clearing pass, no allocation once they have the
/// size). The background gradient is set to zero.
#[allow(clippy::too_many_arguments)]
pub fn project_backward_into(
    g: &Gaussians,
    cam: &CameraF32,
    fwd: &Projected,
    plan: &RenderPlan,
    groups: &GradGroups,
    splat_grads: &[SplatGrad],
    kernel: Kernel,
    out: &mut Gradients,
) {
    use rayon::prelude::*;
    let n = g.len();
    let k1 = g.rest_per_channel();
    // Growing fills with zeros, which the blocks overwrite anyway; shrinking truncates.
    out.means.resize(n, [0.0; 3]);
    out.log_scales.resize(n, [0.0; 3]);
    out.quats.resize(n, [0.0; 4]);
    out.opacity_logits.resize(n, 0.0);
    out.sh_dc.resize(n, [0.0; 3]);
    out.sh_rest.resize(n * k1 * 3, 0.0);
    out.background = [0.0; 3];
    screen_grads(cam, splat_grads, out);
    let degree = plan.sh_degree;
    // Fixed chunks of Gaussians written in place. Degree 0 has no rest coefficients: a
    // placeholder of one value per Gaussian keeps the chunks aligned.
    let rest_per = (k1 * 3).max(1);
    let mut placeholder = if k1 == 0 { vec![0f32; n] } else { Vec::new() };
    let rest: &mut [f32] = if k1 == 0 {
        &mut placeholder
    } else {
        &mut out.sh_rest
    };
    let view = ParamView::of(g);
    out.means
        .par_chunks_mut(CHUNK)
        .zip(out.log_scales.par_chunks_mut(CHUNK))
        .zip(out.quats.par_chunks_mut(CHUNK))
        .zip(out.opacity_logits.par_chunks_mut(CHUNK))
        .zip(out.sh_dc.par_chunks_mut(CHUNK))
        .zip(rest.par_chunks_mut(CHUNK * rest_per))
        .enumerate()
        .for_each(
            |(ci, (((((means, log_scales), quats), opacity), sh_dc), rest))| {
                let mut o = OutChunk {
                    means,
                    log_scales,
                    quats,
                    opacity,
                    sh_dc,
                    rest,
                    rest_per,
                };
                let (sg, first) = (splat_grads, ci * CHUNK);
                range_for(kernel, &view, first, cam, degree, groups, sg, fwd, &mut o);
            },
        );
}

/// The screen-space mean gradients of `out` (pixels, and INRIA's NDC units for
/// densification) from the splat gradients.
pub(crate) fn screen_grads(cam: &CameraF32, splat_grads: &[SplatGrad], out: &mut Gradients) {
    out.means2d.clear();
    out.means2d.extend(splat_grads.iter().map(|s| s.mean2d));
    out.means2d_ndc.clear();
    out.means2d_ndc.extend(
        splat_grads
            .iter()
            .map(|s| mean2d_ndc(s.mean2d, cam.width, cam.height)),
    );
}

/// A screen-space mean gradient in pixels, in INRIA's NDC units (× (W/2, H/2)): what
/// densification accumulates.
#[inline]
pub fn mean2d_ndc(g: [f32; 2], width: u32, height: u32) -> [f32; 2] {
    [g[0] * 0.5 * width as f32, g[1] * 0.5 * height as f32]
}

/// [`backward_range`] in the lane width `kernel` chooses (sixteen Gaussians per AVX-512F
/// instruction, eight per AVX2 instruction, or one); all give the same bits.
#[allow(clippy::too_many_arguments)]
fn range_for(
    kernel: Kernel,
    g: &ParamView,
    first: usize,
    cam: &CameraF32,
    degree: u32,
    groups: &GradGroups,
    sg: &[SplatGrad],
    fwd: &Projected,
    out: &mut OutChunk,
) {
    #[cfg(target_arch = "x86_64")]
    if kernel.avx512() {
        // SAFETY: AVX-512F was detected (`Kernel::avx512`).
        unsafe { backward_range_avx512(g, first, cam, degree, groups, sg, fwd, out) };
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if kernel.avx2() {
        // SAFETY: AVX2 was detected (`Kernel::avx2`).
        unsafe { backward_range_avx2(g, first, cam, degree, groups, sg, fwd, out) };
        return;
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = kernel;
    backward_range::<f32>(g, first, cam, degree, groups, sg, fwd, out);
}

/// One chunk's gradient arrays, reused by a task for every chunk it takes.
#[derive(Default)]
struct ChunkBuf {
    means: Vec<[f32; 3]>,
    log_scales: Vec<[f32; 3]>,
    quats: Vec<[f32; 4]>,
    opacity: Vec<f32>,
    sh_dc: Vec<[f32; 3]>,
    rest: Vec<f32>,
}

/// [`project_backward_into`] that hands each chunk's gradients to its sink instead of
/// storing them: the same gradients, bit for bit, each computed into a buffer of the task
/// (in cache) right before `sink.take` uses it. `sinks` are the scene's chunks of
/// [`CHUNK`] Gaussians in order (the last may be shorter); `splat_grads` and `fwd` cover the
/// whole scene. Gaussians are independent, so chunks run in parallel.
#[allow(clippy::too_many_arguments)]
pub fn project_backward_apply<S: GradSink>(
    cam: &CameraF32,
    fwd: &Projected,
    plan: &RenderPlan,
    groups: &GradGroups,
    splat_grads: &[SplatGrad],
    kernel: Kernel,
    sinks: &mut [S],
) {
    use rayon::prelude::*;
    let degree = plan.sh_degree;
    sinks
        .par_iter_mut()
        .for_each_init(ChunkBuf::default, |buf, sink| {
            let view = sink.params();
            let (first, n) = (view.base, view.means.len());
            debug_assert!(first.is_multiple_of(CHUNK) && n <= CHUNK);
            let rest_per = view.rest_per.max(1);
            buf.means.resize(n, [0.0; 3]);
            buf.log_scales.resize(n, [0.0; 3]);
            buf.quats.resize(n, [0.0; 4]);
            buf.opacity.resize(n, 0.0);
            buf.sh_dc.resize(n, [0.0; 3]);
            buf.rest.resize(n * rest_per, 0.0);
            let mut o = OutChunk {
                means: &mut buf.means,
                log_scales: &mut buf.log_scales,
                quats: &mut buf.quats,
                opacity: &mut buf.opacity,
                sh_dc: &mut buf.sh_dc,
                rest: &mut buf.rest,
                rest_per,
            };
            range_for(
                kernel,
                &view,
                first,
                cam,
                degree,
                groups,
                splat_grads,
                fwd,
                &mut o,
            );
            let grads = ChunkGrads {
                splats: &splat_grads[first..first + n],
                radii: &fwd.radii[first..first + n],
                means: &buf.means,
                log_scales: &buf.log_scales,
                quats: &buf.quats,
                opacity_logits: &buf.opacity,
                sh_dc: &buf.sh_dc,
                sh_rest: &buf.rest[..n * view.rest_per],
            };
            sink.take(&grads);
        });
}

impl Gradients {
    /// The flat gradient of one parameter array (the layout of [`Gaussians::param`]).
    pub fn param(&self, p: Param) -> &[f32] {
        match p {
            Param::Means => self.means.as_flattened(),
            Param::ShDc => self.sh_dc.as_flattened(),
            Param::ShRest => &self.sh_rest,
            Param::OpacityLogits => &self.opacity_logits,
            Param::LogScales => self.log_scales.as_flattened(),
            Param::Quats => self.quats.as_flattened(),
        }
    }
}
