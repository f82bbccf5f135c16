//! Which views' gradients moved the Gaussians (SPEC.md §20.5, issue #72): every Adam step
//! of a fine-tune split exactly between the views of two groups, the original views and the
//! generated ones (whose loss carries the QA-Mask's weights).
//!
//! Adam's step of an element is `−step_size · m / (√v / bc₂ + ε)`: given the second moment,
//! linear in the first moment `m`, itself a decaying sum of the gradients
//! `m_t = β₁ m_{t−1} + (1 − β₁) g_t`. Keeping beside it the same sum over the generated
//! group's gradients alone, `m_gen`, the step's generated part is `step · m_gen / m` and the
//! rest is the original group's: the two parts add up to the step, whatever the second
//! moment (which both groups share, as they share the step's denominator). Summed over the
//! steps, each element's movement splits into what each group's gradients did. Densification
//! (§14.3) moves no element by a step: a copy or split child inherits its source's sums (its
//! moments start at zero, as Adam's do); the opacity reset zeroes both moments and is no
//! step. Bookkeeping beside training: no bit of the training changes (the trainer takes its
//! unfused path, whose bits are the fused path's, `fused_adam_keeps_the_bits_of_separate_steps`).

use super::adam::Adam;
use super::densify::Origin;
use crate::error::{Error, Result};
use crate::gaussian::{Gaussians, Param};
use rayon::prelude::*;

/// The parameter groups attributed: all but the view-dependent colour (`sh_rest`, three
/// quarters of a degree-3 Gaussian's elements, which would double the attribution's cost;
/// measured on the lounge at the quick preset: a reconstruction 8.5 → 15 s with it).
pub const ATTRIBUTED: [Param; 5] = [
    Param::Means,
    Param::ShDc,
    Param::OpacityLogits,
    Param::LogScales,
    Param::Quats,
];

/// Elements per parallel task: independent per element, so the split cannot change a bit.
const CHUNK: usize = 1 << 14;

/// The per-element movement of a fine-tune, split by view group.
#[derive(Clone, Debug)]
pub struct Attribution {
    /// Per view of the training set, whether it belongs to the generated group.
    generated: Vec<bool>,
    /// The generated group's share of Adam's first moment, laid out like the parameters
    /// (at SH degree 0, as are the sums: [`ATTRIBUTED`] holds no `sh_rest`).
    m_generated: Gaussians,
    /// Per element, Σ of Adam's steps, and of their generated parts.
    pub moved: Gaussians,
    pub moved_generated: Gaussians,
    /// The group's parameters before the step being attributed (reused).
    before: Vec<f32>,
}

/// Over a set of Gaussians, one parameter group's movement and the generated views' share
/// of it ([`Attribution::record`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GroupShare {
    pub param: Param,
    /// Root mean square over the elements of their net movement by Adam's steps.
    #[serde(with = "crate::io::json_float")]
    pub moved_rms: f64,
    /// `Σ moved · moved_generated / Σ moved²`: the generated views' part of the net
    /// movement, projected on it (the original views' part is one minus it; either may lie
    /// outside [0, 1] where the groups pull against each other). NaN where nothing moved.
    #[serde(with = "crate::io::json_float")]
    pub generated_share: f64,
}

/// What [`Attribution::record`] says of a set of Gaussians, as recorded.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AttributionRecord {
    /// The Gaussians of the set that the original views' gradients reached.
    pub reached: usize,
    /// One per [`ATTRIBUTED`] parameter group, in its order.
    pub groups: Vec<GroupShare>,
}

impl AttributionRecord {
    /// The generated views' share of group `p`'s movement (NaN if not recorded).
    pub fn share(&self, p: Param) -> f64 {
        self.groups
            .iter()
            .find(|g| g.param == p)
            .map_or(f64::NAN, |g| g.generated_share)
    }
}

impl Attribution {
    /// Attribution for the Gaussians `g`, the views of the training set flagged generated
    /// or not.
    pub fn new(g: &Gaussians, generated: Vec<bool>) -> Result<Self> {
        // At SH degree 0: `sh_rest` is not attributed, so its bookkeeping would be dead
        // weight copied at every densification.
        let z = Gaussians::zeros(g.len(), 0)?;
        Ok(Attribution {
            generated,
            m_generated: z.clone(),
            moved: z.clone(),
            moved_generated: z,
            before: Vec::new(),
        })
    }

    /// Whether view `vi` is in the generated group.
    pub fn is_generated(&self, vi: usize) -> bool {
        self.generated.get(vi).copied().unwrap_or(false)
    }

    /// Remember group `p` of `g` before Adam steps it (a group not [`ATTRIBUTED`] is
    /// left alone, here and in [`Attribution::after_step`]).
    pub(crate) fn before_step(&mut self, g: &Gaussians, p: Param) {
        if !ATTRIBUTED.contains(&p) {
            return;
        }
        self.before.clear();
        self.before.extend_from_slice(g.param(p));
    }

