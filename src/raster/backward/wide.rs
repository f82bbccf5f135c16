//! The projection's adjoint in f64, for Gaussians beyond float32 (numerics revision 8).
//!
//! The f32 chain of [`super::project`] forms `v_F = 2·V·F` with `V = −Σ⁻¹·G·Σ⁻¹`: the conic
//! `Σ⁻¹` (entries of order `1/λ_min`) times the factor `F` (entries of order `√λ_max`) must
//! cancel to the `1/√λ_max` that lies along a needle's long axis. Each product is rounded to
//! `u` of its terms, so the long axis's share of the gradient — its scale, and every
//! parameter that moves the needle along itself — carries a relative error of about
//! `u·κ`, κ = `λ_max/λ_min` of the dilated 2D covariance: at κ = 3·10⁸ it is noise of 20×
//! its value, with the wrong sign as often as not. The forward has no such step (SPEC.md
//! §5.1: its conic is accurate entry by entry, which is all σ needs on the image), so the
//! oracle's backward contradicted its own forward there.
//!
//! Where `(a + c)² > WIDE_CONDITION·det` (κ + 2 + 1/κ, from the forward's own dilated
//! covariance, so the choice is a function of the Gaussian's inputs alone and the same in
//! every lane form and thread count), or where the quaternion's squares are subnormal
//! ([`SUBNORMAL_INV_NORM`]), the chain from the splat's gradients to the
//! camera-space mean, the log-scales and the raw quaternion runs here in f64 instead: the
//! same formulas, in the same order, with `u` 2⁻⁵³, so the error is `2⁻⁵³·κ`, below 10⁻⁶
//! for κ < 10¹⁰. Its inputs are the forward's values where the forward's function is
//! defined by them (the f32 scales, the camera's f32 matrices and Jacobian limits, which
//! side of the clamp the f32 `x/z` fell on) and the raw parameters otherwise: the gradient
//! is the exact one at the point the forward evaluated, to the conic's own float32
//! rounding (`decisions::conic_rounding`).

use crate::math::rotation_f64;
use crate::raster::project::{CameraF32, EPS2D};

/// The 2D condition (as `(a + c)²/det`, `a`, `c`, `det` the dilated covariance's) above
/// which the projection's adjoint runs in f64: 2¹², where the f32 chain's relative error
/// `u·κ` reaches 2.4·10⁻⁴ of the Gaussian's largest gradient term, the scale of the
/// harness's gradient tolerance (SPEC.md §8.1: `2e-4` of a group's largest value). Below
/// it the f32 chain stays within 10⁻⁵ of the f64 one on the long axis (test
/// `wide_adjoint_takes_over_where_f32_loses_the_long_axis`).
pub const WIDE_CONDITION: f32 = 256.0;

/// `1/|q|` above which a quaternion's squares are f32 subnormals (`|q|² < 2⁻¹²⁶`): its f32
/// normalization keeps about `log₂(|q|²/2⁻¹⁴⁹)` bits (17 at `|q|` = 10⁻²⁰, one of the
/// hard cases), and its gradient, `(v_q̂ − q̂(q̂·v_q̂))/|q|`, a projection that cancels, loses
/// more (measured 6·10⁻⁴ relative against a float64 port). Such a Gaussian's chain runs in
/// f64 too.
pub const SUBNORMAL_INV_NORM: f32 = 9.223_372e18; // 2⁶³, exact in f32

/// One Gaussian's inputs to [`adjoint`].
pub(crate) struct WideInput {
    pub mean: [f32; 3],
    pub quat: [f32; 4],
    /// `exp(log_scale)` as the forward computed it (f32).
    pub s: [f32; 3],
    /// Whether the forward clamped `x/z`, `y/z` (SPEC.md §5.1).
    pub clamped: [bool; 2],
    /// The splat's gradients: screen-space mean, conic `(A, B, C)`, camera depth.
    pub v_mean2d: [f32; 2],
    pub v_conic: [f32; 3],
    pub v_depth: f32,
}

/// Gradients of the camera-space mean, the log-scales and the raw (unnormalized)
/// quaternion, rounded to f32 once at the end.
pub(crate) struct WideGrads {
    pub v_t: [f32; 3],
    pub v_log_scale: [f32; 3],
    pub v_quat: [f32; 4],
}

fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]
}

