//! Projection of 3D Gaussians to screen-space splats (EWA, gsplat conventions).
//!
//! Per Gaussian, in f32, no FMA, in the order written here (SPEC.md §5.2):
//!
//! 1. `t = R_cw·μ + t_cw`; cull if `z < NEAR_PLANE` or `z > FAR_PLANE` (gsplat
//!    `persp_proj`; INRIA culls `z <= 0.2`).
//! 2. `q ← q/|q|` (wxyz), `R(q)`, `s = exp(log_scale)`, `Q = W·R` with `W = R_cw`.
//! 3. The 2D covariance is never formed from `Σ = M·Mᵀ`: see step 5.
//! 4. Clamped Jacobian: `tx = z·clamp(x/z, −lim_x_neg, lim_x_pos)` with
//!    `lim_x_pos = (W−cx)/fx + 0.3·tan_fovx`, `lim_x_neg = cx/fx + 0.3·tan_fovx`,
//!    `tan_fovx = 0.5·W/fx` (same in y); `J = [[fx/z, 0, −fx·tx/z²], [0, fy/z, −fy·ty/z²]]`.
//! 5. `F = J·Q·diag(s)` (2×3), `Σ2d = F·Fᵀ = [[a₀, b], [b, c₀]]` (the same matrix as
//!    `J·W·Σ·Wᵀ·Jᵀ`); its determinant `det₀ = |μ|²`, `μ_k = s_i·s_j·(Qᵀ·(J₀ × J₁))_k`
//!    (Cauchy–Binet: the 2×2 minors of F, each a product, summed as squares); dilated
//!    `a = a₀ + 0.3`, `c = c₀ + 0.3`, `det = (det₀ + 0.3·(a₀ + c₀)) + 0.09`; cull if `det`
//!    is not finite and positive; `conic = (c, −b, a)·(1/det)` (glm's `inverse`). No step
//!    subtracts two large numbers: a needle 10⁶ times longer than wide keeps its thin
//!    axis, which `a·c − b²` loses in f32 (SPEC.md §5.1).
//! 6. `mean2d = (fx·x·(1/z) + cx, fy·y·(1/z) + cy)`.
//! 7. `o = sigmoid(logit)` (times `sqrt(max(0, det₀/det))` in antialiased mode); cull if
//!    `o < 1/255`. `k = min(3.33, sqrt(2·ln(255·o)))`, `r = (ceil(k·√a), ceil(k·√c))`
//!    (255 is `Cutoffs::inv_alpha_threshold`, a forward-only knob);
//!    cull if both radii are 0 or the box `mean2d ± r` misses the image.
//! 8. Colour: `dir = (μ − C)/|μ − C|`, `rgb = max(Σ_k coeff_k·Y_k(dir) + 0.5, 0)`.
//!
//! A Gaussian with a non-finite mean, scale, quaternion or opacity logit, or whose
//! camera-space mean overflows f32, is skipped and counted as `non_finite` (the first check
//! of all). Step 8 runs only for the Gaussians that pass steps 1–7, so no SH row of a culled
//! Gaussian is read; a colour sum that is not finite (a non-finite coefficient among those
//! the plan uses, or an overflow) skips the Gaussian then, as `non_finite` (the last check).

use super::kernel::Kernel;
use super::plan::RenderPlan;
use super::{RenderOptions, RenderReport};
use crate::camera::Camera;
use crate::gaussian::Gaussians;
use crate::math::lanes::Lanes;
#[cfg(target_arch = "x86_64")]
use crate::math::lanes::{F32x8, F32x16};
use crate::math::sh::{MAX_SH_COEFFS, SH_C0, num_coeffs, sh_basis};
use rayon::prelude::*;
use std::mem::MaybeUninit;

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

/// The fields of a [`Splat`], in declaration order, as f32 values.
pub const SPLAT_FLOATS: usize = 10;
const _: () = assert!(std::mem::size_of::<Splat>() == SPLAT_FLOATS * 4);

