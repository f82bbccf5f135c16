//! Backward of the projection (mirrors `raster::project`): from splat gradients to the raw
//! parameters. Per Gaussian and independent, so parallel and deterministic. In f32, except
//! the SH direction derivative, which uses the f64 forward-mode basis (`sh_basis_grad`).
//!
//! Chain (forward in `raster::project`):
//! `conic = Σ2d⁻¹` → `v_Σ2d = −Σ2d⁻¹·G·Σ2d⁻¹` with `G = [[vA, vB/2], [vB/2, vC]]`;
//! `Σ2d = J·Σc·Jᵀ (+0.3 I)` → `v_Σc = Jᵀ·V·J`, `v_J = 2·V·J·Σc`;
//! `Σc = W·Σ·Wᵀ` → `v_Σ = Wᵀ·v_Σc·W`; `Σ = M·Mᵀ` → `v_M = 2·v_Σ·M`;
//! `M = R·diag(s)` → `v_R = v_M·diag(s)`, `v_s_j = Σ_i v_M_ij·R_ij`, `v_log_s = v_s·s`;
//! `R(q̂)` → `v_q̂`; `q̂ = q/|q|` → `v_q = (v_q̂ − q̂(q̂·v_q̂))/|q|`;
//! `J(t)` with the clamp: a clamped `x/z` makes `tx = z·lim`, so its gradient goes to z;
//! `mean2d(t)`; `t = W·μ + t_w` → `v_μ = Wᵀ·v_t` plus the SH direction term;
//! `o = sigmoid(l)` → `v_l = v_o·o·(1 − o)`;
//! `c = max(Σ coeff·Y + 0.5, 0)` → coefficient gradients `Y·v_c` where the clamp is open.

use super::composite::SplatGrad;
use crate::gaussian::{Gaussians, Param};
use crate::math::fastexp::sigmoid;
use crate::math::sh::{MAX_SH_COEFFS, num_coeffs, sh_basis_grad};
use crate::raster::plan::RenderPlan;
use crate::raster::project::{CameraF32, EPS2D, Geometry, geometry, sh_color};

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

type M3 = [[f32; 3]; 3];

fn mul(a: &M3, b: &M3) -> M3 {
    let mut o = [[0f32; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            o[i][j] = (a[i][0] * b[0][j] + a[i][1] * b[1][j]) + a[i][2] * b[2][j];
        }
    }
    o
}

fn tr(a: &M3) -> M3 {
    [
        [a[0][0], a[1][0], a[2][0]],
        [a[0][1], a[1][1], a[2][1]],
        [a[0][2], a[1][2], a[2][2]],
    ]
}

