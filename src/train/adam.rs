//! Adam with one parameter group per Gaussian parameter array (SPEC.md §14.2).
//!
//! Per element, in this order and in f32 without fused multiply-add (PyTorch's `Adam`,
//! `foreach=False`, written out):
//!
//! ```text
//! t  ← t + 1                      (per group; skipped steps do not count)
//! m  ← β1·m + (1 − β1)·g
//! v  ← β2·v + (1 − β2)·g·g
//! p  ← p − (lr / (1 − β1ᵗ)) · m / (√v / √(1 − β2ᵗ) + ε)
//! ```
//!
//! `β1ᵗ`, `β2ᵗ` are running f64 products (no `powi`, whose rounding is platform-defined);
//! the two scalars are rounded to f32 once per step. The moments live in two [`Gaussians`]
//! of the same layout as the parameters, so densification selects and appends them with
//! the same index lists (INRIA: new Gaussians start with zero moments, pruned ones drop
//! theirs, the step count is kept).

use crate::error::{Error, Result};
use crate::gaussian::{Gaussians, GaussiansChunk, Param};
use crate::raster::backward::project::{CHUNK, ChunkGrads, GradSink, ParamView};
use crate::raster::kernel::Isa;
use rayon::prelude::*;

/// Adam's constants (INRIA: PyTorch defaults with `eps = 1e-15`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct AdamConfig {
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    /// *Sparse* Adam (gsplat's `SelectiveAdam`): a step updates only the Gaussians the
    /// iteration's view sees (radii not both 0); the others keep their parameters and both
    /// moments. Off by default (INRIA's dense Adam).
    pub sparse: bool,
}

impl AdamConfig {
    /// `β1, β2 ∈ [0, 1)` and `ε` finite and positive: the update is then finite, and a
    /// zero gradient from zero moments leaves a parameter and its moments exactly as they
    /// are (the QA-Mask fine-tune's skip relies on it, SPEC.md §15.1).
    pub fn validate(&self) -> Result<()> {
        let beta = |b: f32| (0.0..1.0).contains(&b);
        if !(beta(self.beta1) && beta(self.beta2)) {
            return Err(Error::invalid(format!(
                "Adam's beta1 and beta2 must be in [0, 1), got {} and {}",
                self.beta1, self.beta2
            )));
        }
        if !(self.eps > 0.0 && self.eps.is_finite()) {
            return Err(Error::invalid(format!(
                "Adam's eps must be finite and positive, got {}",
                self.eps
            )));
        }
        Ok(())
    }
}

impl Default for AdamConfig {
    fn default() -> Self {
        AdamConfig {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
            sparse: false,
        }
    }
}

/// Gaussians per parallel chunk: a fixed partition, so results never depend on the thread
/// count (the update is element-wise anyway), and a chunk's gradient buffer stays in L2.
const CHUNK_ROWS: usize = 256;

/// The scalars of one step, the same for every element.
#[derive(Clone, Copy)]
pub(crate) struct StepScalars {
    b1: f32,
    b2: f32,
    ob1: f32,
    ob2: f32,
    eps: f32,
    bc2_sqrt: f32,
    step_size: f32,
    /// A decaying moment's step cannot move an x with |x| strictly above this (bits; see
    /// [`update`]): `2²⁵·(|step_size|·(2⁻¹²⁶/ε·(1 + 2⁻¹⁰) + 2⁻¹⁴⁹) + 2⁻¹⁴⁹)` rounded to f32
    /// and one ulp up (+∞ when it is not finite — a NaN or infinite step size —: then no x
    /// qualifies).
    x_min_bits: u32,
}

impl StepScalars {
    fn new(b1: f32, b2: f32, eps: f32, bc2_sqrt: f32, step_size: f32) -> StepScalars {
        // |δ| for |m'| < 2⁻¹²⁶ and a denominator ≥ ε (`bc2_sqrt ≥ 0`, as `begin` gives): the
        // quotient and the product each rounded (relative 2⁻²³ in the normal range,
        // absolute 2⁻¹⁵⁰ in the subnormal one, taken as 2⁻¹⁴⁹).
        let step = f64::from(step_size).abs();
        let bound = step
            * (2f64.powi(-126) / f64::from(eps) * (1.0 + 2f64.powi(-10)) + 2f64.powi(-149))
            + 2f64.powi(-149);
        let x_min = (2f64.powi(25) * bound) as f32;
        let x_min = if x_min.is_finite() {
            x_min.next_up()
        } else {
            f32::INFINITY
        };
        StepScalars {
            b1,
            b2,
            ob1: 1.0 - b1,
            ob2: 1.0 - b2,
            eps,
            bc2_sqrt,
            step_size,
            x_min_bits: x_min.to_bits(),
        }
    }
}