impl Splat {
    /// The splats' fields as one f32 slice (`SPLAT_FLOATS` per splat, declaration order).
    pub fn floats(s: &[Splat]) -> &[f32] {
        // SAFETY: as in `as_floats`, for a shared borrow.
        unsafe { std::slice::from_raw_parts(s.as_ptr().cast::<f32>(), s.len() * SPLAT_FLOATS) }
    }
    /// [`Splat::floats`], mutable.
    fn as_floats(s: &mut [Splat]) -> &mut [f32] {
        // SAFETY: `Splat` is `repr(C)` with only f32 fields (`SPLAT_FLOATS` of them, no
        // padding: the size is asserted above), so a slice of splats is a slice of f32 of
        // `SPLAT_FLOATS` times the length, with f32's alignment; the borrow is carried over.
        unsafe {
            std::slice::from_raw_parts_mut(s.as_mut_ptr().cast::<f32>(), s.len() * SPLAT_FLOATS)
        }
    }
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
    /// The clamped Jacobian's limits on `x/z` and `y/z` (step 4 of the module docs), in f32:
    /// `[−lim_x_neg, lim_x_pos, −lim_y_neg, lim_y_pos]`, i.e. the lower and upper bound of
    /// each.
    pub(crate) fn jacobian_limits(&self) -> [f32; 4] {
        let (w, h) = (self.width as f32, self.height as f32);
        let tan_fovx = 0.5 * w / self.fx;
        let tan_fovy = 0.5 * h / self.fy;
        [
            -(self.cx / self.fx + JACOBIAN_GUARD * tan_fovx),
            (w - self.cx) / self.fx + JACOBIAN_GUARD * tan_fovx,
            -(self.cy / self.fy + JACOBIAN_GUARD * tan_fovy),
            (h - self.cy) / self.fy + JACOBIAN_GUARD * tan_fovy,
        ]
    }

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
pub(crate) fn dot3<R: Lanes>(a: [R; 3], b: [R; 3]) -> R {
    (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]
}

/// `A·B` for 3×3 row-major matrices, each entry summed in k order.
#[inline(always)]
pub(crate) fn mat3_mul<R: Lanes>(a: &[[R; 3]; 3], b: &[[R; 3]; 3]) -> [[R; 3]; 3] {
    let mut o = [[R::splat(0.0); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            o[i][j] = (a[i][0] * b[0][j] + a[i][1] * b[1][j]) + a[i][2] * b[2][j];
        }
    }
    o
}

#[inline(always)]
pub(crate) fn transpose<R: Lanes>(a: &[[R; 3]; 3]) -> [[R; 3]; 3] {
    [
        [a[0][0], a[1][0], a[2][0]],
        [a[0][1], a[1][1], a[2][1]],
        [a[0][2], a[1][2], a[2][2]],
    ]
}

// Generic code over `Lanes` avoids `array::from_fn`, `array::map` and iterator adaptors on
// lane values: they may stay out-of-line, compiled without AVX2 (see `math::lanes`).

/// Rotation matrix of a normalized wxyz quaternion (row-major).
#[inline(always)]
pub fn quat_to_rotmat<R: Lanes>(q: [R; 4]) -> [[R; 3]; 3] {
    let [w, x, y, z] = q;
    let (one, two) = (R::splat(1.0), R::splat(2.0));
    let (x2, y2, z2) = (x * x, y * y, z * z);
    let (xy, xz, yz) = (x * y, x * z, y * z);
    let (wx, wy, wz) = (w * x, w * y, w * z);
    [
        [one - two * (y2 + z2), two * (xy - wz), two * (xz + wy)],
        [two * (xy + wz), one - two * (x2 + z2), two * (yz - wx)],
        [two * (xz - wy), two * (yz + wx), one - two * (x2 + y2)],
    ]
}

/// Which Gaussians (lanes) are culled so far and why: the first failing check wins, as in
/// a sequence of early returns.
#[derive(Clone, Copy)]
pub(crate) struct Culls<R: Lanes> {
    pub ok: R::Mask,
    /// `1 + Cull as usize` of the first failed check, as f32; unspecified where `ok`.
    code: R,
}

/// Every reason in `Cull` order, for turning a lane's code back into a `Cull`.
const CULLS: [Cull; 6] = [
    Cull::NonFinite,
    Cull::Near,
    Cull::Far,
    Cull::Degenerate,
    Cull::LowOpacity,
    Cull::OffScreen,
];

impl<R: Lanes> Culls<R> {
    #[inline(always)]
    pub(crate) fn new() -> Self {
        Culls {
            ok: !R::all_false(),
            code: R::splat(0.0),
        }
    }
    /// Cull the lanes where `fail` holds and no earlier check failed.
    #[inline(always)]
    fn check(&mut self, fail: R::Mask, why: Cull) {
        self.code = R::select(fail & self.ok, R::splat(1.0 + why as u8 as f32), self.code);
        self.ok = self.ok & !fail;
    }
    /// Cull the lanes where `fail` holds, before every check made so far.
    #[inline(always)]
    fn check_first(&mut self, fail: R::Mask, why: Cull) {
        self.code = R::select(fail, R::splat(1.0 + why as u8 as f32), self.code);
        self.ok = self.ok & !fail;
    }
}

impl Culls<f32> {
    fn result(&self) -> Result<(), Cull> {
        if self.ok {
            Ok(())
        } else {
            Err(CULLS[self.code as usize - 1])
        }
    }
}

/// The projection's intermediate values for one Gaussian (or one per lane), steps 1–5 of
/// the module docs up to the undilated 2D covariance and its determinant. The backward pass
/// recomputes them with this same code.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Geometry<R: Lanes = f32> {
    /// Camera-space mean.
    pub t: [R; 3],
    /// Normalized quaternion and `1/|q|`.
    pub qh: [R; 4],
    pub inv_qn: R,
    pub s: [R; 3],
    /// `Q = W·R`: the Gaussian's axes in camera space.
    pub q_cam: [[R; 3]; 3],
    pub rz: R,
    /// Clamped `tx`, `ty` and whether the clamp was active.
    pub tx: R,
    pub ty: R,
    pub x_clamped: R::Mask,
    pub y_clamped: R::Mask,
    pub j: [[R; 3]; 2],
    /// `P = J·Q` and the factor `F = P·diag(s)` of the 2D covariance (`Σ2d = F·Fᵀ`).
    pub p: [[R; 3]; 2],
    pub f: [[R; 3]; 2],
    /// `F·Fᵀ` as `(a, b, c)`, before the dilation.
    pub cov: [R; 3],
    /// `det(F·Fᵀ)` as a sum of three squares (Cauchy–Binet), before the dilation.
    pub det0: R,
}

impl<R: Lanes> Geometry<R> {
    /// The dilated 2D covariance `(a₀ + ε, b, c₀ + ε)` and its determinant `(det₀ + ε·(a₀ +
    /// c₀)) + ε²` (ε = `EPS2D`): a sum of non-negative terms, equal to `(a₀ + ε)(c₀ + ε) −
    /// b²` in exact arithmetic but without its cancellation.
    #[inline(always)]
    pub(crate) fn dilated(&self) -> ([R; 3], R) {
        let e = R::splat(EPS2D);
        let [a0, b, c0] = self.cov;
        let det = (self.det0 + e * (a0 + c0)) + R::splat(EPS2D * EPS2D);
        ([a0 + e, b, c0 + e], det)
    }
}

