//! Real spherical harmonics, degrees 0..=5, in the basis and ordering of 3DGS / gsplat.
//!
//! Real SH with the Condon–Shortley phase, evaluated on a unit direction `(x, y, z)` as
//! polynomials (degrees 0–3 as INRIA's `utils/sh_utils.py`; degrees 4–5 from Sloan, "Efficient Spherical Harmonic
//! Evaluation", JCGT 2013). Coefficient `k` of degree `l` and order `m` sits at
//! `k = l² + l + m`; a degree-`L` colour has `(L+1)²` coefficients per channel.
//!
//! The basis is written once, generic over [`ShScalar`], and instantiated for `f32` (the
//! rasterizer), `f64` (tests) and [`Dual3`] (forward-mode derivatives with respect to the
//! direction), so value and gradient can never disagree about the basis.

use std::ops::{Add, Mul, Neg, Sub};

/// Highest SH degree supported.
pub const MAX_SH_DEGREE: u32 = 5;
/// Coefficients per channel for the highest degree.
pub const MAX_SH_COEFFS: usize = 36;
/// `Y_0^0 = 1 / (2 sqrt(pi))`.
pub const SH_C0: f64 = 0.282_094_791_773_878_14;

/// Number of coefficients per channel for SH degree `degree`.
pub const fn num_coeffs(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}

/// The SH degree whose coefficient count per channel is `k`, if `k` is a square ≤ 36.
pub fn degree_for_coeffs(k: usize) -> Option<u32> {
    (0..=MAX_SH_DEGREE).find(|&d| num_coeffs(d) == k)
}

/// What the generic basis needs from a number type.
pub trait ShScalar:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Neg<Output = Self>
{
    fn c(v: f64) -> Self;
}

impl ShScalar for f32 {
    #[inline(always)]
    fn c(v: f64) -> Self {
        v as f32
    }
}

impl ShScalar for f64 {
    #[inline(always)]
    fn c(v: f64) -> Self {
        v
    }
}

/// A number with its derivatives with respect to `(x, y, z)` (forward-mode AD), over any
/// [`ShScalar`]: `f64` for [`sh_basis_grad`], lanes of f32 for the backward projection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dual3<T = f64> {
    pub v: T,
    pub d: [T; 3],
}

impl<T: ShScalar> Dual3<T> {
    /// The variable `v` itself: derivative 1 with respect to component `i`.
    #[inline(always)]
    pub fn var(v: T, i: usize) -> Self {
        let mut d = [T::c(0.0); 3];
        d[i] = T::c(1.0);
        Dual3 { v, d }
    }
}

impl<T: ShScalar> Add for Dual3<T> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Dual3 {
            v: self.v + o.v,
            d: [self.d[0] + o.d[0], self.d[1] + o.d[1], self.d[2] + o.d[2]],
        }
    }
}
impl<T: ShScalar> Sub for Dual3<T> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Dual3 {
            v: self.v - o.v,
            d: [self.d[0] - o.d[0], self.d[1] - o.d[1], self.d[2] - o.d[2]],
        }
    }
}
#[allow(clippy::suspicious_arithmetic_impl)] // product rule
impl<T: ShScalar> Mul for Dual3<T> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        // Written out: a closure over lane values might not be inlined (`math::lanes`).
        Dual3 {
            v: self.v * o.v,
            d: [
                self.d[0] * o.v + self.v * o.d[0],
                self.d[1] * o.v + self.v * o.d[1],
                self.d[2] * o.v + self.v * o.d[2],
            ],
        }
    }
}
impl<T: ShScalar> Neg for Dual3<T> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Dual3 {
            v: -self.v,
            d: [-self.d[0], -self.d[1], -self.d[2]],
        }
    }
}
impl<T: ShScalar> ShScalar for Dual3<T> {
    #[inline(always)]
    fn c(v: f64) -> Self {
        Dual3 {
            v: T::c(v),
            d: [T::c(0.0); 3],
        }
    }
}