/// The Adam update of a run of elements (module docs), in the reference order. Zipped
/// slices (no index checks) so the loop vectorizes; every element does the same IEEE
/// operations whatever the vector width, so the bits do not depend on it. [`update`] calls
/// it for all but blocks of decaying moments.
#[inline(always)]
fn update_plain(x: &mut [f32], m: &mut [f32], v: &mut [f32], g: &[f32], k: StepScalars) {
    for (((x, m), v), &g) in x.iter_mut().zip(m.iter_mut()).zip(v.iter_mut()).zip(g) {
        *m = k.b1 * *m + k.ob1 * g;
        *v = k.b2 * *v + k.ob2 * (g * g);
        let denom = v.sqrt() / k.bc2_sqrt + k.eps;
        *x -= k.step_size * (*m / denom);
    }
}

/// Whether f32 bits are those of a subnormal (zero excluded).
#[inline(always)]
fn subnormal(b: u32) -> bool {
    (b & 0x7FFF_FFFF).wrapping_sub(1) < 0x007F_FFFF
}

/// Elements per block of [`update`] (larger blocks measured slower).
const BLOCK: usize = 64;

/// [`update_plain`]'s bits, without subnormal arithmetic where a first moment decays.
///
/// A moment whose gradient stays exactly 0 (a Gaussian no view sees, a colour held at the
/// clamp) decays by β1 per step through the subnormals, and x86 runs every vector
/// instruction with a subnormal operand or result through a microcode assist (≈ 100+
/// cycles): late in a QA-Mask fine-tune (SPEC.md §14.2) the update ran ~5× slower. The
/// equivalence assumes the default floating-point environment (no FTZ/DAZ). A lane
/// is a *decaying moment* when m is subnormal, g = ±0, x is finite with |x| above
/// `x_min_bits` and v is finite. Per block of [`BLOCK`] elements (told by the bits alone: a
/// float comparison could take an assist itself): no subnormal m → the plain update; every
/// subnormal of x, m, v, g a decaying moment → [`update_decaying`]; otherwise the plain
/// update (the same bits at the assists' pace; rare).
#[inline(always)]
fn update(x: &mut [f32], m: &mut [f32], v: &mut [f32], g: &[f32], k: StepScalars) {
    let blocks = x
        .chunks_mut(BLOCK)
        .zip(m.chunks_mut(BLOCK))
        .zip(v.chunks_mut(BLOCK))
        .zip(g.chunks(BLOCK));
    for (((x, m), v), g) in blocks {
        let mut decay = m
            .iter()
            .fold(0u32, |a, m| a | u32::from(subnormal(m.to_bits())))
            != 0;
        if decay {
            for (((x, m), v), g) in x.iter().zip(m.iter()).zip(v.iter()).zip(g) {
                let (xb, mb, vb, gb) = (x.to_bits(), m.to_bits(), v.to_bits(), g.to_bits());
                let other = subnormal(xb) | subnormal(vb) | subnormal(gb);
                decay &= !(other | (subnormal(mb) & !decaying(xb, vb, gb, k)));
            }
        }
        if decay {
            update_decaying(x, m, v, g, k);
        } else {
            update_plain(x, m, v, g, k);
        }
    }
}

/// Whether a lane with a subnormal m (and bits `xb`, `vb`, `gb`) is a decaying moment.
#[inline(always)]
fn decaying(xb: u32, vb: u32, gb: u32, k: StepScalars) -> bool {
    let ax = xb & 0x7FFF_FFFF;
    (gb << 1 == 0) & (ax > k.x_min_bits) & (ax < 0x7F80_0000) & (vb & 0x7F80_0000 != 0x7F80_0000)
}