/// Steps 1–5 for the lanes' `mean`, `quat` and `log_scale`; failed checks go to `culls`.
#[inline(always)]
#[allow(clippy::needless_range_loop)] // `a`, `b` index two matrices
pub(crate) fn geometry_lanes<R: Lanes>(
    mean: [R; 3],
    q: [R; 4],
    ls: [R; 3],
    cam: &CameraF32,
    culls: &mut Culls<R>,
) -> Geometry<R> {
    let c = R::splat;
    // 1. Camera space.
    let mut r = [[c(0.0); 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            r[a][b] = c(cam.r_cw[a][b]);
        }
    }
    let x = dot3(r[0], mean) + c(cam.t_cw[0]);
    let y = dot3(r[1], mean) + c(cam.t_cw[1]);
    let z = dot3(r[2], mean) + c(cam.t_cw[2]);
    // Finite but huge means overflow here.
    culls.check(
        !(x.is_finite() & y.is_finite() & z.is_finite()),
        Cull::NonFinite,
    );
    culls.check(z.lt(c(NEAR_PLANE)), Cull::Near);
    culls.check(z.gt(c(FAR_PLANE)), Cull::Far);
    // 2. World covariance.
    let qn2 = (q[0] * q[0] + q[1] * q[1]) + (q[2] * q[2] + q[3] * q[3]);
    culls.check(!(qn2.gt(c(0.0)) & qn2.is_finite()), Cull::Degenerate);
    let inv_qn = c(1.0) / qn2.sqrt();
    let qh = [q[0] * inv_qn, q[1] * inv_qn, q[2] * inv_qn, q[3] * inv_qn];
    let rot = quat_to_rotmat(qh);
    let s = [ls[0].exp(), ls[1].exp(), ls[2].exp()];
    // 3. The Gaussian's axes in camera space.
    let q_cam = mat3_mul(&r, &rot);
    // 4. Clamped Jacobian (the limits are per camera, in f32).
    let [lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos] = cam.jacobian_limits().map(c);
    let rz = c(1.0) / z;
    let rz2 = rz * rz;
    let (xz, yz) = (x * rz, y * rz);
    let tx = z * xz.clamp_sel(lim_x_neg, lim_x_pos);
    let ty = z * yz.clamp_sel(lim_y_neg, lim_y_pos);
    let zero = c(0.0);
    let j = [
        [c(cam.fx) * rz, zero, c(-cam.fx) * tx * rz2],
        [zero, c(cam.fy) * rz, c(-cam.fy) * ty * rz2],
    ];
    // 5. Σ2d = F·Fᵀ with F = J·Q·diag(s) (2×3): sums of squares and one dot product.
    let mut p = [[zero; 3]; 2];
    let mut f = [[zero; 3]; 2];
    for a in 0..2 {
        for k in 0..3 {
            p[a][k] = (j[a][0] * q_cam[0][k] + j[a][1] * q_cam[1][k]) + j[a][2] * q_cam[2][k];
            f[a][k] = p[a][k] * s[k];
        }
    }
    let cov = [dot3(f[0], f[0]), dot3(f[0], f[1]), dot3(f[1], f[1])];
    // det(F·Fᵀ) = |F₀ × F₁|² (Lagrange), and for the rotation Q, F₀ × F₁ = det(S)·S⁻¹·Qᵀ·(J₀ ×
    // J₁): component k is `s_i·s_j·n_k` ({i, j, k} = {0, 1, 2}), `n = Qᵀ·(J₀ × J₁)`, and
    // `J₀ × J₁ = (−J₀₂·J₁₁, −J₀₀·J₁₂, J₀₀·J₁₁)` (J₀₁ = J₁₀ = 0). Products and sums of
    // squares only: a needle's thin axis keeps its relative precision, which `a·c − b²`
    // cancels away once the entries exceed the thin variance by 2²⁴.
    let jc = [
        -(j[0][2] * j[1][1]),
        -(j[0][0] * j[1][2]),
        j[0][0] * j[1][1],
    ];
    let mut minors = [zero; 3];
    let ss = [s[1] * s[2], s[0] * s[2], s[0] * s[1]];
    for k in 0..3 {
        minors[k] = ss[k] * dot3([q_cam[0][k], q_cam[1][k], q_cam[2][k]], jc);
    }
    let det0 = dot3(minors, minors);
    Geometry {
        t: [x, y, z],
        qh,
        inv_qn,
        s,
        q_cam,
        rz,
        tx,
        ty,
        x_clamped: xz.lt(lim_x_neg) | xz.gt(lim_x_pos),
        y_clamped: yz.lt(lim_y_neg) | yz.gt(lim_y_pos),
        j,
        p,
        f,
        cov,
        det0,
    }
}

/// The SH basis (up to `degree`) at the view direction `(μ − C)/|μ − C|` of the lanes' means.
#[inline(always)]
pub(crate) fn sh_basis_lanes<R: Lanes>(
    mean: [R; 3],
    cam: &CameraF32,
    degree: u32,
) -> [R; MAX_SH_COEFFS] {
    let c = R::splat;
    let d = [
        mean[0] - c(cam.center[0]),
        mean[1] - c(cam.center[1]),
        mean[2] - c(cam.center[2]),
    ];
    let inv_len = R::splat(1.0) / dot3(d, d).sqrt();
    let mut basis = [R::splat(0.0); MAX_SH_COEFFS];
    sh_basis(
        degree,
        d[0] * inv_len,
        d[1] * inv_len,
        d[2] * inv_len,
        &mut basis,
    );
    basis
}

