//! Projection of 3D Gaussians to screen-space splats (EWA, gsplat conventions).
//!
//! Per Gaussian, in f32, no FMA, in the order written here (SPEC.md §5.2):
//!
//! 1. `t = R_cw·μ + t_cw`; cull if `z < NEAR_PLANE` or `z > FAR_PLANE` (gsplat
//!    `persp_proj`; INRIA culls `z <= 0.2`).
//! 2. `q ← q/|q|` (wxyz), `R(q)`, `s = exp(log_scale)`, `M = R·diag(s)`, `Σ = M·Mᵀ`.
//! 3. `Σc = W·Σ·Wᵀ` with `W = R_cw`.
//! 4. Clamped Jacobian: `tx = z·clamp(x/z, −lim_x_neg, lim_x_pos)` with
//!    `lim_x_pos = (W−cx)/fx + 0.3·tan_fovx`, `lim_x_neg = cx/fx + 0.3·tan_fovx`,
//!    `tan_fovx = 0.5·W/fx` (same in y); `J = [[fx/z, 0, −fx·tx/z²], [0, fy/z, −fy·ty/z²]]`.
//! 5. `Σ2d = J·Σc·Jᵀ + 0.3·I`; cull if `det ≤ 0` or not finite; `conic = (c, −b, a)/det`
//!    computed as a product with `1/det` (glm's `inverse`).
//! 6. `mean2d = (fx·x·(1/z) + cx, fy·y·(1/z) + cy)`.
//! 7. `o = sigmoid(logit)` (times `sqrt(max(0, det₀/det))` in antialiased mode); cull if
//!    `o < 1/255`. `k = min(3.33, sqrt(2·ln(255·o)))`, `r = (ceil(k·√a), ceil(k·√c))`;
//!    cull if both radii are 0 or the box `mean2d ± r` misses the image.
//! 8. Colour: `dir = (μ − C)/|μ − C|`, `rgb = max(Σ_k coeff_k·Y_k(dir) + 0.5, 0)`.
//!
//! A Gaussian with a non-finite parameter (among those the plan uses), or whose camera-space
//! mean or colour overflows f32, is skipped and counted as `non_finite`.

use super::plan::RenderPlan;
use super::{RenderOptions, RenderReport};
use crate::camera::Camera;
use crate::gaussian::Gaussians;
use crate::math::fastexp::{exp, ln, sigmoid};
use crate::math::round::ceil;
use crate::math::sh::{MAX_SH_COEFFS, SH_C0, num_coeffs, sh_basis};
use rayon::prelude::*;

/// Near clipping plane in camera z (gsplat `near_plane` default).
pub const NEAR_PLANE: f32 = 0.01;
/// Far clipping plane in camera z (gsplat `far_plane` default).
pub const FAR_PLANE: f32 = 1e10;
/// Screen-space dilation added to the 2D covariance diagonal (gsplat `eps2d`, INRIA 0.3).
pub const EPS2D: f32 = 0.3;
/// Guard band of the clamped Jacobian, in units of the half field of view (gsplat, INRIA).
pub const JACOBIAN_GUARD: f32 = 0.3;
/// Smallest alpha that is blended, and the opacity cull (gsplat `ALPHA_THRESHOLD`).
pub const ALPHA_THRESHOLD: f32 = 1.0 / 255.0;
/// Largest extent of the splat in standard deviations (gsplat ≥ PR #596).
pub const MAX_EXTENT_SIGMA: f32 = 3.33;

/// A projected Gaussian, everything the blend needs (40 bytes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct Splat {
    /// Centre in pixels.
    pub mean: [f32; 2],
    /// Inverse 2D covariance `(A, B, C)`: `σ = ½(A·dx² + C·dy²) + B·dx·dy`.
    pub conic: [f32; 3],
    pub opacity: f32,
    pub color: [f32; 3],
    /// Camera-space z.
    pub depth: f32,
}

/// Why a Gaussian is not drawn (the report counts each).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cull {
    NonFinite,
    Near,
    Far,
    Degenerate,
    LowOpacity,
    OffScreen,
}

/// Per-Gaussian projection result.
#[derive(Clone, Debug, Default)]
pub struct Projected {
    pub splats: Vec<Splat>,
    /// Pixel radii `(r_x, r_y)`; `(0, 0)` for culled Gaussians.
    pub radii: Vec<[i32; 2]>,
}

/// The camera in the f32 form the projection uses.
#[derive(Clone, Copy, Debug)]
pub struct CameraF32 {
    pub r_cw: [[f32; 3]; 3],
    pub t_cw: [f32; 3],
    pub center: [f32; 3],
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: u32,
    pub height: u32,
}