/// The plain update on a block whose subnormals are all decaying moments (see [`update`]),
/// the same bits without an operation on a subnormal. Those lanes run the plain arithmetic
/// with m = +0 and then take, as m, β1·m on the subnormal grid — `m = i·2⁻¹⁴⁹`, so
/// RN(β1·m) = RNE(β1·i)·2⁻¹⁴⁹ with `β1·i` exact in f64 (24 × 23 bits) and rounded to an
/// integer by adding and subtracting 1.5·2⁵² — plus `(1 − β1)·g = ±0` (a nonzero sum is
/// RN(β1·m), of sign sign(β1)·sign(m); a zero one is −0 only when both are −0). Their x is
/// unchanged, as in the plain update: |m'| < 2⁻¹²⁶ and the denominator is ≥ ε, so the step
/// is below `step_size·2⁻¹²⁶/ε` (with rounding), which `x_min_bits` keeps under half of x's
/// spacing; with m = +0 the plain arithmetic subtracts ±0 from x ≠ 0, which also gives x.
/// Their v is the plain arithmetic's (g·g = +0 either way).
#[inline(always)]
fn update_decaying(x: &mut [f32], m: &mut [f32], v: &mut [f32], g: &[f32], k: StepScalars) {
    const ROUND: f64 = 6_755_399_441_055_744.0; // 1.5·2^52: RNE to an integer below 2^51
    let b1 = f64::from(k.b1);
    for (((x, m), v), &g) in x.iter_mut().zip(m.iter_mut()).zip(v.iter_mut()).zip(g) {
        let mb = m.to_bits();
        let special = subnormal(mb);
        let m_in = if special { 0.0 } else { *m };
        let m_new = k.b1 * m_in + k.ob1 * g;
        *v = k.b2 * *v + k.ob2 * (g * g);
        let denom = v.sqrt() / k.bc2_sqrt + k.eps;
        *x -= k.step_size * (m_new / denom);
        let j = ((f64::from(mb & 0x007F_FFFF) * b1 + ROUND) - ROUND) as u32;
        // The product's sign (β1 may be −0, which the config accepts).
        let sign = (mb ^ k.b1.to_bits()) & 0x8000_0000;
        let decayed = if j != 0 { sign | j } else { sign & g.to_bits() };
        *m = if special {
            f32::from_bits(decayed)
        } else {
            m_new
        };
    }
}

/// [`update`] compiled for `isa` (the same code, auto-vectorized 4, 8 or 16 wide).
fn update_dispatch(
    isa: Isa,
    x: &mut [f32],
    m: &mut [f32],
    v: &mut [f32],
    g: &[f32],
    k: StepScalars,
) {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2")]
        fn avx2(x: &mut [f32], m: &mut [f32], v: &mut [f32], g: &[f32], k: StepScalars) {
            update(x, m, v, g, k)
        }
        #[target_feature(enable = "avx512f")]
        fn avx512(x: &mut [f32], m: &mut [f32], v: &mut [f32], g: &[f32], k: StepScalars) {
            update(x, m, v, g, k)
        }
        match isa {
            // SAFETY: `isa` comes from `Isa::detect`, which saw the feature.
            Isa::Avx512 => return unsafe { avx512(x, m, v, g, k) },
            // SAFETY: as above.
            Isa::Avx2 => return unsafe { avx2(x, m, v, g, k) },
            Isa::Baseline => {}
        }
    }
    update(x, m, v, g, k)
}

/// Step count and bias-correction products of one group.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GroupStep {
    pub t: u64,
    pub(crate) beta1_pow: f64,
    pub(crate) beta2_pow: f64,
}

impl GroupStep {
    /// A group before its first step.
    pub const START: GroupStep = GroupStep {
        t: 0,
        beta1_pow: 1.0,
        beta2_pow: 1.0,
    };

    /// Advance the step counter and the bias-correction products; the scalars of this
    /// step's update with learning rate `lr`.
    fn advance(&mut self, c: AdamConfig, lr: f32) -> StepScalars {
        self.t += 1;
        self.beta1_pow *= c.beta1 as f64;
        self.beta2_pow *= c.beta2 as f64;
        let step_size = (lr as f64 / (1.0 - self.beta1_pow)) as f32;
        let bc2_sqrt = (1.0 - self.beta2_pow).sqrt() as f32;
        StepScalars::new(c.beta1, c.beta2, c.eps, bc2_sqrt, step_size)
    }
}

/// One parameter tensor's Adam steps, each state after each step (what a port of the
/// optimizer is compared against, SPEC.md §14.2): rows of `n` values, one per step.
#[derive(Clone, Debug, PartialEq)]
pub struct AdamTrace {
    pub x: Vec<f32>,
    pub m: Vec<f32>,
    pub v: Vec<f32>,
}

