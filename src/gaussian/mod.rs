//! Gaussians as INRIA 3DGS stores them: raw (pre-activation) parameters, struct of arrays.
//!
//! | field | activation | shape |
//! |---|---|---|
//! | `means` | identity (world units) | N × 3 |
//! | `log_scales` | `exp` | N × 3 |
//! | `quats` | normalize, **wxyz** | N × 4 |
//! | `opacity_logits` | sigmoid | N |
//! | `sh_dc` | colour = `max(C0·dc + Σ rest·Y + 0.5, 0)` | N × 3 |
//! | `sh_rest` | coefficient-major `(N, K−1, 3)` like gsplat | N × (K−1) × 3 |
//!
//! `K = (degree+1)²`. The PLY file stores `f_rest` channel-major (see [`ply`]).

pub mod ply;

use crate::error::{Error, Result};
use crate::math::sh::{MAX_SH_DEGREE, num_coeffs};

/// A set of 3D Gaussians with raw parameters.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gaussians {
    pub means: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    /// Rotation quaternions, `[w, x, y, z]`, not necessarily normalized.
    pub quats: Vec<[f32; 4]>,
    pub opacity_logits: Vec<f32>,
    pub sh_dc: Vec<[f32; 3]>,
    /// `(N, K−1, 3)`: entry `(i, j, c)` at `(i·(K−1) + j)·3 + c` is coefficient `j+1` of
    /// channel `c`.
    pub sh_rest: Vec<f32>,
    pub sh_degree: u32,
}

/// Gaussians `base .. base + means.len()` of a set, borrowed mutably
/// ([`Gaussians::chunks_mut`]).
#[derive(Debug)]
pub struct GaussiansChunk<'a> {
    pub means: &'a mut [[f32; 3]],
    pub log_scales: &'a mut [[f32; 3]],
    pub quats: &'a mut [[f32; 4]],
    pub opacity_logits: &'a mut [f32],
    pub sh_dc: &'a mut [[f32; 3]],
    /// `rest_per` values per Gaussian.
    pub sh_rest: &'a mut [f32],
    pub rest_per: usize,
    pub base: usize,
}

impl GaussiansChunk<'_> {
    /// One parameter group, flat (the layout of [`Gaussians::param`]).
    pub fn param_mut(&mut self, p: Param) -> &mut [f32] {
        match p {
            Param::Means => self.means.as_flattened_mut(),
            Param::ShDc => self.sh_dc.as_flattened_mut(),
            Param::ShRest => self.sh_rest,
            Param::OpacityLogits => self.opacity_logits,
            Param::LogScales => self.log_scales.as_flattened_mut(),
            Param::Quats => self.quats.as_flattened_mut(),
        }
    }
}

impl Gaussians {
    /// An empty set with the given SH degree.
    pub fn new(sh_degree: u32) -> Result<Self> {
        if sh_degree > MAX_SH_DEGREE {
            return Err(Error::invalid(format!(
                "SH degree {sh_degree} > {MAX_SH_DEGREE}"
            )));
        }
        Ok(Gaussians {
            sh_degree,
            ..Default::default()
        })
    }

    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Higher-order coefficients per channel, `K − 1`.
    pub fn rest_per_channel(&self) -> usize {
        num_coeffs(self.sh_degree) - 1
    }

    /// The `K−1` rest coefficients of Gaussian `i`, as `[j][channel]`.
    pub fn rest(&self, i: usize) -> &[f32] {
        let r = self.rest_per_channel() * 3;
        &self.sh_rest[i * r..(i + 1) * r]
    }

    /// Append one Gaussian. `rest` must hold `(K−1)·3` values, coefficient-major.
    pub fn push(
        &mut self,
        mean: [f32; 3],
        log_scale: [f32; 3],
        quat_wxyz: [f32; 4],
        opacity_logit: f32,
        dc: [f32; 3],
        rest: &[f32],
    ) {
        assert_eq!(
            rest.len(),
            self.rest_per_channel() * 3,
            "rest coefficient count"
        );
        self.means.push(mean);
        self.log_scales.push(log_scale);
        self.quats.push(quat_wxyz);
        self.opacity_logits.push(opacity_logit);
        self.sh_dc.push(dc);
        self.sh_rest.extend_from_slice(rest);
    }