/// Evaluate the basis functions of degrees `0..=degree` at the unit direction `(x, y, z)`
/// into `out[..num_coeffs(degree)]`. Directions are not normalized here.
///
/// # Panics
/// If `degree > 5` or `out` is shorter than `num_coeffs(degree)` (programming errors).
#[inline(always)] // compiled into each SIMD caller (math::lanes)
pub fn sh_basis<T: ShScalar>(degree: u32, x: T, y: T, z: T, out: &mut [T]) {
    assert!(degree <= MAX_SH_DEGREE && out.len() >= num_coeffs(degree));
    let c = T::c;
    out[0] = c(SH_C0);
    if degree == 0 {
        return;
    }
    let c1 = 0.488_602_511_902_919_9;
    out[1] = -(c(c1) * y);
    out[2] = c(c1) * z;
    out[3] = -(c(c1) * x);
    if degree == 1 {
        return;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, yz, xz) = (x * y, y * z, x * z);
    out[4] = c(1.092_548_430_592_079_2) * xy;
    out[5] = c(-1.092_548_430_592_079_2) * yz;
    out[6] = c(0.315_391_565_252_520_05) * (((zz + zz) - xx) - yy);
    out[7] = c(-1.092_548_430_592_079_2) * xz;
    out[8] = c(0.546_274_215_296_039_6) * (xx - yy);
    if degree == 2 {
        return;
    }
    out[9] = c(-0.590_043_589_926_643_5) * y * ((c(3.0) * xx) - yy);
    out[10] = c(2.890_611_442_640_554) * xy * z;
    out[11] = c(-0.457_045_799_464_465_8) * y * ((c(4.0) * zz - xx) - yy);
    out[12] = c(0.373_176_332_590_115_4) * z * ((c(2.0) * zz - c(3.0) * xx) - c(3.0) * yy);
    out[13] = c(-0.457_045_799_464_465_8) * x * ((c(4.0) * zz - xx) - yy);
    out[14] = c(1.445_305_721_320_277) * z * (xx - yy);
    out[15] = c(-0.590_043_589_926_643_5) * x * (xx - c(3.0) * yy);
    if degree == 3 {
        return;
    }
    let z4 = zz * zz;
    out[16] = c(2.503_342_941_796_704_6) * xy * (xx - yy);
    out[17] = c(-1.770_130_769_779_930_4) * yz * (c(3.0) * xx - yy);
    out[18] = c(0.946_174_695_757_560_1) * xy * (c(7.0) * zz - c(1.0));
    out[19] = c(-0.669_046_543_557_289_2) * yz * (c(7.0) * zz - c(3.0));
    out[20] = c(0.105_785_546_915_204_31) * ((c(35.0) * z4 - c(30.0) * zz) + c(3.0));
    out[21] = c(-0.669_046_543_557_289_2) * xz * (c(7.0) * zz - c(3.0));
    out[22] = c(0.473_087_347_878_780_04) * (xx - yy) * (c(7.0) * zz - c(1.0));
    out[23] = c(-1.770_130_769_779_930_4) * xz * (xx - c(3.0) * yy);
    out[24] = c(0.625_835_735_449_176_1) * ((xx * xx - c(6.0) * xx * yy) + yy * yy);
    if degree == 4 {
        return;
    }
    let (x4, y4) = (xx * xx, yy * yy);
    let x4_6x2y2_y4 = (x4 - c(6.0) * xx * yy) + y4;
    out[25] = c(-0.656_382_056_840_170_1) * y * ((c(5.0) * x4 - c(10.0) * xx * yy) + y4);
    out[26] = c(2.075_662_314_881_041_6) * (c(4.0) * xy * z) * (xx - yy);
    out[27] = c(-0.489_238_299_435_250_4) * y * (c(3.0) * xx - yy) * (c(9.0) * zz - c(1.0));
    out[28] = c(2.396_768_392_486_662) * (c(2.0) * xy * z) * (c(3.0) * zz - c(1.0));
    out[29] = c(-0.452_946_651_195_696_94) * y * ((c(21.0) * z4 - c(14.0) * zz) + c(1.0));
    out[30] = c(0.116_950_322_453_423_6) * z * ((c(63.0) * z4 - c(70.0) * zz) + c(15.0));
    out[31] = c(-0.452_946_651_195_696_94) * x * ((c(21.0) * z4 - c(14.0) * zz) + c(1.0));
    out[32] = c(2.396_768_392_486_662) * (xx - yy) * z * (c(3.0) * zz - c(1.0));
    out[33] = c(-0.489_238_299_435_250_4) * x * (xx - c(3.0) * yy) * (c(9.0) * zz - c(1.0));
    out[34] = c(2.075_662_314_881_041_6) * z * x4_6x2y2_y4;
    out[35] = c(-0.656_382_056_840_170_1) * x * ((x4 - c(10.0) * xx * yy) + c(5.0) * y4);
}