/// Where the update's constants come from (SPEC.md §14.2). The element update is the same.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Constants {
    /// The trainer's: β rounded to f32 first; `1 − β` in f32 (exact) and the bias
    /// corrections' powers of that f32 β in f64.
    Unseen,
    /// `torch.optim.Adam`'s, whose β are Python floats: the decay multiplies by f32(β)
    /// (PyTorch forms the first moment by `lerp` with weight f32(1 − β1), whose rounding
    /// the port comparison allows), the gradient term by f32(1 − β) with `1 − β` in f64 (0.001 for β2 = 0.999, not the
    /// f32 `1 − 0.999f32` = 0.00099998713), the bias corrections are powers of the f64 β,
    /// and the step size is f32(lr / (1 − β1ᵗ)) with lr in f64.
    PyTorch,
}

impl Constants {
    /// The profile named `pytorch` or `unseen` (what the CLI and the Python binding take).
    pub fn by_name(name: &str) -> Result<Constants> {
        match name {
            "pytorch" => Ok(Constants::PyTorch),
            "unseen" => Ok(Constants::Unseen),
            other => Err(Error::invalid(format!(
                "unknown conventions '{other}' (pytorch or unseen)"
            ))),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Constants::PyTorch => "pytorch",
            Constants::Unseen => "unseen",
        }
    }
}

/// Adam from zero moments (a fresh optimizer, as `torch.optim.Adam` starts) on `x0` with
/// the gradients `grads` (`steps` rows of `x0.len()` values) at learning rate `lr` under
/// `constants`: with [`Constants::Unseen`] the very update [`Adam::step`] makes on one
/// group (β and lr rounded to f32 as the trainer holds them), the same bits.
pub fn adam_trace(
    betas: [f64; 2],
    eps: f32,
    lr: f64,
    constants: Constants,
    x0: &[f32],
    grads: &[f32],
) -> Result<AdamTrace> {
    let config = AdamConfig {
        beta1: betas[0] as f32,
        beta2: betas[1] as f32,
        eps,
        sparse: false,
    };
    config.validate()?;
    if !lr.is_finite() {
        return Err(Error::invalid(format!("Adam: lr must be finite, got {lr}")));
    }
    let n = x0.len();
    if n == 0 || !grads.len().is_multiple_of(n) {
        return Err(Error::invalid(format!(
            "Adam: {} gradient values are not whole steps of {n} parameters",
            grads.len()
        )));
    }
    let (mut x, mut m, mut v) = (x0.to_vec(), vec![0f32; n], vec![0f32; n]);
    let mut trace = AdamTrace {
        x: Vec::with_capacity(grads.len()),
        m: Vec::with_capacity(grads.len()),
        v: Vec::with_capacity(grads.len()),
    };
    let (isa, mut step) = (Isa::detect(), GroupStep::START);
    let mut powers = [1f64; 2];
    for g in grads.chunks_exact(n) {
        let k = match constants {
            Constants::Unseen => step.advance(config, lr as f32),
            Constants::PyTorch => {
                powers = [powers[0] * betas[0], powers[1] * betas[1]];
                let step_size = (lr / (1.0 - powers[0])) as f32;
                let bc2_sqrt = (1.0 - powers[1]).sqrt() as f32;
                StepScalars {
                    ob1: (1.0 - betas[0]) as f32,
                    ob2: (1.0 - betas[1]) as f32,
                    ..StepScalars::new(config.beta1, config.beta2, eps, bc2_sqrt, step_size)
                }
            }
        };
        update_dispatch(isa, &mut x, &mut m, &mut v, g, k);
        trace.x.extend_from_slice(&x);
        trace.m.extend_from_slice(&m);
        trace.v.extend_from_slice(&v);
    }
    Ok(trace)
}

/// The optimizer state for a set of Gaussians.
#[derive(Clone, Debug, PartialEq)]
pub struct Adam {
    pub config: AdamConfig,
    /// First and second moments, laid out like the parameters.
    pub m: Gaussians,
    pub v: Gaussians,
    /// One per [`Param::ALL`] entry.
    pub steps: [GroupStep; 6],
}

fn group_index(p: Param) -> usize {
    Param::ALL.iter().position(|&q| q == p).expect("listed")
}

