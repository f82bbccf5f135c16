//! What a render must compute ("simulate only what the scene and the caller need").
//!
//! A [`RenderPlan`] is derived from the caller's [`RenderOptions`] and the scene. Each skip
//! below gives output bit-identical to the full computation (tests in `tests/raster.rs`):
//!
//! | skip | when | why it is exact |
//! |---|---|---|
//! | depth accumulation | no depth output requested | depth never feeds colour |
//! | SH bands above the highest non-zero band | always | `0·Y` adds ±0, and `+0.5` erases the sign of a zero |
//! | per-pixel `final_t` / `n_contrib`, per-intersection `blend_halves` bookkeeping | not requested (inference) | bookkeeping only |
//! | background term `T·bg` | background is exactly black | `C + T·0 = C` for `C ≥ 0` |
//! | rows of a tile outside a Gaussian's radius + 1 px | unless a lower alpha threshold lets the 3.33σ cap bind | `α < 1/255` there (SPEC.md §5.4) |

use super::{Conventions, Cutoffs, RenderOptions};
use crate::gaussian::Gaussians;

/// The outputs a caller may ask for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Outputs {
    pub rgb: bool,
    pub alpha: bool,
    /// Accumulated depth `D = Σ wᵢ zᵢ` (camera z, background 0).
    pub depth: bool,
    /// Expected depth `ED = D / max(alpha, 1e-10)`.
    pub expected_depth: bool,
    /// Per-pixel final transmittance and `n_contrib`, and per (tile, Gaussian) intersection
    /// the row halves that blended it (`blend_halves`), as the backward pass needs.
    pub backward_state: bool,
}

impl Outputs {
    pub const RGB: Outputs = Outputs {
        rgb: true,
        alpha: false,
        depth: false,
        expected_depth: false,
        backward_state: false,
    };
    pub const ALL: Outputs = Outputs {
        rgb: true,
        alpha: true,
        depth: true,
        expected_depth: true,
        backward_state: true,
    };
}

impl Default for Outputs {
    fn default() -> Self {
        Outputs::RGB
    }
}

/// The work a render will do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderPlan {
    /// SH degree actually evaluated.
    pub sh_degree: u32,
    pub accumulate_depth: bool,
    pub track_backward_state: bool,
    pub apply_background: bool,
    /// Skip tile rows a Gaussian cannot reach. Off only in tests that prove it exact.
    pub cull_rows: bool,
    /// Where blending is cut off (the caller's [`RenderOptions::cutoffs`]).
    pub cutoffs: Cutoffs,
    /// The caller's [`RenderOptions::conventions`] (the α clamp).
    pub conventions: Conventions,
}

impl RenderPlan {
    /// The minimal plan for `opts` on `scene`.
    pub fn new(scene: &Gaussians, opts: &RenderOptions) -> RenderPlan {
        let plan = Self::for_backward(scene, opts);
        RenderPlan {
            sh_degree: match plan.sh_degree {
                0 => 0, // nothing to skip: no scan of the coefficients
                d => d.min(scene.highest_nonzero_band()),
            },
            ..plan
        }
    }

    /// [`RenderPlan::new`] evaluating every requested SH band: a render for the backward
    /// pass needs the zero bands too (the gradient of a zero coefficient is not zero).
    pub fn for_backward(scene: &Gaussians, opts: &RenderOptions) -> RenderPlan {
        RenderPlan {
            sh_degree: opts
                .sh_degree
                .unwrap_or(scene.sh_degree)
                .min(scene.sh_degree),
            accumulate_depth: opts.outputs.depth || opts.outputs.expected_depth,
            track_backward_state: opts.outputs.backward_state,
            apply_background: opts.background != [0.0; 3],
            cull_rows: opts.cutoffs.rows_cull_exactly(),
            cutoffs: opts.cutoffs,
            conventions: opts.conventions,
        }
    }

    /// The plan that computes everything (the reference the skips are tested against).
    pub fn full(scene: &Gaussians, opts: &RenderOptions) -> RenderPlan {
        RenderPlan {
            sh_degree: opts
                .sh_degree
                .unwrap_or(scene.sh_degree)
                .min(scene.sh_degree),
            accumulate_depth: true,
            track_backward_state: true,
            apply_background: true,
            cull_rows: false,
            cutoffs: opts.cutoffs,
            conventions: opts.conventions,
        }
    }
}