    /// Check that every array has N entries.
    pub fn validate(&self) -> Result<()> {
        let n = self.len();
        let ok = self.log_scales.len() == n
            && self.quats.len() == n
            && self.opacity_logits.len() == n
            && self.sh_dc.len() == n
            && self.sh_rest.len() == n * self.rest_per_channel() * 3
            && self.sh_degree <= MAX_SH_DEGREE;
        if ok {
            Ok(())
        } else {
            Err(Error::invalid(
                "Gaussian parameter arrays have inconsistent lengths",
            ))
        }
    }

    /// The highest SH band with a non-zero coefficient in any Gaussian (0 if none).
    /// Bands above it contribute exactly zero, so the rasterizer may skip them
    /// (test `plan_skips_zero_sh_bands_bit_identically`).
    pub fn highest_nonzero_band(&self) -> u32 {
        let k1 = self.rest_per_channel();
        let mut best = 0u32;
        for g in
            self.sh_rest
                .chunks_exact((k1 * 3).max(1))
                .take(if k1 == 0 { 0 } else { self.len() })
        {
            for band in (best + 1..=self.sh_degree).rev() {
                let lo = (num_coeffs(band - 1) - 1) * 3;
                let hi = (num_coeffs(band) - 1) * 3;
                if g[lo..hi].iter().any(|&v| v != 0.0) {
                    best = band;
                    break;
                }
            }
            if best == self.sh_degree {
                break;
            }
        }
        best
    }
}

/// One parameter array of [`Gaussians`] (an optimizer parameter group).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Param {
    Means,
    ShDc,
    ShRest,
    OpacityLogits,
    LogScales,
    Quats,
}

impl Param {
    /// INRIA's optimizer order (`xyz`, `f_dc`, `f_rest`, `opacity`, `scaling`, `rotation`).
    pub const ALL: [Param; 6] = [
        Param::Means,
        Param::ShDc,
        Param::ShRest,
        Param::OpacityLogits,
        Param::LogScales,
        Param::Quats,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Param::Means => "means",
            Param::ShDc => "sh_dc",
            Param::ShRest => "sh_rest",
            Param::OpacityLogits => "opacity_logits",
            Param::LogScales => "log_scales",
            Param::Quats => "quats",
        }
    }
}

impl Gaussians {
    /// The flat `f32` values of one parameter array.
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

    pub fn param_mut(&mut self, p: Param) -> &mut [f32] {
        match p {
            Param::Means => self.means.as_flattened_mut(),
            Param::ShDc => self.sh_dc.as_flattened_mut(),
            Param::ShRest => &mut self.sh_rest,
            Param::OpacityLogits => &mut self.opacity_logits,
            Param::LogScales => self.log_scales.as_flattened_mut(),
            Param::Quats => self.quats.as_flattened_mut(),
        }
    }