/// One Gaussian's backward. `sg` is its accumulated splat gradient.
#[allow(clippy::too_many_arguments)]
fn backward_one(
    g: &Gaussians,
    i: usize,
    cam: &CameraF32,
    plan: &RenderPlan,
    groups: &GradGroups,
    sg: &SplatGrad,
    out_mean: &mut [f32; 3],
    out_ls: &mut [f32; 3],
    out_q: &mut [f32; 4],
    out_op: &mut f32,
    out_dc: &mut [f32; 3],
    out_rest: &mut [f32],
) {
    let r = &cam.r_cw;
    let k_used = num_coeffs(plan.sh_degree) - 1;
    let rest = g.rest(i);
    // Colour: which channels are open (Σ + 0.5 > 0), recomputed as the forward did.
    let (raw, basis) = sh_color(g, i, cam, plan.sh_degree);
    let v_sh: [f32; 3] = std::array::from_fn(|ch| if raw[ch] > 0.0 { sg.color[ch] } else { 0.0 });
    if groups.sh_dc {
        for ch in 0..3 {
            out_dc[ch] = basis[0] * v_sh[ch];
        }
    }
    if groups.sh_rest {
        for k in 0..k_used {
            for ch in 0..3 {
                out_rest[k * 3 + ch] = basis[k + 1] * v_sh[ch];
            }
        }
    }
    if !groups.geometry() {
        return;
    }
    // The forward quantities the chain needs, recomputed by the forward's own code.
    let Ok(geo) = geometry(g, i, cam) else {
        return; // culled in the forward too (radii are checked by the caller)
    };
    let Geometry {
        t: [x, y, _],
        qh,
        inv_qn,
        rot,
        s,
        m,
        sigma_c,
        rz,
        tx,
        ty,
        x_clamped,
        y_clamped,
        j,
        cov,
    } = geo;
    let rz2 = rz * rz;
    let (a_, b_, c_) = (cov[0] + EPS2D, cov[1], cov[2] + EPS2D);
    let inv_det = 1.0 / (a_ * c_ - b_ * b_);
    let ci = [[c_ * inv_det, -b_ * inv_det], [-b_ * inv_det, a_ * inv_det]];
    // v_Σ2d = −Σ⁻¹·G·Σ⁻¹ with G the symmetric gradient of the conic.
    let gm = [
        [sg.conic[0], 0.5 * sg.conic[1]],
        [0.5 * sg.conic[1], sg.conic[2]],
    ];
    let mut tmp = [[0f32; 2]; 2];
    for a in 0..2 {
        for b in 0..2 {
            tmp[a][b] = ci[a][0] * gm[0][b] + ci[a][1] * gm[1][b];
        }
    }
    let mut v_cov = [[0f32; 2]; 2];
    for a in 0..2 {
        for b in 0..2 {
            v_cov[a][b] = -(tmp[a][0] * ci[0][b] + tmp[a][1] * ci[1][b]);
        }
    }
    // v_Σc = Jᵀ·V·J and v_J = 2·V·J·Σc (V symmetric, Σc symmetric).
    let mut vj = [[0f32; 3]; 2]; // V·J
    for a in 0..2 {
        for b in 0..3 {
            vj[a][b] = v_cov[a][0] * j[0][b] + v_cov[a][1] * j[1][b];
        }
    }
    let mut v_sigma_c = [[0f32; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            v_sigma_c[a][b] = j[0][a] * vj[0][b] + j[1][a] * vj[1][b];
        }
    }
    let mut v_j = [[0f32; 3]; 2];
    for a in 0..2 {
        for b in 0..3 {
            v_j[a][b] = 2.0
                * ((vj[a][0] * sigma_c[0][b] + vj[a][1] * sigma_c[1][b])
                    + vj[a][2] * sigma_c[2][b]);
        }
    }
    // Camera-space mean.
    let v_m2d = sg.mean2d;
    let mut v_t = [
        v_m2d[0] * cam.fx * rz,
        v_m2d[1] * cam.fy * rz,
        -(v_m2d[0] * cam.fx * x + v_m2d[1] * cam.fy * y) * rz2 + sg.depth,
    ];
    let v_tx = v_j[0][2] * (-cam.fx * rz2);
    let v_ty = v_j[1][2] * (-cam.fy * rz2);
    v_t[2] += v_j[0][0] * (-cam.fx * rz2)
        + v_j[1][1] * (-cam.fy * rz2)
        + v_j[0][2] * (2.0 * cam.fx * tx * rz2 * rz)
        + v_j[1][2] * (2.0 * cam.fy * ty * rz2 * rz);
    if x_clamped {
        v_t[2] += v_tx * (tx * rz);
    } else {
        v_t[0] += v_tx;
    }
    if y_clamped {
        v_t[2] += v_ty * (ty * rz);
    } else {
        v_t[1] += v_ty;
    }
    if groups.means {
        let mut v_mu = [0f32; 3];
        for (a, v) in v_mu.iter_mut().enumerate() {
            *v = (r[0][a] * v_t[0] + r[1][a] * v_t[1]) + r[2][a] * v_t[2];
        }
        // The colour depends on the mean through dir = (μ − C)/|μ − C|.
        if v_sh.iter().any(|&v| v != 0.0) && plan.sh_degree > 0 {
            let mean = g.means[i];
            let d: [f32; 3] = std::array::from_fn(|a| mean[a] - cam.center[a]);
            let len = ((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]).sqrt();
            let dir = d.map(|v| v / len);
            let mut vals = [0f64; MAX_SH_COEFFS];
            let mut grads = [[0f64; 3]; MAX_SH_COEFFS];
            sh_basis_grad(plan.sh_degree, dir.map(|v| v as f64), &mut vals, &mut grads);
            let mut v_dir = [0f64; 3];
            for k in 1..=k_used {
                for ch in 0..3 {
                    let coef = rest[(k - 1) * 3 + ch] as f64 * v_sh[ch] as f64;
                    for a in 0..3 {
                        v_dir[a] += coef * grads[k][a];
                    }
                }
            }
            let dd =
                (dir[0] as f64 * v_dir[0] + dir[1] as f64 * v_dir[1]) + dir[2] as f64 * v_dir[2];
            for a in 0..3 {
                v_mu[a] += ((v_dir[a] - dir[a] as f64 * dd) / len as f64) as f32;
            }
        }
        *out_mean = v_mu;
    }
    if groups.opacities {
        let o = sigmoid(g.opacity_logits[i]);
        *out_op = sg.opacity * o * (1.0 - o);
    }
    if groups.log_scales || groups.quats {
        // v_Σ = Wᵀ·v_Σc·W, v_M = 2·v_Σ·M.
        let v_sigma = mul(&mul(&tr(r), &v_sigma_c), r);
        let v_m = mul(&v_sigma, &m).map(|row| row.map(|v| 2.0 * v));
        if groups.log_scales {
            for b in 0..3 {
                let v_s = (v_m[0][b] * rot[0][b] + v_m[1][b] * rot[1][b]) + v_m[2][b] * rot[2][b];
                out_ls[b] = v_s * s[b];
            }
        }
        if groups.quats {
            let mut vr = [[0f32; 3]; 3];
            for a in 0..3 {
                for b in 0..3 {
                    vr[a][b] = v_m[a][b] * s[b];
                }
            }
            let [w_, x_, y_, z_] = qh;
            let vq = [
                2.0 * (-z_ * vr[0][1] + y_ * vr[0][2] + z_ * vr[1][0]
                    - x_ * vr[1][2]
                    - y_ * vr[2][0]
                    + x_ * vr[2][1]),
                2.0 * (y_ * vr[0][1] + z_ * vr[0][2] + y_ * vr[1][0]
                    - 2.0 * x_ * vr[1][1]
                    - w_ * vr[1][2]
                    + z_ * vr[2][0]
                    + w_ * vr[2][1]
                    - 2.0 * x_ * vr[2][2]),
                2.0 * (-2.0 * y_ * vr[0][0]
                    + x_ * vr[0][1]
                    + w_ * vr[0][2]
                    + x_ * vr[1][0]
                    + z_ * vr[1][2]
                    - w_ * vr[2][0]
                    + z_ * vr[2][1]
                    - 2.0 * y_ * vr[2][2]),
                2.0 * (-2.0 * z_ * vr[0][0] - w_ * vr[0][1] + x_ * vr[0][2] + w_ * vr[1][0]
                    - 2.0 * z_ * vr[1][1]
                    + y_ * vr[1][2]
                    + x_ * vr[2][0]
                    + y_ * vr[2][1]),
            ];
            let dot = (qh[0] * vq[0] + qh[1] * vq[1]) + (qh[2] * vq[2] + qh[3] * vq[3]);
            for k in 0..4 {
                out_q[k] = (vq[k] - qh[k] * dot) * inv_qn;
            }
        }
    }
}