    /// Attribute the step Adam just took on group `p` (`g` after it, `adam` holding the new
    /// moments) with gradient `grad` from a view of the generated group or not.
    pub(crate) fn after_step(
        &mut self,
        g: &Gaussians,
        adam: &Adam,
        p: Param,
        grad: &[f32],
        generated: bool,
    ) {
        if !ATTRIBUTED.contains(&p) {
            return;
        }
        let (b1, ob1) = (adam.config.beta1, 1.0 - adam.config.beta1);
        let x = g.param(p);
        let m = adam.m.param(p);
        let before = &self.before;
        assert_eq!(before.len(), x.len(), "attribution of {}", p.name());
        let mg = self.m_generated.param_mut(p);
        let moved = self.moved.param_mut(p);
        let moved_g = self.moved_generated.param_mut(p);
        mg.par_chunks_mut(CHUNK)
            .zip(moved.par_chunks_mut(CHUNK))
            .zip(moved_g.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, ((mg, moved), moved_g))| {
                let e = c * CHUNK..c * CHUNK + mg.len();
                let (x, b, m, grad) = (&x[e.clone()], &before[e.clone()], &m[e.clone()], &grad[e]);
                for i in 0..mg.len() {
                    let g_gen = if generated { grad[i] } else { 0.0 };
                    mg[i] = b1 * mg[i] + ob1 * g_gen;
                    let step = x[i] - b[i];
                    moved[i] += step;
                    if m[i] != 0.0 {
                        moved_g[i] += step * (mg[i] / m[i]);
                    }
                }
            });
    }

    /// The opacity reset zeroed Adam's moments of group `p`: so are the generated group's.
    pub(crate) fn reset_moments(&mut self, p: Param) {
        self.m_generated.param_mut(p).fill(0.0);
    }

    /// Follow a densify step: each survivor takes its source's sums; a new Gaussian's
    /// generated moment starts at zero, as Adam's moments do.
    pub(crate) fn follow(&mut self, origins: &[Origin]) {
        let sources: Vec<usize> = origins.iter().map(|o| o.source()).collect();
        self.moved = self.moved.select(&sources);
        self.moved_generated = self.moved_generated.select(&sources);
        let kept: Vec<usize> = origins
            .iter()
            .filter_map(|o| match o {
                Origin::Kept(i) => Some(*i as usize),
                Origin::New(_) => None,
            })
            .collect();
        let new = origins.len() - kept.len();
        let zeros = Gaussians::zeros(new, self.m_generated.sh_degree).expect("a valid degree");
        // Kept Gaussians lead the new ones in a densify step's order (its `keep` is sorted
        // over the scene followed by its additions).
        debug_assert!(
            origins[..kept.len()]
                .iter()
                .all(|o| matches!(o, Origin::Kept(_)))
        );
        let n0 = self.m_generated.len();
        let joined: Vec<usize> = kept.iter().copied().chain(n0..n0 + new).collect();
        self.m_generated = self.m_generated.select_joined(&zeros, &joined);
    }

    /// Per parameter group, the movement of the Gaussians `which` that the original views'
    /// gradients reached (some element's original part not zero): the rest is movement the
    /// original views cannot see. Serial sums in index order.
    pub fn record(&self, which: &[usize]) -> AttributionRecord {
        let reached: Vec<usize> = which
            .iter()
            .copied()
            .filter(|&j| {
                ATTRIBUTED.iter().any(|&p| {
                    let row = row_of(&self.moved, p);
                    let (a, b) = (self.moved.param(p), self.moved_generated.param(p));
                    (j * row..(j + 1) * row).any(|e| a[e] - b[e] != 0.0)
                })
            })
            .collect();
        let shares = ATTRIBUTED
            .iter()
            .map(|&p| {
                let row = row_of(&self.moved, p);
                let (a, b) = (self.moved.param(p), self.moved_generated.param(p));
                let (mut sq, mut dot, mut n) = (0.0f64, 0.0f64, 0usize);
                for &j in &reached {
                    for e in j * row..(j + 1) * row {
                        sq += f64::from(a[e]) * f64::from(a[e]);
                        dot += f64::from(a[e]) * f64::from(b[e]);
                        n += 1;
                    }
                }
                GroupShare {
                    param: p,
                    moved_rms: if n == 0 {
                        f64::NAN
                    } else {
                        (sq / n as f64).sqrt()
                    },
                    generated_share: if sq > 0.0 { dot / sq } else { f64::NAN },
                }
            })
            .collect();
        AttributionRecord {
            reached: reached.len(),
            groups: shares,
        }
    }

    /// Checked size: the attribution follows `g`.
    pub fn check(&self, g: &Gaussians) -> Result<()> {
        if self.moved.len() != g.len() {
            return Err(Error::invalid(format!(
                "an attribution of {} Gaussians for a scene of {}",
                self.moved.len(),
                g.len()
            )));
        }
        Ok(())
    }
}

/// Elements per Gaussian of group `p`.
fn row_of(g: &Gaussians, p: Param) -> usize {
    (g.param(p).len() / g.len().max(1)).max(1)
}