/// Rest coefficients per Gaussian at most (SH degree 5), rounded up to whole copy chunks.
pub(crate) const MAX_REST: usize = (3 * (MAX_SH_COEFFS - 1)).div_ceil(COPY) * COPY;

/// Floats per copy chunk of a staged row (one 64-byte move).
pub(crate) const COPY: usize = 16;

/// Copy row `src` (its first `len` values are the row) into `dst`, whose length is `len`
/// rounded up to [`COPY`], in whole chunks: values past `len` are those that follow the
/// row in `src` (its next row), or zeros where `src` ends. Fixed-size chunks compile to
/// vector moves; a variable-length `copy_from_slice` is a call into `memmove`, which at
/// these sizes cost as much as staging saved (4.7 % of a training iteration's samples).
#[inline(always)]
pub(crate) fn copy_padded(dst: &mut [f32], src: &[f32], len: usize) {
    for (c, d) in dst.chunks_exact_mut(COPY).enumerate() {
        let at = c * COPY;
        match src.get(at..at + COPY) {
            Some(s) => d.copy_from_slice(s),
            None => {
                for (j, v) in d.iter_mut().enumerate() {
                    *v = if at + j < len { src[at + j] } else { 0.0 };
                }
            }
        }
    }
}

/// SH colour sums `Σ_k coeff_k·Y_k(dir) + 0.5` per channel (before the clamp at 0). Lane
/// `l`'s rest coefficients are `rest[l·stride ..]` (layout of `Gaussians::sh_rest`: the
/// first `3·(num_coeffs(degree) − 1)` of a row are the ones `degree` uses). A sum is finite
/// exactly when every coefficient it uses is finite and nothing overflowed: a non-finite
/// coefficient makes its product, and so the sum, ±∞ or NaN (∞·0 is NaN), and finite
/// additions keep a sum non-finite.
#[inline(always)]
fn sh_color_lanes<R: Lanes>(
    mean: [R; 3],
    cam: &CameraF32,
    degree: u32,
    dc: [R; 3],
    rest: &[f32],
    stride: usize,
) -> [R; 3] {
    let basis = sh_basis_lanes(mean, cam, degree);
    let k_used = num_coeffs(degree) - 1;
    let mut acc = [basis[0] * dc[0], basis[0] * dc[1], basis[0] * dc[2]];
    // Eight coefficients (24 columns) per load: each channel's sum still runs in k order.
    const K_BLOCK: usize = 8;
    let mut cols = [R::splat(0.0); 3 * K_BLOCK];
    let mut k0 = 0;
    while k0 < k_used {
        let kn = (k_used - k0).min(K_BLOCK);
        R::load_columns(&rest[3 * k0..], stride, &mut cols[..3 * kn]);
        for k in 0..kn {
            for ch in 0..3 {
                acc[ch] = acc[ch] + basis[k0 + k + 1] * cols[3 * k + ch];
            }
        }
        k0 += K_BLOCK;
    }
    [
        acc[0] + R::splat(0.5),
        acc[1] + R::splat(0.5),
        acc[2] + R::splat(0.5),
    ]
}

/// The SH basis (up to `degree`) at Gaussian `i`'s view direction `(μ − C)/|μ − C|`.
pub(crate) fn sh_view_basis(
    g: &Gaussians,
    i: usize,
    cam: &CameraF32,
    degree: u32,
) -> [f32; MAX_SH_COEFFS] {
    sh_basis_lanes(g.means[i], cam, degree)
}

/// SH colour sums (before the clamp) of Gaussians `first + k` into `raw[k]` where
/// `visible[k]`, +0.0 elsewhere: the projection's colour code, `R::N` visible Gaussians
/// per block, staged side by side ([`StagedSh`]).
#[inline(always)]
fn sh_colors_range<R: Lanes>(
    g: &Gaussians,
    first: usize,
    visible: &[bool],
    cam: &CameraF32,
    degree: u32,
    raw: &mut [[f32; 3]],
) {
    let mut st = StagedSh::new(g, degree);
    for k in 0..raw.len() {
        raw[k] = [0.0; 3];
        if visible[k] && st.push(g, first + k, k) == R::N {
            st.flush::<R>(cam, degree, |slot, sum| raw[slot] = sum);
        }
    }
    st.flush::<R>(cam, degree, |slot, sum| raw[slot] = sum);
}

/// Up to sixteen Gaussians staged side by side for their SH colour in lanes: the means,
/// DC and the rest coefficients the degree uses (copied in whole [`COPY`] chunks, a row
/// every `pad` floats), and each one's entry (`slot`) in the caller's output.
pub(crate) struct StagedSh {
    used: usize,
    /// Floats of a row the degree uses, and that rounded up to whole chunks.
    len: usize,
    pad: usize,
    /// Floats per row of `Gaussians::sh_rest`.
    stride: usize,
    slot: [usize; 16],
    means: [[f32; 3]; 16],
    dc: [[f32; 3]; 16],
    rest: [f32; 16 * MAX_REST],
}

impl StagedSh {
    /// Empty, for `g`'s rows at SH `degree`.
    #[inline(always)]
    pub(crate) fn new(g: &Gaussians, degree: u32) -> Self {
        let len = 3 * (num_coeffs(degree) - 1);
        let stride = g.rest_per_channel() * 3;
        assert!(len <= stride, "SH degree {degree} beyond the scene's");
        StagedSh {
            used: 0,
            len,
            pad: len.div_ceil(COPY) * COPY,
            stride,
            slot: [0; 16],
            means: [[0.0; 3]; 16],
            dc: [[0.0; 3]; 16],
            rest: [0.0; 16 * MAX_REST],
        }
    }