impl CameraF32 {
    pub fn new(cam: &Camera) -> CameraF32 {
        let r = cam.camera_from_world_rotation();
        let t = cam.camera_from_world_translation();
        let row = |i: usize| [r.x_axis[i] as f32, r.y_axis[i] as f32, r.z_axis[i] as f32];
        CameraF32 {
            r_cw: [row(0), row(1), row(2)],
            t_cw: [t.x as f32, t.y as f32, t.z as f32],
            center: [
                cam.center.x as f32,
                cam.center.y as f32,
                cam.center.z as f32,
            ],
            fx: cam.fx as f32,
            fy: cam.fy as f32,
            cx: cam.cx as f32,
            cy: cam.cy as f32,
            width: cam.width,
            height: cam.height,
        }
    }
}

#[inline(always)]
fn dot3(a: [f32; 3], b: [f32; 3]) -> f32 {
    (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]
}

#[inline(always)]
fn clamp(v: f32, lo: f32, hi: f32) -> f32 {
    let v = if v < lo { lo } else { v };
    if v > hi { hi } else { v }
}

/// `A·B` for 3×3 row-major matrices, each entry summed in k order.
#[inline(always)]
fn mat3_mul(a: &[[f32; 3]; 3], b: &[[f32; 3]; 3]) -> [[f32; 3]; 3] {
    let mut o = [[0f32; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            o[i][j] = (a[i][0] * b[0][j] + a[i][1] * b[1][j]) + a[i][2] * b[2][j];
        }
    }
    o
}

#[inline(always)]
fn transpose(a: &[[f32; 3]; 3]) -> [[f32; 3]; 3] {
    [
        [a[0][0], a[1][0], a[2][0]],
        [a[0][1], a[1][1], a[2][1]],
        [a[0][2], a[1][2], a[2][2]],
    ]
}

/// Rotation matrix of a normalized wxyz quaternion (row-major).
#[inline(always)]
pub fn quat_to_rotmat(q: [f32; 4]) -> [[f32; 3]; 3] {
    let [w, x, y, z] = q;
    let (x2, y2, z2) = (x * x, y * y, z * z);
    let (xy, xz, yz) = (x * y, x * z, y * z);
    let (wx, wy, wz) = (w * x, w * y, w * z);
    [
        [1.0 - 2.0 * (y2 + z2), 2.0 * (xy - wz), 2.0 * (xz + wy)],
        [2.0 * (xy + wz), 1.0 - 2.0 * (x2 + z2), 2.0 * (yz - wx)],
        [2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (x2 + y2)],
    ]
}

fn all_finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// The projection's intermediate values for one Gaussian, steps 1–5 of the module docs up to
/// the undilated 2D covariance. The backward pass recomputes them with this same function.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Geometry {
    /// Camera-space mean.
    pub t: [f32; 3],
    /// Normalized quaternion and `1/|q|`.
    pub qh: [f32; 4],
    pub inv_qn: f32,
    pub rot: [[f32; 3]; 3],
    pub s: [f32; 3],
    /// `M = R·diag(s)`.
    pub m: [[f32; 3]; 3],
    pub sigma_c: [[f32; 3]; 3],
    pub rz: f32,
    /// Clamped `tx`, `ty` and whether the clamp was active.
    pub tx: f32,
    pub ty: f32,
    pub x_clamped: bool,
    pub y_clamped: bool,
    pub j: [[f32; 3]; 2],
    /// `J·Σc·Jᵀ` as `(a, b, c)`, before the dilation.
    pub cov: [f32; 3],
}