/// The adjoint of steps 1–6 of `raster::project` for one Gaussian, in f64.
#[allow(clippy::needless_range_loop)] // a, i, k index matrices
pub(crate) fn adjoint(inp: &WideInput, cam: &CameraF32) -> WideGrads {
    let w = cam.r_cw.map(|row| row.map(f64::from));
    let m = inp.mean.map(f64::from);
    let t: [f64; 3] = std::array::from_fn(|a| dot3(w[a], m) + f64::from(cam.t_cw[a]));
    let [x, y, z] = t;
    let q = inp.quat.map(f64::from);
    let qn = ((q[0] * q[0] + q[1] * q[1]) + (q[2] * q[2] + q[3] * q[3])).sqrt();
    let qh = q.map(|v| v / qn);
    let rot = rotation_f64(qh);
    let s = inp.s.map(f64::from);
    let [lx0, lx1, ly0, ly1] = cam.jacobian_limits().map(f64::from);
    let tx = if inp.clamped[0] {
        z * (x / z).clamp(lx0, lx1)
    } else {
        x
    };
    let ty = if inp.clamped[1] {
        z * (y / z).clamp(ly0, ly1)
    } else {
        y
    };
    let (fx, fy) = (f64::from(cam.fx), f64::from(cam.fy));
    let (rz, rz2) = (1.0 / z, 1.0 / (z * z));
    let j = [
        [fx * rz, 0.0, -fx * tx * rz2],
        [0.0, fy * rz, -fy * ty * rz2],
    ];
    let Factor64 {
        q_cam,
        p,
        f,
        minors,
        ..
    } = factor64(&w, &rot, &j, s);
    // The dilated covariance and its cancellation-free determinant (SPEC.md §5.1).
    let e = f64::from(EPS2D);
    let (a0, b, c0) = (dot3(f[0], f[0]), dot3(f[0], f[1]), dot3(f[1], f[1]));
    let det = (dot3(minors, minors) + e * (a0 + c0)) + e * e;
    let (a, c) = (a0 + e, c0 + e);
    let ci = [[c / det, -b / det], [-b / det, a / det]];
    // v_Σ = −Σ⁻¹·G·Σ⁻¹, G the symmetric gradient of the conic.
    let [va, vb, vc] = inp.v_conic.map(f64::from);
    let gm = [[va, 0.5 * vb], [0.5 * vb, vc]];
    let mut tmp = [[0.0; 2]; 2];
    for r in 0..2 {
        for col in 0..2 {
            tmp[r][col] = ci[r][0] * gm[0][col] + ci[r][1] * gm[1][col];
        }
    }
    let mut v_cov = [[0.0; 2]; 2];
    for r in 0..2 {
        for col in 0..2 {
            v_cov[r][col] = -(tmp[r][0] * ci[0][col] + tmp[r][1] * ci[1][col]);
        }
    }
    // Σ = F·Fᵀ → v_F = 2·V·F; F = P·diag(s) → v_P = v_F·diag(s), v_s = Σ_a v_F·P.
    let mut v_f = [[0.0; 3]; 2];
    let mut v_p = [[0.0; 3]; 2];
    for r in 0..2 {
        for k in 0..3 {
            v_f[r][k] = 2.0 * (v_cov[r][0] * f[0][k] + v_cov[r][1] * f[1][k]);
            v_p[r][k] = v_f[r][k] * s[k];
        }
    }
    let v_log_scale: [f64; 3] =
        std::array::from_fn(|k| (v_f[0][k] * p[0][k] + v_f[1][k] * p[1][k]) * s[k]);
    // P = J·Q → v_J = v_P·Qᵀ, v_Q = Jᵀ·v_P.
    let v_j: [[f64; 3]; 2] =
        std::array::from_fn(|r| std::array::from_fn(|i| dot3(v_p[r], q_cam[i])));
    // The camera-space mean: mean2d = (fx·x/z + cx, fy·y/z + cy), the depth, and J(t).
    let [vm0, vm1] = inp.v_mean2d.map(f64::from);
    let mut v_t = [
        vm0 * fx * rz,
        vm1 * fy * rz,
        -(vm0 * fx * x + vm1 * fy * y) * rz2 + f64::from(inp.v_depth),
    ];
    let v_tx = v_j[0][2] * (-fx * rz2);
    let v_ty = v_j[1][2] * (-fy * rz2);
    v_t[2] += v_j[0][0] * (-fx * rz2)
        + v_j[1][1] * (-fy * rz2)
        + v_j[0][2] * (2.0 * fx * tx * rz2 * rz)
        + v_j[1][2] * (2.0 * fy * ty * rz2 * rz);
    // A clamped x/z makes tx = z·lim: its gradient goes to z.
    if inp.clamped[0] {
        v_t[2] += v_tx * (tx * rz);
    } else {
        v_t[0] += v_tx;
    }
    if inp.clamped[1] {
        v_t[2] += v_ty * (ty * rz);
    } else {
        v_t[1] += v_ty;
    }
    // Q = W·R → v_R = Wᵀ·Jᵀ·v_P; R(q̂) → v_q̂; q̂ = q/|q| → v_q = (v_q̂ − q̂(q̂·v_q̂))/|q|.
    let mut v_q = [[0.0; 3]; 3];
    for i in 0..3 {
        for k in 0..3 {
            v_q[i][k] = j[0][i] * v_p[0][k] + j[1][i] * v_p[1][k];
        }
    }
    let vr: [[f64; 3]; 3] = std::array::from_fn(|a| {
        std::array::from_fn(|k| {
            dot3(
                [w[0][a], w[1][a], w[2][a]],
                [v_q[0][k], v_q[1][k], v_q[2][k]],
            )
        })
    });
    let vq = quat_adjoint(qh, &vr);
    let dot = (qh[0] * vq[0] + qh[1] * vq[1]) + (qh[2] * vq[2] + qh[3] * vq[3]);
    WideGrads {
        v_t: v_t.map(|v| v as f32),
        v_log_scale: v_log_scale.map(|v| v as f32),
        v_quat: std::array::from_fn(|i| ((vq[i] - qh[i] * dot) / qn) as f32),
    }
}