    /// Stage Gaussian `i` for entry `slot`; returns how many are staged (at most 16: the
    /// caller flushes at its lane count).
    #[inline(always)]
    pub(crate) fn push(&mut self, g: &Gaussians, i: usize, slot: usize) -> usize {
        let u = self.used;
        self.slot[u] = slot;
        self.means[u] = g.means[i];
        self.dc[u] = g.sh_dc[i];
        copy_padded(
            &mut self.rest[u * self.pad..(u + 1) * self.pad],
            &g.sh_rest[i * self.stride..],
            self.len,
        );
        self.used = u + 1;
        self.used
    }

    /// The colour sums of the staged Gaussians in `R::N` lanes (the lanes past the staged
    /// ones hold earlier inputs or zeros and are not reported): `out(slot, sum)` for each,
    /// in staging order; then empty.
    #[inline(always)]
    pub(crate) fn flush<R: Lanes>(
        &mut self,
        cam: &CameraF32,
        degree: u32,
        mut out: impl FnMut(usize, [f32; 3]),
    ) {
        if self.used == 0 {
            return;
        }
        let mean = gather3::<R>(&self.means[..R::N]);
        let dc = gather3::<R>(&self.dc[..R::N]);
        let rest = &self.rest[..R::N * self.pad];
        let s = sh_color_lanes(mean, cam, degree, dc, rest, self.pad).map(lanes_of);
        for (l, &slot) in self.slot[..self.used].iter().enumerate() {
            out(slot, [s[0][l], s[1][l], s[2][l]]);
        }
        self.used = 0;
    }
}

/// [`sh_colors_range`] sixteen Gaussians per instruction.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn sh_colors_avx512(
    g: &Gaussians,
    first: usize,
    visible: &[bool],
    cam: &CameraF32,
    degree: u32,
    raw: &mut [[f32; 3]],
) {
    sh_colors_range::<F32x16>(g, first, visible, cam, degree, raw)
}

/// [`sh_colors_range`] eight Gaussians per instruction.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn sh_colors_avx2(
    g: &Gaussians,
    first: usize,
    visible: &[bool],
    cam: &CameraF32,
    degree: u32,
    raw: &mut [[f32; 3]],
) {
    sh_colors_range::<F32x8>(g, first, visible, cam, degree, raw)
}