pub(crate) fn geometry(g: &Gaussians, i: usize, cam: &CameraF32) -> Result<Geometry, Cull> {
    let mean = g.means[i];
    // 1. Camera space.
    let r = &cam.r_cw;
    let x = dot3(r[0], mean) + cam.t_cw[0];
    let y = dot3(r[1], mean) + cam.t_cw[1];
    let z = dot3(r[2], mean) + cam.t_cw[2];
    if !(x.is_finite() && y.is_finite() && z.is_finite()) {
        return Err(Cull::NonFinite); // finite but huge means overflow here
    }
    if z < NEAR_PLANE {
        return Err(Cull::Near);
    }
    if z > FAR_PLANE {
        return Err(Cull::Far);
    }
    // 2. World covariance.
    let q = g.quats[i];
    let qn2 = (q[0] * q[0] + q[1] * q[1]) + (q[2] * q[2] + q[3] * q[3]);
    if !(qn2 > 0.0 && qn2.is_finite()) {
        return Err(Cull::Degenerate);
    }
    let inv_qn = 1.0 / qn2.sqrt();
    let qh = [q[0] * inv_qn, q[1] * inv_qn, q[2] * inv_qn, q[3] * inv_qn];
    let rot = quat_to_rotmat(qh);
    let ls = g.log_scales[i];
    let s = [exp(ls[0]), exp(ls[1]), exp(ls[2])];
    let mut m = [[0f32; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            m[a][b] = rot[a][b] * s[b];
        }
    }
    let sigma = mat3_mul(&m, &transpose(&m));
    // 3. Camera covariance.
    let sigma_c = mat3_mul(&mat3_mul(r, &sigma), &transpose(r));
    // 4. Clamped Jacobian.
    let (w, h) = (cam.width as f32, cam.height as f32);
    let tan_fovx = 0.5 * w / cam.fx;
    let tan_fovy = 0.5 * h / cam.fy;
    let lim_x_pos = (w - cam.cx) / cam.fx + JACOBIAN_GUARD * tan_fovx;
    let lim_x_neg = cam.cx / cam.fx + JACOBIAN_GUARD * tan_fovx;
    let lim_y_pos = (h - cam.cy) / cam.fy + JACOBIAN_GUARD * tan_fovy;
    let lim_y_neg = cam.cy / cam.fy + JACOBIAN_GUARD * tan_fovy;
    let rz = 1.0 / z;
    let rz2 = rz * rz;
    let (xz, yz) = (x * rz, y * rz);
    let tx = z * clamp(xz, -lim_x_neg, lim_x_pos);
    let ty = z * clamp(yz, -lim_y_neg, lim_y_pos);
    let j = [
        [cam.fx * rz, 0.0, -cam.fx * tx * rz2],
        [0.0, cam.fy * rz, -cam.fy * ty * rz2],
    ];
    // 5. Σ2d = J·Σc·Jᵀ.
    let mut js = [[0f32; 3]; 2];
    for a in 0..2 {
        for b in 0..3 {
            js[a][b] =
                (j[a][0] * sigma_c[0][b] + j[a][1] * sigma_c[1][b]) + j[a][2] * sigma_c[2][b];
        }
    }
    let cov = |a: usize, b: usize| (js[a][0] * j[b][0] + js[a][1] * j[b][1]) + js[a][2] * j[b][2];
    let (a0, b, c0) = (cov(0, 0), cov(0, 1), cov(1, 1));
    Ok(Geometry {
        t: [x, y, z],
        qh,
        inv_qn,
        rot,
        s,
        m,
        sigma_c,
        rz,
        tx,
        ty,
        x_clamped: xz < -lim_x_neg || xz > lim_x_pos,
        y_clamped: yz < -lim_y_neg || yz > lim_y_pos,
        j,
        cov: [a0, b, c0],
    })
}

/// The SH basis (up to `degree`) at Gaussian `i`'s view direction `(μ − C)/|μ − C|`.
pub(crate) fn sh_view_basis(
    g: &Gaussians,
    i: usize,
    cam: &CameraF32,
    degree: u32,
) -> [f32; MAX_SH_COEFFS] {
    let mean = g.means[i];
    let d = [
        mean[0] - cam.center[0],
        mean[1] - cam.center[1],
        mean[2] - cam.center[2],
    ];
    let inv_len = 1.0 / dot3(d, d).sqrt();
    let mut basis = [0f32; MAX_SH_COEFFS];
    sh_basis(
        degree,
        d[0] * inv_len,
        d[1] * inv_len,
        d[2] * inv_len,
        &mut basis,
    );
    basis
}

/// SH colour sums `Σ_k coeff_k·Y_k(dir) + 0.5` per channel (before the clamp at 0) and the
/// basis, `dir = (μ − C)/|μ − C|`. Shared by the forward and backward passes.
pub(crate) fn sh_color(
    g: &Gaussians,
    i: usize,
    cam: &CameraF32,
    degree: u32,
) -> ([f32; 3], [f32; MAX_SH_COEFFS]) {
    let basis = sh_view_basis(g, i, cam, degree);
    let (dc, rest) = (g.sh_dc[i], g.rest(i));
    let k_used = num_coeffs(degree) - 1;
    let mut out = [0f32; 3];
    for (ch, o) in out.iter_mut().enumerate() {
        let mut acc = basis[0] * dc[ch];
        for k in 0..k_used {
            acc += basis[k + 1] * rest[k * 3 + ch];
        }
        *o = acc + 0.5;
    }
    (out, basis)
}