/// The projection's factor in f64 (SPEC.md §5.1): the Gaussian's axes in camera space
/// `Q = W·R`, `P = J·Q`, `F = P·diag(s)`, and the 2×2 minors of `F` as `s_i·s_j·(Qᵀ·(J₀ ×
/// J₁))_k` (`jc = J₀ × J₁`, `ss_k = s_i·s_j`): products and sums, no subtraction.
pub(crate) struct Factor64 {
    pub q_cam: [[f64; 3]; 3],
    pub p: [[f64; 3]; 2],
    pub f: [[f64; 3]; 2],
    pub jc: [f64; 3],
    pub ss: [f64; 3],
    pub minors: [f64; 3],
}

/// [`Factor64`] of the camera rotation `w`, the Gaussian's rotation `rot`, the (clamped)
/// Jacobian `j` and the scales `s`.
pub(crate) fn factor64(
    w: &[[f64; 3]; 3],
    rot: &[[f64; 3]; 3],
    j: &[[f64; 3]; 2],
    s: [f64; 3],
) -> Factor64 {
    let q_cam: [[f64; 3]; 3] = std::array::from_fn(|a| {
        std::array::from_fn(|k| dot3(w[a], [rot[0][k], rot[1][k], rot[2][k]]))
    });
    let col = |k: usize| [q_cam[0][k], q_cam[1][k], q_cam[2][k]];
    let p: [[f64; 3]; 2] = std::array::from_fn(|a| std::array::from_fn(|k| dot3(j[a], col(k))));
    let f: [[f64; 3]; 2] = std::array::from_fn(|a| std::array::from_fn(|k| p[a][k] * s[k]));
    let jc = [
        -(j[0][2] * j[1][1]),
        -(j[0][0] * j[1][2]),
        j[0][0] * j[1][1],
    ];
    let ss = [s[1] * s[2], s[0] * s[2], s[0] * s[1]];
    let minors = std::array::from_fn(|k| ss[k] * dot3(col(k), jc));
    Factor64 {
        q_cam,
        p,
        f,
        jc,
        ss,
        minors,
    }
}

/// `∂L/∂q̂` from `∂L/∂R` for `R(q̂)` of a unit wxyz quaternion (the derivative of
/// `math::rotation_f64`'s matrix entries, q̂ held at unit norm).
fn quat_adjoint([w, x, y, z]: [f64; 4], vr: &[[f64; 3]; 3]) -> [f64; 4] {
    [
        2.0 * (-z * vr[0][1] + y * vr[0][2] + z * vr[1][0] - x * vr[1][2] - y * vr[2][0]
            + x * vr[2][1]),
        2.0 * (y * vr[0][1] + z * vr[0][2] + y * vr[1][0] - 2.0 * x * vr[1][1] - w * vr[1][2]
            + z * vr[2][0]
            + w * vr[2][1]
            - 2.0 * x * vr[2][2]),
        2.0 * (-2.0 * y * vr[0][0] + x * vr[0][1] + w * vr[0][2] + x * vr[1][0] + z * vr[1][2]
            - w * vr[2][0]
            + z * vr[2][1]
            - 2.0 * y * vr[2][2]),
        2.0 * (-2.0 * z * vr[0][0] - w * vr[0][1] + x * vr[0][2] + w * vr[1][0]
            - 2.0 * z * vr[1][1]
            + y * vr[1][2]
            + x * vr[2][0]
            + y * vr[2][1]),
    ]
}