/// SH colour sums (before the clamp) of the visible Gaussians `first ..
/// first + raw.len()` (`visible[k]` for entry `k`; +0.0 for the others), in the lane width
/// `kernel` chooses; every form gives the bits of the one-lane form (the projection's
/// colour, `project_one`).
pub(crate) fn sh_colors(
    g: &Gaussians,
    first: usize,
    visible: &[bool],
    cam: &CameraF32,
    degree: u32,
    kernel: Kernel,
    raw: &mut [[f32; 3]],
) {
    assert_eq!(visible.len(), raw.len());
    #[cfg(target_arch = "x86_64")]
    if kernel.avx512() {
        // SAFETY: AVX-512F was detected (`Kernel::avx512`).
        unsafe { sh_colors_avx512(g, first, visible, cam, degree, raw) };
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if kernel.avx2() {
        // SAFETY: AVX2 was detected (`Kernel::avx2`).
        unsafe { sh_colors_avx2(g, first, visible, cam, degree, raw) };
        return;
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = kernel;
    sh_colors_range::<f32>(g, first, visible, cam, degree, raw);
}

/// The projection of `R::N` consecutive Gaussians, one per lane.
struct Block<R: Lanes> {
    /// World-space mean (for the view direction of the colour).
    world: [R; 3],
    mean2d: [R; 2],
    conic: [R; 3],
    opacity: R,
    color: [R; 3],
    depth: R,
    radii: [R; 2],
    culls: Culls<R>,
}

/// The smallest blended α for `1/inv_alpha`: the threshold itself, or the smallest
/// positive f32 where it is 0 (`inv_alpha = +∞`), so that "α ≥ threshold" means "α > 0"
/// there (an α of exactly 0 is not blended and an opacity of 0 is culled). `1/255` by
/// default, bit for bit `ALPHA_THRESHOLD`.
#[inline(always)]
pub(crate) fn alpha_floor(inv_alpha: f32) -> f32 {
    (1.0 / inv_alpha).max(f32::from_bits(1))
}

/// Project Gaussians `i .. i + R::N`, steps 1–7 of the module docs, all lanes at once; the
/// colour (step 8) is left at 0 for [`color_block`] or a [`StagedSh`].
#[inline(always)]
fn project_block<R: Lanes>(
    g: &Gaussians,
    i: usize,
    cam: &CameraF32,
    antialiased: bool,
    inv_alpha: f32,
) -> Block<R> {
    let c = R::splat;
    let mean = gather3(&g.means[i..i + R::N]);
    let quat = R::load_dense::<4>(g.quats[i..i + R::N].as_flattened());
    let log_scale = gather3(&g.log_scales[i..i + R::N]);
    let [logit] = R::load_dense::<1>(&g.opacity_logits[i..i + R::N]);

    let mut culls = Culls::new();
    let geo = geometry_lanes(mean, quat, log_scale, cam, &mut culls);
    let [x, y, z] = geo.t;
    let (w, h) = (c(cam.width as f32), c(cam.height as f32));
    let ([a, b, cc], det) = geo.dilated();
    culls.check(!(det.gt(c(0.0)) & det.is_finite()), Cull::Degenerate);
    let inv_det = c(1.0) / det;
    let conic = [cc * inv_det, -b * inv_det, a * inv_det];
    // 6. Mean.
    let mean2d = [
        c(cam.fx) * x * geo.rz + c(cam.cx),
        c(cam.fy) * y * geo.rz + c(cam.cy),
    ];
    // 7. Opacity and radius.
    let mut opacity = c(1.0) / (c(1.0) + (-logit).exp()); // fastexp::sigmoid
    if antialiased {
        let ratio = geo.det0 / det;
        opacity = opacity * R::select(ratio.gt(c(0.0)), ratio.sqrt(), c(0.0));
    }
    // `inv_alpha` = 1/threshold (255 by default: the floor is then exactly
    // `ALPHA_THRESHOLD`; ∞ blends every α > 0 and gives every splat the 3.33σ extent).
    culls.check(opacity.lt(c(alpha_floor(inv_alpha))), Cull::LowOpacity);
    let ext = (c(2.0) * (opacity * c(inv_alpha)).ln()).sqrt();
    let ext = R::select(ext.lt(c(MAX_EXTENT_SIGMA)), ext, c(MAX_EXTENT_SIGMA));
    let rx = (ext * a.sqrt()).ceil();
    let ry = (ext * cc.sqrt()).ceil();
    culls.check(rx.le(c(0.0)) & ry.le(c(0.0)), Cull::LowOpacity);
    let off = (mean2d[0] + rx).le(c(0.0))
        | (mean2d[0] - rx).ge(w)
        | (mean2d[1] + ry).le(c(0.0))
        | (mean2d[1] - ry).ge(h);
    culls.check(off, Cull::OffScreen);
    // A non-finite parameter of the geometry is the first check of all.
    let mut params_finite = logit.is_finite();
    for k in 0..3 {
        params_finite = params_finite & mean[k].is_finite() & log_scale[k].is_finite();
    }
    for q in quat {
        params_finite = params_finite & q.is_finite();
    }
    culls.check_first(!params_finite, Cull::NonFinite);
    Block {
        world: mean,
        mean2d,
        conic,
        opacity,
        color: [c(0.0); 3],
        depth: z,
        radii: [rx, ry],
        culls,
    }
}

/// Step 8 for every lane of `b` (Gaussians `i .. i + R::N`, read in place): the colour
/// `max(sum, 0)`, or the lane culled as `NonFinite` where its sum is not finite (the last
/// check, made only where the colour is computed).
#[inline(always)]
fn color_block<R: Lanes>(b: &mut Block<R>, g: &Gaussians, i: usize, cam: &CameraF32, degree: u32) {
    let stride = g.rest_per_channel() * 3;
    let rest = &g.sh_rest[i * stride..(i + R::N) * stride];
    let dc = gather3(&g.sh_dc[i..i + R::N]);
    let sum = sh_color_lanes(b.world, cam, degree, dc, rest, stride);
    let finite = sum[0].is_finite() & sum[1].is_finite() & sum[2].is_finite();
    b.culls.check(!finite, Cull::NonFinite);
    b.color = [clamp0(sum[0]), clamp0(sum[1]), clamp0(sum[2])];
}

/// `max(v, 0)` per lane (NaN → 0).
#[inline(always)]
fn clamp0<R: Lanes>(v: R) -> R {
    let zero = R::splat(0.0);
    R::select(v.gt(zero), v, zero)
}

/// The colour `max(sum, 0)` of one staged Gaussian (a [`StagedSh`] sum), `None` where the
/// sum is not finite: [`color_block`]'s arithmetic for one lane.
#[inline(always)]
fn clamped_color(sum: [f32; 3]) -> Option<[f32; 3]> {
    sum.iter()
        .all(|v| v.is_finite())
        .then(|| sum.map(clamp0::<f32>))
}

/// Lanes `l` of `v[l]` (one slice entry per lane; `v` holds `R::N` of them).
#[inline(always)]
pub(crate) fn gather3<R: Lanes>(v: &[[f32; 3]]) -> [R; 3] {
    R::load_dense::<3>(v.as_flattened())
}

/// Lanes as an array (the first `R::N` entries).
#[inline(always)]
pub(crate) fn lanes_of<R: Lanes>(v: R) -> [f32; 16] {
    let mut a = [0f32; 16];
    v.write(&mut a);
    a
}

/// Write a block's lanes to `splats`/`radii` — its visible lanes' values, +0.0 and 0 for
/// its culled lanes (their slots' initial values: [`project`] hands out slots set to
/// `Splat::default()` and `[0, 0]`) — in one transposed store, and count each lane's
/// outcome in `counts` (`[visible, 1 + Cull …]`).
#[inline(always)]
fn store<R: Lanes>(
    b: &Block<R>,
    splats: &mut [Splat],
    radii: &mut [[i32; 2]],
    counts: &mut [u64; 7],
) {
    let all = R::all(b.culls.ok);
    let zero = R::splat(0.0);
    // Where every lane is visible (the common case) no lane needs its zeros.
    let keep = |v: R| {
        if all {
            v
        } else {
            R::select(b.culls.ok, v, zero)
        }
    };
    let fields = [
        keep(b.mean2d[0]),
        keep(b.mean2d[1]),
        keep(b.conic[0]),
        keep(b.conic[1]),
        keep(b.conic[2]),
        keep(b.opacity),
        keep(b.color[0]),
        keep(b.color[1]),
        keep(b.color[2]),
        keep(b.depth),
    ];
    R::store_columns(&fields, Splat::as_floats(&mut splats[..R::N]), SPLAT_FLOATS);
    // Radii are at most ~1e19 here; saturated to i32 for storage.
    R::store_i32_pairs(keep(b.radii[0]), keep(b.radii[1]), radii);
    let ok = R::bits(b.culls.ok);
    counts[0] += u64::from(ok.count_ones());
    let mut culled = !ok & (u32::MAX >> (32 - R::N));
    if culled != 0 {
        let code = lanes_of(b.culls.code);
        while culled != 0 {
            counts[code[culled.trailing_zeros() as usize] as usize] += 1;
            culled &= culled - 1;
        }
    }
}

/// Project one Gaussian (the reference form of what [`project`] does for every Gaussian).
pub fn project_one(
    g: &Gaussians,
    i: usize,
    cam: &CameraF32,
    plan: &RenderPlan,
    antialiased: bool,
) -> Result<(Splat, [i32; 2]), Cull> {
    let inv = plan.cutoffs.inv_alpha_threshold;
    let mut b = project_block::<f32>(g, i, cam, antialiased, inv);
    if b.culls.ok {
        color_block(&mut b, g, i, cam, plan.sh_degree);
    }
    b.culls.result()?;
    let (mut splat, mut radii, mut counts) = ([Splat::default()], [[0, 0]], [0; 7]);
    store(&b, &mut splat, &mut radii, &mut counts);
    Ok((splat[0], radii[0]))
}

/// Project Gaussians `first ..` into `splats`/`radii`, `R::N` at a time, the remainder one
/// at a time. The colour is computed only for Gaussians that survive steps 1–7: in place
/// for a block whose lanes all survive, else staged with the survivors of later blocks, so
/// that a culled Gaussian's SH coefficients are never read. A mixed block's survivors' rows
/// are asked for (prefetched) when the block is projected and staged [`AHEAD`] mixed
/// blocks later: staged right away, ≈ 20 % of the stage's samples sat on the first store after a row's
/// load (measured; 16 % after, the stage ≈ 7 % faster).
/// The staging order, and so every flush's lanes, is the same either way.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn project_range<R: Lanes>(
    g: &Gaussians,
    first: usize,
    cam: &CameraF32,
    degree: u32,
    antialiased: bool,
    inv_alpha: f32,
    splats: &mut [Splat],
    radii: &mut [[i32; 2]],
    counts: &mut [u64; 7],
) {
    let n = splats.len();
    let full = n - n % R::N;
    let mut st = StagedSh::new(g, degree);
    // Mixed blocks whose survivors' rows were asked for and are not yet staged (block
    // start, survivor bits), oldest first: staged `AHEAD` mixed blocks later, so that the
    // rows have arrived by then.
    let mut pending = [(0usize, 0u32); AHEAD];
    let (mut head, mut queued) = (0usize, 0usize);
    for k in (0..full).step_by(R::N) {
        let mut b = project_block::<R>(g, first + k, cam, antialiased, inv_alpha);
        if R::all(b.culls.ok) {
            color_block(&mut b, g, first + k, cam, degree);
            store(&b, &mut splats[k..], &mut radii[k..], counts);
            continue;
        }
        let ok = R::bits(b.culls.ok);
        prefetch_rows(&g.sh_rest, g.rest_per_channel() * 3, first + k, ok, st.pad);
        store(&b, &mut splats[k..], &mut radii[k..], counts);
        if ok == 0 {
            continue;
        }
        if queued == AHEAD {
            let (k0, ok0) = pending[head];
            stage::<R>(
                g, first, cam, degree, k0, ok0, &mut st, splats, radii, counts,
            );
            queued -= 1;
            head = (head + 1) % AHEAD;
        }
        pending[(head + queued) % AHEAD] = (k, ok);
        queued += 1;
    }
    for q in 0..queued {
        let (k0, ok0) = pending[(head + q) % AHEAD];
        stage::<R>(
            g, first, cam, degree, k0, ok0, &mut st, splats, radii, counts,
        );
    }
    st.flush::<R>(cam, degree, |k, sum| {
        set_color(k, sum, splats, radii, counts)
    });
    for k in full..n {
        let mut b = project_block::<f32>(g, first + k, cam, antialiased, inv_alpha);
        if b.culls.ok {
            color_block(&mut b, g, first + k, cam, degree);
        }
        store(&b, &mut splats[k..], &mut radii[k..], counts);
    }
}

/// Stage the survivors `ok` of the block at `k` (entries of `splats`) in `st`, flushing
/// it whenever it is full.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn stage<R: Lanes>(
    g: &Gaussians,
    first: usize,
    cam: &CameraF32,
    degree: u32,
    k: usize,
    ok: u32,
    st: &mut StagedSh,
    splats: &mut [Splat],
    radii: &mut [[i32; 2]],
    counts: &mut [u64; 7],
) {
    let mut left = ok;
    while left != 0 {
        let l = left.trailing_zeros() as usize;
        left &= left - 1;
        if st.push(g, first + k + l, k + l) == R::N {
            st.flush::<R>(cam, degree, |k, sum| {
                set_color(k, sum, splats, radii, counts)
            });
        }
    }
}