/// Project one Gaussian.
pub fn project_one(
    g: &Gaussians,
    i: usize,
    cam: &CameraF32,
    plan: &RenderPlan,
    antialiased: bool,
) -> Result<(Splat, [i32; 2]), Cull> {
    let mean = g.means[i];
    let k_used = num_coeffs(plan.sh_degree) - 1;
    let rest = &g.rest(i)[..k_used * 3];
    if !(all_finite(&mean)
        && all_finite(&g.log_scales[i])
        && all_finite(&g.quats[i])
        && g.opacity_logits[i].is_finite()
        && all_finite(&g.sh_dc[i])
        && all_finite(rest))
    {
        return Err(Cull::NonFinite);
    }
    let geo = geometry(g, i, cam)?;
    let [x, y, z] = geo.t;
    let (w, h) = (cam.width as f32, cam.height as f32);
    let (rz, [a0, b, c0]) = (geo.rz, geo.cov);
    let det_orig = a0 * c0 - b * b;
    let (a, c) = (a0 + EPS2D, c0 + EPS2D);
    let det = a * c - b * b;
    if !(det > 0.0 && det.is_finite()) {
        return Err(Cull::Degenerate);
    }
    let inv_det = 1.0 / det;
    let conic = [c * inv_det, -b * inv_det, a * inv_det];
    // 6. Mean.
    let mean2d = [cam.fx * x * rz + cam.cx, cam.fy * y * rz + cam.cy];
    // 7. Opacity and radius.
    let mut opacity = sigmoid(g.opacity_logits[i]);
    if antialiased {
        let ratio = det_orig / det;
        opacity *= if ratio > 0.0 { ratio.sqrt() } else { 0.0 };
    }
    if opacity < ALPHA_THRESHOLD {
        return Err(Cull::LowOpacity);
    }
    let ext = (2.0 * ln(opacity * 255.0)).sqrt();
    let ext = if ext < MAX_EXTENT_SIGMA {
        ext
    } else {
        MAX_EXTENT_SIGMA
    };
    let rx = ceil(ext * a.sqrt());
    let ry = ceil(ext * c.sqrt());
    if rx <= 0.0 && ry <= 0.0 {
        return Err(Cull::LowOpacity);
    }
    if mean2d[0] + rx <= 0.0 || mean2d[0] - rx >= w || mean2d[1] + ry <= 0.0 || mean2d[1] - ry >= h
    {
        return Err(Cull::OffScreen);
    }
    // 8. Colour.
    let (raw, _) = sh_color(g, i, cam, plan.sh_degree);
    let color = raw.map(|v| if v > 0.0 { v } else { 0.0 });
    if !color.iter().all(|c| c.is_finite()) {
        return Err(Cull::NonFinite); // finite but huge SH coefficients overflow here
    }
    let splat = Splat {
        mean: mean2d,
        conic,
        opacity,
        color,
        depth: z,
    };
    // Radii are at most ~1e19 here; saturate to i32 for storage.
    Ok((
        splat,
        [
            rx.min(i32::MAX as f32) as i32,
            ry.min(i32::MAX as f32) as i32,
        ],
    ))
}

/// Project every Gaussian (parallel over fixed chunks; output order is the input order).
pub fn project(
    g: &Gaussians,
    cam: &Camera,
    plan: &RenderPlan,
    opts: &RenderOptions,
    report: &mut RenderReport,
) -> Projected {
    let cam = CameraF32::new(cam);
    let n = g.len();
    let mut out = Projected {
        splats: vec![Splat::default(); n],
        radii: vec![[0, 0]; n],
    };
    // Fixed chunks, written in place; per-chunk cull counts are integers, so their sum does
    // not depend on how chunks map to threads.
    const CHUNK: usize = 4096;
    let counts: Vec<[u64; 7]> = out
        .splats
        .par_chunks_mut(CHUNK)
        .zip(out.radii.par_chunks_mut(CHUNK))
        .enumerate()
        .map(|(ci, (splats, radii))| {
            let mut c = [0u64; 7];
            for (k, (s, r)) in splats.iter_mut().zip(radii.iter_mut()).enumerate() {
                match project_one(g, ci * CHUNK + k, &cam, plan, opts.antialiased) {
                    Ok((splat, rad)) => {
                        *s = splat;
                        *r = rad;
                        c[0] += 1;
                    }
                    Err(cull) => c[1 + cull as usize] += 1,
                }
            }
            c
        })
        .collect();
    for c in counts {
        report.visible += c[0];
        report.non_finite += c[1 + Cull::NonFinite as usize];
        report.behind_near_plane += c[1 + Cull::Near as usize];
        report.beyond_far_plane += c[1 + Cull::Far as usize];
        report.degenerate += c[1 + Cull::Degenerate as usize];
        report.low_opacity += c[1 + Cull::LowOpacity as usize];
        report.off_screen += c[1 + Cull::OffScreen as usize];
    }
    out
}

/// `C0` as f32, for callers that convert colours to DC coefficients.
pub const SH_C0_F32: f32 = SH_C0 as f32;