/// Basis values and their derivatives with respect to the (unnormalized-agnostic) direction
/// components, in f64: `values[k]` and `grads[k] = dY_k/d(x, y, z)` treating `x, y, z` as
/// independent. Chain through the normalization separately when the direction is
/// `v / |v|` (the backward pass does).
pub fn sh_basis_grad(degree: u32, dir: [f64; 3], values: &mut [f64], grads: &mut [[f64; 3]]) {
    let n = num_coeffs(degree);
    let mut tmp = [Dual3::<f64>::c(0.0); MAX_SH_COEFFS];
    let var = |i: usize| Dual3::var(dir[i], i);
    sh_basis(degree, var(0), var(1), var(2), &mut tmp);
    for k in 0..n {
        values[k] = tmp[k].v;
        grads[k] = tmp[k].d;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The forward-mode gradient equals central finite differences of the f64 basis.
    #[test]
    fn sh_gradient_matches_finite_differences() {
        let dirs = [
            [0.3, -0.5, 0.81],
            [-0.9, 0.1, 0.2],
            [0.0, 0.0, 1.0],
            [0.577, 0.577, -0.577],
        ];
        for d in dirs {
            let mut vals = [0.0; MAX_SH_COEFFS];
            let mut grads = [[0.0; 3]; MAX_SH_COEFFS];
            sh_basis_grad(5, d, &mut vals, &mut grads);
            let h = 1e-6;
            for axis in 0..3 {
                let (mut p, mut m) = (d, d);
                p[axis] += h;
                m[axis] -= h;
                let (mut vp, mut vm) = ([0.0; MAX_SH_COEFFS], [0.0; MAX_SH_COEFFS]);
                sh_basis(5, p[0], p[1], p[2], &mut vp);
                sh_basis(5, m[0], m[1], m[2], &mut vm);
                for k in 0..MAX_SH_COEFFS {
                    let fd = (vp[k] - vm[k]) / (2.0 * h);
                    assert!((fd - grads[k][axis]).abs() < 1e-7, "k {k} axis {axis}");
                }
            }
            let mut v64 = [0.0; MAX_SH_COEFFS];
            sh_basis(5, d[0], d[1], d[2], &mut v64);
            assert_eq!(v64, vals);
        }
    }

    /// The f32 duals the backward projection uses agree with the f64 duals to
    /// `SH_GRAD_F32_ATOL` on 4096 Fibonacci-sphere directions, degree 5. Measured 2.2e-6: the
    /// direction's own rounding to f32 (≤ 6e-8 relative) times second derivatives of up to
    /// ~50 in degree 5, plus the f32 arithmetic of the product rule.
    #[test]
    fn sh_gradient_f32_duals_match_f64() {
        const SH_GRAD_F32_ATOL: f64 = 1e-5;
        let n = 4096;
        let mut worst = 0f64;
        for i in 0..n {
            let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = i as f64 * 2.399_963_229_728_653;
            let d = [r * phi.cos(), r * phi.sin(), z];
            let (mut vals, mut grads) = ([0.0; MAX_SH_COEFFS], [[0.0; 3]; MAX_SH_COEFFS]);
            sh_basis_grad(5, d, &mut vals, &mut grads);
            let d32 = d.map(|v| v as f32);
            let var = |a: usize| Dual3::var(d32[a], a);
            let mut y = [Dual3::<f32>::c(0.0); MAX_SH_COEFFS];
            sh_basis(5, var(0), var(1), var(2), &mut y);
            for (yk, gk) in y.iter().zip(&grads) {
                for (a, g) in yk.d.iter().zip(gk) {
                    worst = worst.max((f64::from(*a) - g).abs());
                }
            }
        }
        eprintln!("f32 dual SH gradient: worst |error| {worst:.3e}");
        assert!(worst < SH_GRAD_F32_ATOL, "{worst}");
    }

    /// Orthonormality on the sphere (Fibonacci quadrature, 20k points): ∫Y_i Y_j = δ_ij.
    #[test]
    fn sh_basis_is_orthonormal() {
        let n = 20_000;
        let mut gram = vec![0.0f64; MAX_SH_COEFFS * MAX_SH_COEFFS];
        let mut y = [0.0; MAX_SH_COEFFS];
        for i in 0..n {
            let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
            sh_basis(5, r * phi.cos(), r * phi.sin(), z, &mut y);
            for a in 0..MAX_SH_COEFFS {
                for b in 0..MAX_SH_COEFFS {
                    gram[a * MAX_SH_COEFFS + b] += y[a] * y[b];
                }
            }
        }
        let w = 4.0 * std::f64::consts::PI / n as f64;
        for a in 0..MAX_SH_COEFFS {
            for b in 0..MAX_SH_COEFFS {
                let want = if a == b { 1.0 } else { 0.0 };
                let got = gram[a * MAX_SH_COEFFS + b] * w;
                assert!((got - want).abs() < 1e-3, "<Y{a}, Y{b}> = {got}");
            }
        }
    }
}