/// Where a step's gradient comes from: a whole array, or chunk by chunk (`Adam::step_with`).
#[derive(Clone, Copy)]
enum Grad<'a> {
    Slice(&'a [f32]),
    Chunks(&'a (dyn Fn(usize, &mut [f32]) + Sync)),
}

impl Adam {
    pub fn new(config: AdamConfig, params: &Gaussians) -> Result<Self> {
        let z = Gaussians::zeros(params.len(), params.sh_degree)?;
        Ok(Adam {
            config,
            m: z.clone(),
            v: z,
            steps: [GroupStep::START; 6],
        })
    }

    /// Number of steps taken by group `p`.
    pub fn step_count(&self, p: Param) -> u64 {
        self.steps[group_index(p)].t
    }

    /// One Adam step of group `p` with learning rate `lr`.
    pub fn step(&mut self, params: &mut Gaussians, p: Param, grad: &[f32], lr: f32) {
        self.step_sparse(params, p, grad, lr, None);
    }

    /// [`Adam::step`] that, with `visible`, updates only the Gaussians `i` with
    /// `visible[i]`: the others keep their parameters and moments (sparse Adam). The step
    /// counter advances either way, so the bias correction is the dense one.
    pub fn step_sparse(
        &mut self,
        params: &mut Gaussians,
        p: Param,
        grad: &[f32],
        lr: f32,
        visible: Option<&[bool]>,
    ) {
        assert_eq!(
            params.param_mut(p).len(),
            grad.len(),
            "gradient length of {}",
            p.name()
        );
        self.step_impl(params, p, lr, Grad::Slice(grad), visible);
    }

    /// [`Adam::step`] with the gradient produced chunk by chunk: `grad(first, out)` fills
    /// `out` with the gradient of elements `first..first + out.len()` of the group (chunks
    /// hold whole Gaussians). A caller that can compute its gradient per Gaussian (the
    /// QA-Mask fine-tune) never materializes the full gradient array; the bits are those
    /// of [`Adam::step_sparse`] with the same gradient and `visible`. With `visible`,
    /// `grad` is not called for a chunk without a visible Gaussian.
    pub fn step_with(
        &mut self,
        params: &mut Gaussians,
        p: Param,
        lr: f32,
        grad: &(dyn Fn(usize, &mut [f32]) + Sync),
        visible: Option<&[bool]>,
    ) {
        self.step_impl(params, p, lr, Grad::Chunks(grad), visible);
    }

    /// Advance group `p`'s step counter and bias-correction products and return the
    /// scalars of its update with learning rate `lr`: the first half of every step, shared
    /// by [`Adam::step`] and the fused chunks of [`Adam::fused_chunks`].
    pub(crate) fn begin(&mut self, p: Param, lr: f32) -> StepScalars {
        let c = self.config;
        self.steps[group_index(p)].advance(c, lr)
    }

    /// The scene and its moments in chunks of [`CHUNK`] Gaussians that take their
    /// projection gradients straight into the update ([`project_backward_apply`]): group
    /// `p` is updated with `steps[i]` where `Param::ALL[i] = p` (from [`Adam::begin`]) and
    /// left alone where that is `None`. Every element gets the operations of
    /// [`Adam::step`] (dense), so the bits are the same; the scene's gradient arrays are
    /// never written or read back (SPEC.md §14.2).
    ///
    /// [`project_backward_apply`]: crate::raster::backward::project::project_backward_apply
    pub(crate) fn fused_chunks<'a>(
        &'a mut self,
        params: &'a mut Gaussians,
        steps: [Option<StepScalars>; 6],
    ) -> Vec<AdamChunk<'a>> {
        let isa = Isa::detect();
        params
            .chunks_mut(CHUNK)
            .into_iter()
            .zip(self.m.chunks_mut(CHUNK))
            .zip(self.v.chunks_mut(CHUNK))
            .map(|((params, m), v)| AdamChunk {
                params,
                m,
                v,
                steps,
                isa,
            })
            .collect()
    }

    fn step_impl(
        &mut self,
        params: &mut Gaussians,
        p: Param,
        lr: f32,
        grad: Grad,
        visible: Option<&[bool]>,
    ) {
        if let Some(vis) = visible {
            assert_eq!(vis.len(), params.len(), "visibility length");
        }
        let k = self.begin(p, lr);
        let isa = Isa::detect();
        let row = (params.param(p).len() / params.len().max(1)).max(1);
        let chunk = row * CHUNK_ROWS;
        let x = params.param_mut(p);
        let m = self.m.param_mut(p);
        let v = self.v.param_mut(p);
        assert_eq!(x.len(), m.len(), "moment length of {}", p.name());
        x.par_chunks_mut(chunk)
            .zip(m.par_chunks_mut(chunk))
            .zip(v.par_chunks_mut(chunk))
            .enumerate()
            .for_each_init(Vec::new, |buf, (ci, ((x, m), v))| {
                let first = ci * chunk;
                let rows = visible.map(|vis| &vis[ci * CHUNK_ROWS..][..x.len() / row]);
                if rows.is_some_and(|r| !r.contains(&true)) {
                    return; // nothing to update: no gradient to make
                }
                // A gradient array is read in place; a chunked one is made in `buf`.
                let g: &[f32] = match grad {
                    Grad::Slice(g) => &g[first..first + x.len()],
                    Grad::Chunks(f) => {
                        buf.resize(x.len(), 0.0);
                        f(first, buf);
                        buf
                    }
                };
                let update = |x: &mut [f32], m: &mut [f32], v: &mut [f32], g: &[f32]| {
                    update_dispatch(isa, x, m, v, g, k);
                };
                match rows {
                    None => update(x, m, v, g),
                    Some(rows) => {
                        for (k, _) in rows.iter().enumerate().filter(|(_, v)| **v) {
                            let e = k * row..(k + 1) * row;
                            update(
                                &mut x[e.clone()],
                                &mut m[e.clone()],
                                &mut v[e.clone()],
                                &g[e],
                            );
                        }
                    }
                }
            });
    }

    /// Zero both moments of group `p` (INRIA's `replace_tensor_to_optimizer`, used by the
    /// opacity reset).
    pub fn reset_moments(&mut self, p: Param) {
        self.m.param_mut(p).fill(0.0);
        self.v.param_mut(p).fill(0.0);
    }

    /// Keep the moments of the Gaussians at `indices` (in that order).
    pub fn select(&mut self, indices: &[usize]) {
        self.m = self.m.select(indices);
        self.v = self.v.select(indices);
    }

    /// Keep the moments at `indices` of the current Gaussians followed by `n` new ones
    /// with zero moments ([`Gaussians::select_joined`]): appending zero moments and then
    /// selecting, without the intermediate copies.
    pub fn select_joined(&mut self, n: usize, indices: &[usize]) -> Result<()> {
        let z = Gaussians::zeros(n, self.m.sh_degree)?;
        self.m = self.m.select_joined(&z, indices);
        self.v = self.v.select_joined(&z, indices);
        Ok(())
    }
}