/// Backward of [`crate::raster::project::project`] for every Gaussian with a non-zero splat
/// gradient (culled Gaussians, radii `(0, 0)` in the projection, get exactly zero).
pub fn project_backward(
    g: &Gaussians,
    cam: &CameraF32,
    radii: &[[i32; 2]],
    plan: &RenderPlan,
    groups: &GradGroups,
    splat_grads: &[crate::raster::backward::composite::SplatGrad],
) -> Gradients {
    use rayon::prelude::*;
    let n = g.len();
    let k1 = g.rest_per_channel();
    let mut out = Gradients {
        means: vec![[0.0; 3]; n],
        log_scales: vec![[0.0; 3]; n],
        quats: vec![[0.0; 4]; n],
        opacity_logits: vec![0.0; n],
        sh_dc: vec![[0.0; 3]; n],
        sh_rest: vec![0.0; n * k1 * 3],
        background: [0.0; 3],
        means2d: splat_grads.iter().map(|s| s.mean2d).collect(),
        means2d_ndc: splat_grads
            .iter()
            .map(|s| {
                [
                    s.mean2d[0] * 0.5 * cam.width as f32,
                    s.mean2d[1] * 0.5 * cam.height as f32,
                ]
            })
            .collect(),
    };
    // Fixed chunks of Gaussians written in place. Degree 0 has no rest coefficients: a
    // placeholder of one value per Gaussian keeps the chunks aligned.
    const CHUNK: usize = 1024;
    let rest_per = (k1 * 3).max(1);
    let mut placeholder = if k1 == 0 { vec![0f32; n] } else { Vec::new() };
    let rest: &mut [f32] = if k1 == 0 {
        &mut placeholder
    } else {
        &mut out.sh_rest
    };
    out.means
        .par_chunks_mut(CHUNK)
        .zip(out.log_scales.par_chunks_mut(CHUNK))
        .zip(out.quats.par_chunks_mut(CHUNK))
        .zip(out.opacity_logits.par_chunks_mut(CHUNK))
        .zip(out.sh_dc.par_chunks_mut(CHUNK))
        .zip(rest.par_chunks_mut(CHUNK * rest_per))
        .enumerate()
        .for_each(|(ci, (((((mc, lc), qc), oc), dc), rc))| {
            for k in 0..mc.len() {
                let i = ci * CHUNK + k;
                if radii[i] == [0, 0] {
                    continue;
                }
                let r = &mut rc[k * rest_per..k * rest_per + k1 * 3];
                backward_one(
                    g,
                    i,
                    cam,
                    plan,
                    groups,
                    &splat_grads[i],
                    &mut mc[k],
                    &mut lc[k],
                    &mut qc[k],
                    &mut oc[k],
                    &mut dc[k],
                    r,
                );
            }
        });
    out
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