    /// The parameters split into consecutive chunks of `len` Gaussians (the last may be
    /// shorter), each borrowed mutably on its own, so that chunks can be updated in
    /// parallel.
    pub fn chunks_mut(&mut self, len: usize) -> Vec<GaussiansChunk<'_>> {
        assert!(len > 0, "chunk length");
        let rest_per = self.rest_per_channel() * 3;
        let mut out = Vec::with_capacity(self.len().div_ceil(len));
        let mut means = &mut self.means[..];
        let mut log_scales = &mut self.log_scales[..];
        let mut quats = &mut self.quats[..];
        let mut opacity_logits = &mut self.opacity_logits[..];
        let mut sh_dc = &mut self.sh_dc[..];
        let mut sh_rest = &mut self.sh_rest[..];
        let mut base = 0;
        while !means.is_empty() {
            let k = len.min(means.len());
            // Split each array's head off (`take` leaves an empty slice behind).
            fn head<'a, T>(v: &mut &'a mut [T], k: usize) -> &'a mut [T] {
                let (a, b) = std::mem::take(v).split_at_mut(k);
                *v = b;
                a
            }
            out.push(GaussiansChunk {
                means: head(&mut means, k),
                log_scales: head(&mut log_scales, k),
                quats: head(&mut quats, k),
                opacity_logits: head(&mut opacity_logits, k),
                sh_dc: head(&mut sh_dc, k),
                sh_rest: head(&mut sh_rest, k * rest_per),
                rest_per,
                base,
            });
            base += k;
        }
        out
    }

    /// `n` Gaussians with every parameter 0 (the layout of optimizer moments).
    pub fn zeros(n: usize, sh_degree: u32) -> Result<Self> {
        let mut g = Gaussians::new(sh_degree)?;
        let k1 = g.rest_per_channel();
        g.means = vec![[0.0; 3]; n];
        g.log_scales = vec![[0.0; 3]; n];
        g.quats = vec![[0.0; 4]; n];
        g.opacity_logits = vec![0.0; n];
        g.sh_dc = vec![[0.0; 3]; n];
        g.sh_rest = vec![0.0; n * k1 * 3];
        Ok(g)
    }

    /// The Gaussians at `indices`, in that order (indices may repeat).
    pub fn select(&self, indices: &[usize]) -> Gaussians {
        self.select_joined(&self.head(0), indices)
    }

    /// The first `n` Gaussians (at most all).
    fn head(&self, n: usize) -> Gaussians {
        let n = n.min(self.len());
        let r = self.rest_per_channel() * 3;
        Gaussians {
            means: self.means[..n].to_vec(),
            log_scales: self.log_scales[..n].to_vec(),
            quats: self.quats[..n].to_vec(),
            opacity_logits: self.opacity_logits[..n].to_vec(),
            sh_dc: self.sh_dc[..n].to_vec(),
            sh_rest: self.sh_rest[..n * r].to_vec(),
            sh_degree: self.sh_degree,
        }
    }

    /// The Gaussians at `indices` of `self` followed by `extra` (index `len() + j` is
    /// `extra`'s `j`), in that order: each array allocated once at its final size and
    /// filled in parallel over fixed runs of indices (densification builds its result
    /// this way instead of appending to the whole scene and its moments, which copied them
    /// into fresh, page-faulting memory twice more). Plain copies: the same values as
    /// appending and selecting.
    ///
    /// # Panics
    /// If the SH degrees differ or an index is out of range.
    pub fn select_joined(&self, extra: &Gaussians, indices: &[usize]) -> Gaussians {
        use rayon::prelude::*;
        assert_eq!(
            self.sh_degree, extra.sh_degree,
            "SH degree of the joined set"
        );
        const RUN: usize = 4096;
        let n = self.len();
        let r = self.rest_per_channel() * 3;
        let mut sh_rest = vec![0f32; indices.len() * r];
        if r > 0 {
            sh_rest
                .par_chunks_mut(r * RUN)
                .zip(indices.par_chunks(RUN))
                .for_each(|(dst, run)| {
                    for (d, &i) in dst.chunks_exact_mut(r).zip(run) {
                        let (src, k) = if i < n {
                            (&self.sh_rest, i)
                        } else {
                            (&extra.sh_rest, i - n)
                        };
                        d.copy_from_slice(&src[k * r..(k + 1) * r]);
                    }
                });
        }
        fn pick<T: Copy + Send + Sync>(a: &[T], b: &[T], indices: &[usize]) -> Vec<T> {
            let n = a.len();
            indices
                .par_iter()
                .with_min_len(RUN)
                .map(|&i| if i < n { a[i] } else { b[i - n] })
                .collect()
        }
        Gaussians {
            means: pick(&self.means, &extra.means, indices),
            log_scales: pick(&self.log_scales, &extra.log_scales, indices),
            quats: pick(&self.quats, &extra.quats, indices),
            opacity_logits: pick(&self.opacity_logits, &extra.opacity_logits, indices),
            sh_dc: pick(&self.sh_dc, &extra.sh_dc, indices),
            sh_rest,
            sh_degree: self.sh_degree,
        }
    }

    /// Append `other` (same SH degree) after the last Gaussian.
    pub fn append(&mut self, other: &Gaussians) {
        assert_eq!(self.sh_degree, other.sh_degree, "SH degree of appended set");
        self.means.extend_from_slice(&other.means);
        self.log_scales.extend_from_slice(&other.log_scales);
        self.quats.extend_from_slice(&other.quats);
        self.opacity_logits.extend_from_slice(&other.opacity_logits);
        self.sh_dc.extend_from_slice(&other.sh_dc);
        self.sh_rest.extend_from_slice(&other.sh_rest);
    }
}