/// A chunk of Gaussians with its moments ([`Adam::fused_chunks`]).
pub(crate) struct AdamChunk<'a> {
    params: GaussiansChunk<'a>,
    m: GaussiansChunk<'a>,
    v: GaussiansChunk<'a>,
    steps: [Option<StepScalars>; 6],
    isa: Isa,
}

impl GradSink for AdamChunk<'_> {
    fn params(&self) -> ParamView<'_> {
        let p = &self.params;
        ParamView {
            means: p.means,
            log_scales: p.log_scales,
            quats: p.quats,
            opacity_logits: p.opacity_logits,
            sh_rest: p.sh_rest,
            rest_per: p.rest_per,
            base: p.base,
        }
    }

    fn take(&mut self, grads: &ChunkGrads) {
        for (p, k) in Param::ALL.into_iter().zip(self.steps) {
            if let Some(k) = k {
                let (x, m, v) = (
                    self.params.param_mut(p),
                    self.m.param_mut(p),
                    self.v.param_mut(p),
                );
                update_dispatch(self.isa, x, m, v, grads.param(p), k);
            }
        }
    }
}

/// INRIA's `get_expon_lr_func` without delay: log-linear from `init` to `final_` over
/// `max_steps`, constant after. Evaluated in f32 with the crate's own `exp`/`ln`, so the
/// rate does not depend on the platform's libm.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExpSchedule {
    pub init: f32,
    #[serde(rename = "final")]
    pub final_: f32,
    pub max_steps: u32,
}