/// Mixed blocks [`project_range`] keeps between asking for their survivors' SH rows and
/// staging them (1, 4 and 16 measured alike within noise; 4 is ≈ 60 Gaussians of work,
/// longer than a miss).
pub(crate) const AHEAD: usize = 4;

/// Ask for values `0..len` from the start of row `i + l` of `rest` (rows of `stride`
/// values: SH rest coefficients; `len` may pass the row's end, as a staged copy in whole
/// chunks reads, and is cut at the array's) for each bit `l` of `ok`: one prefetch per cache
/// line. Never faults; changes no value.
#[inline(always)]
pub(crate) fn prefetch_rows(rest: &[f32], stride: usize, i: usize, ok: u32, len: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let mut left = ok;
        while left != 0 {
            let l = left.trailing_zeros() as usize;
            left &= left - 1;
            let start = (i + l) * stride;
            let row = &rest[start.min(rest.len())..(start + len).min(rest.len())];
            if row.is_empty() {
                continue;
            }
            // 16 floats per 64-byte line; the last value covers a line the steps miss.
            for off in (0..row.len()).step_by(16).chain([row.len() - 1]) {
                // SAFETY: prefetching never faults; the address is inside `row`.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(row.as_ptr().add(off).cast()) };
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (rest, stride, i, ok, len);
}

/// Entry `k`'s colour from its staged sum; where the sum is not finite the Gaussian is
/// culled after all (`NonFinite`; its slot back to the culled state, its count moved).
#[inline(always)]
fn set_color(
    k: usize,
    sum: [f32; 3],
    splats: &mut [Splat],
    radii: &mut [[i32; 2]],
    counts: &mut [u64; 7],
) {
    match clamped_color(sum) {
        Some(color) => splats[k].color = color,
        None => {
            splats[k] = Splat::default();
            radii[k] = [0, 0];
            counts[0] -= 1;
            counts[1 + Cull::NonFinite as usize] += 1;
        }
    }
}

/// [`project_range`] eight Gaussians per instruction.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn project_range_avx2(
    g: &Gaussians,
    first: usize,
    cam: &CameraF32,
    degree: u32,
    antialiased: bool,
    inv_alpha: f32,
    splats: &mut [Splat],
    radii: &mut [[i32; 2]],
    counts: &mut [u64; 7],
) {
    project_range::<F32x8>(
        g,
        first,
        cam,
        degree,
        antialiased,
        inv_alpha,
        splats,
        radii,
        counts,
    )
}

/// [`project_range`] sixteen Gaussians per instruction.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
unsafe fn project_range_avx512(
    g: &Gaussians,
    first: usize,
    cam: &CameraF32,
    degree: u32,
    antialiased: bool,
    inv_alpha: f32,
    splats: &mut [Splat],
    radii: &mut [[i32; 2]],
    counts: &mut [u64; 7],
) {
    project_range::<F32x16>(
        g,
        first,
        cam,
        degree,
        antialiased,
        inv_alpha,
        splats,
        radii,
        counts,
    )
}

/// Project every Gaussian (parallel over fixed chunks; output order is the input order).
/// `opts.kernel` chooses the lane width: sixteen Gaussians per AVX-512F instruction where
/// the CPU has it (`Kernel::Auto`), eight per AVX2 instruction (`Kernel::Auto` without
/// AVX-512F, `Kernel::Avx2`), one at a time with `Kernel::Scalar`; all give the same bits.
///
/// # Panics
/// If `plan.sh_degree` is above the scene's SH degree (`RenderPlan::new` never makes such a
/// plan).
pub fn project(
    g: &Gaussians,
    cam: &Camera,
    plan: &RenderPlan,
    opts: &RenderOptions,
    report: &mut RenderReport,
) -> Projected {
    let cam = CameraF32::new(cam);
    let n = g.len();
    // Each chunk's task initialises its own slots just before projecting into them (in
    // its cache, in parallel; not a serial memset of the whole arrays first).
    let (mut splats, mut radii) = (Vec::with_capacity(n), Vec::with_capacity(n));
    #[cfg(target_arch = "x86_64")]
    let (avx512, avx2) = (opts.kernel.avx512(), opts.kernel.avx2());
    let (degree, aa, inv) = (
        plan.sh_degree,
        opts.antialiased,
        plan.cutoffs.inv_alpha_threshold,
    );
    // Fixed chunks, written in place; per-chunk cull counts are integers, so their sum does
    // not depend on how chunks map to threads.
    const CHUNK: usize = 4096;
    let counts: Vec<[u64; 7]> = splats.spare_capacity_mut()[..n]
        .par_chunks_mut(CHUNK)
        .zip(radii.spare_capacity_mut()[..n].par_chunks_mut(CHUNK))
        .enumerate()
        .map(|(ci, (splats, radii))| {
            let (splats, radii) = (init_default(splats), init_default(radii));
            let mut c = [0u64; 7];
            let first = ci * CHUNK;
            #[cfg(target_arch = "x86_64")]
            if avx512 {
                // SAFETY: AVX-512F was detected just above.
                unsafe {
                    project_range_avx512(g, first, &cam, degree, aa, inv, splats, radii, &mut c)
                };
                return c;
            }
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                // SAFETY: AVX2 was detected just above.
                unsafe {
                    project_range_avx2(g, first, &cam, degree, aa, inv, splats, radii, &mut c)
                };
                return c;
            }
            project_range::<f32>(g, first, &cam, degree, aa, inv, splats, radii, &mut c);
            c
        })
        .collect();
    // SAFETY: the tasks above initialised every slot `..n` of both (`init_default`).
    unsafe {
        splats.set_len(n);
        radii.set_len(n);
    }
    let out = Projected { splats, radii };
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

/// `s` with every slot set to `T::default()`, as an initialised slice.
fn init_default<T: Default>(s: &mut [MaybeUninit<T>]) -> &mut [T] {
    for v in s.iter_mut() {
        v.write(T::default());
    }
    // SAFETY: every element was just initialised; `MaybeUninit<T>` has `T`'s layout.
    unsafe { &mut *(s as *mut [MaybeUninit<T>] as *mut [T]) }
}

/// `C0` as f32, for callers that convert colours to DC coefficients.
pub const SH_C0_F32: f32 = SH_C0 as f32;