impl ExpSchedule {
    pub fn at(&self, step: u32) -> f32 {
        use crate::math::fastexp::{exp, ln};
        if self.init == self.final_ {
            return self.init;
        }
        if self.init <= 0.0 || self.final_ <= 0.0 {
            return 0.0;
        }
        let t = if self.max_steps == 0 {
            1.0
        } else {
            (step as f32 / self.max_steps as f32).clamp(0.0, 1.0)
        };
        exp(ln(self.init) * (1.0 - t) + ln(self.final_) * t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every vector width gives the reference bits (values spanning many magnitudes,
    /// lengths that leave remainders for every width).
    #[test]
    fn update_is_bit_identical_across_vector_widths() {
        let k = StepScalars::new(0.9, 0.999, 1e-15, 0.0316, 0.0123);
        let n = 1037;
        let val = |i: usize, s: f32| (i as f32 * s).sin() * 10f32.powi((i % 13) as i32 - 6);
        let x0: Vec<f32> = (0..n).map(|i| val(i, 0.37)).collect();
        let m0: Vec<f32> = (0..n).map(|i| val(i, 0.71)).collect();
        let v0: Vec<f32> = (0..n).map(|i| val(i, 0.13).abs()).collect();
        let g: Vec<f32> = (0..n).map(|i| val(i, 1.91)).collect();
        let run = |isa: Isa| {
            let (mut x, mut m, mut v) = (x0.clone(), m0.clone(), v0.clone());
            update_dispatch(isa, &mut x, &mut m, &mut v, &g, k);
            [x, m, v].map(|a| a.iter().map(|f| f.to_bits()).collect::<Vec<_>>())
        };
        let reference = run(Isa::Baseline);
        assert_eq!(run(Isa::detect()), reference, "{:?}", Isa::detect());
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            assert_eq!(run(Isa::Avx2), reference);
        }
    }

    /// The update with decaying moments taken apart ([`update`], [`update_decaying`]) gives
    /// [`update_plain`]'s bits: blocks of normal values of every magnitude, subnormal first
    /// moments with ±0 gradients (the decaying case) of every sign and size, and the cases
    /// that must fall back (a subnormal m with a nonzero gradient, subnormal x, v or g, an
    /// x too small to keep, x or v not finite, signed zeros), for several β1, step sizes
    /// (0, negative, huge) and ε, at every vector width.
    #[test]
    fn decaying_moments_give_the_plain_bits() {
        use crate::rng::Uniform;
        let mut u = Uniform::new(41);
        let sub = |u: &mut Uniform| {
            let sign = if u.unit() < 0.5 { 0x8000_0000 } else { 0 };
            // Mantissas across their range: 1, small, mid, 2^23 − 1.
            let mant = match u.below(4) {
                0 => 1 + u.below(4),
                1 => 1 + u.below(1 << 10),
                2 => 1 + u.below((1 << 23) - 1),
                _ => (1 << 23) - 1 - u.below(3),
            };
            f32::from_bits(sign | mant)
        };
        // Normal values of every magnitude (1e-30 … 1e6), never subnormal.
        let normal = |u: &mut Uniform| {
            let e = u.range(-30.0, 6.0);
            (u.unit() + 0.5) * 10f32.powf(e) * if u.unit() < 0.5 { -1.0 } else { 1.0 }
        };
        let bits = |a: &[f32]| a.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
        let mut decayed = 0;
        for case in 0..400 {
            let (b1, step, eps) = match case % 9 {
                8 => (-0.0, 0.0123, 1e-15),
                0 => (0.9, 0.0123, 1e-15),
                1 => (0.5, 3e-4, 1e-15),
                2 => (0.0, 0.0123, 1e-15),
                3 => (0.999, -0.02, 1e-8),
                4 => (0.9, 0.0, 1e-15),
                5 => (0.9, 1e10, 1e-15),
                6 => (0.9, 0.0123, 1e-40),
                _ => (0.9, 1e-30, 1.0),
            };
            let k = StepScalars::new(b1, 0.999, eps, 0.0316, step);
            let n = 1 + u.below(200) as usize;
            // Mostly decaying lanes among normal ones; now and then a lane that must fall
            // back, so both paths and the classification are exercised.
            let rare = case % 3 == 0;
            let (mut x, mut m, mut v, mut g) =
                (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            for i in 0..n {
                x[i] = normal(&mut u);
                m[i] = normal(&mut u);
                v[i] = normal(&mut u).abs();
                g[i] = normal(&mut u);
                if u.unit() < 0.4 {
                    m[i] = sub(&mut u);
                    g[i] = if u.unit() < 0.5 { 0.0 } else { -0.0 };
                    x[i] = (u.unit() - 0.5) * 10f32.powf(u.range(-10.0, 3.0));
                    if case % 3 == 1 && u.unit() < 0.2 {
                        // The largest steps (v = 0: the denominator is ε) against x of
                        // every size down to the normal floor: some are moved by them.
                        v[i] = 0.0;
                        x[i] = (u.unit() + 0.5) * 10f32.powf(u.range(-37.0, -10.0));
                    }
                }
                if rare && u.unit() < 0.03 {
                    match u.below(9) {
                        0 => g[i] = normal(&mut u),
                        1 => g[i] = sub(&mut u),
                        2 => v[i] = sub(&mut u).abs(),
                        3 => x[i] = sub(&mut u),
                        4 => x[i] = 1e-36,
                        5 => x[i] = [f32::NAN, f32::INFINITY, -0.0, 0.0][u.below(4) as usize],
                        6 => v[i] = [f32::NAN, f32::INFINITY, 0.0][u.below(3) as usize],
                        7 => {
                            m[i] =
                                [f32::MIN_POSITIVE, -f32::MIN_POSITIVE * 1.05][u.below(2) as usize]
                        }
                        _ => m[i] = -0.0,
                    }
                }
            }
            let plain = {
                let (mut x, mut m, mut v) = (x.clone(), m.clone(), v.clone());
                update_plain(&mut x, &mut m, &mut v, &g, k);
                [bits(&x), bits(&m), bits(&v)]
            };
            let isas = [Isa::Baseline, Isa::detect()];
            for isa in isas {
                let (mut x, mut m, mut v) = (x.clone(), m.clone(), v.clone());
                update_dispatch(isa, &mut x, &mut m, &mut v, &g, k);
                assert_eq!(
                    [bits(&x), bits(&m), bits(&v)],
                    plain,
                    "case {case}, {isa:?}"
                );
            }
            let decaying_only = (0..n).all(|i| {
                let (xb, mb, vb, gb) = (
                    x[i].to_bits(),
                    m[i].to_bits(),
                    v[i].to_bits(),
                    g[i].to_bits(),
                );
                !(subnormal(xb) | subnormal(vb) | subnormal(gb))
                    && (!subnormal(mb) || decaying(xb, vb, gb, k))
            });
            if decaying_only {
                // Only normal values and decaying moments: the decaying form itself.
                let (mut x2, mut m2, mut v2) = (x.clone(), m.clone(), v.clone());
                update_decaying(&mut x2, &mut m2, &mut v2, &g, k);
                assert_eq!(
                    [bits(&x2), bits(&m2), bits(&v2)],
                    plain,
                    "case {case}, decaying"
                );
                decayed += 1;
            }
        }
        assert!(decayed > 100, "{decayed} blocks of decaying moments");
    }

    /// `step_with` with `visible` gives the bits of `step_sparse` with the same gradient and
    /// never asks for the gradient of a chunk without a visible Gaussian.
    #[test]
    fn chunked_sparse_step_skips_invisible_chunks() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let n = 3 * CHUNK_ROWS + 17;
        let mut a = Gaussians::zeros(n, 1).unwrap();
        for (i, x) in a.sh_rest.iter_mut().enumerate() {
            *x = (i as f32 * 0.37).sin();
        }
        let mut b = a.clone();
        let grad: Vec<f32> = (0..a.sh_rest.len())
            .map(|i| (i as f32 * 0.11).cos())
            .collect();
        // Visible: Gaussians 0–9, and every 7th from 2·256 + 50 on; chunk 1 has none.
        let visible: Vec<bool> = (0..n)
            .map(|i| i < 10 || (i >= 2 * CHUNK_ROWS + 50 && i % 7 == 0))
            .collect();
        let mut adam_a = Adam::new(AdamConfig::default(), &a).unwrap();
        let mut adam_b = adam_a.clone();
        let calls = AtomicUsize::new(0);
        for _ in 0..3 {
            adam_a.step_sparse(&mut a, Param::ShRest, &grad, 1e-2, Some(&visible));
            adam_b.step_with(
                &mut b,
                Param::ShRest,
                1e-2,
                &|first, out| {
                    calls.fetch_add(1, Ordering::Relaxed);
                    out.copy_from_slice(&grad[first..first + out.len()]);
                },
                Some(&visible),
            );
        }
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a.sh_rest), bits(&b.sh_rest));
        assert_eq!(bits(&adam_a.m.sh_rest), bits(&adam_b.m.sh_rest));
        assert_eq!(bits(&adam_a.v.sh_rest), bits(&adam_b.v.sh_rest));
        // Chunks 0, 2 and 3 of 4, three steps: 9 calls.
        assert_eq!(calls.load(Ordering::Relaxed), 9);
    }
}
