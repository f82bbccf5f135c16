//! The two numbers that say which results this build reproduces: the conventions version
//! (what a port must match) and the numerics revision (what bits this code computes). Every
//! manifest, checkpoint, pipeline step key and audit record carries them.

/// The conventions version of SPEC.md (bumped when a number a port must match changes).
pub const CONVENTIONS_VERSION: u32 = 1;

/// The numerics revision (SPEC.md §20.8): bumped whenever any bit of any stage's output
/// changes — a new summation order, another form of a derivative — including changes the
/// conventions version does not cover (numbers a port matches only to a tolerance). Part
/// of every pipeline step's key, so neither a step cache nor `--resume` reuses a result the
/// current code would not reproduce bit for bit. History: 1 before issue #13; 2 the
/// backward blend's lane-pair summation order; 3 the f32 SH direction derivative; 4 GJK's
/// verdict on its certified lower bound (differs only where GJK stalls on nearly parallel
/// faces); 5 depth supervision on the generated views only (the original views' dataset
/// depth became the non-paper switch `original_view_depth`), Eq. 4's mean as
/// `r₀ + Σ(rⱼ − r₀)/n` (exact for equal ranges); 6 stage 2's dependent-view depth by video
/// depth alignment (the least-squares fit to the stage-1 render became the non-paper
/// `stage2_depth: render_fit`); 7 the projection's 2D covariance from its factor `F = J·W·R·S`
/// and its determinant as a sum of squared minors (issue #51: stable on needles); 8 the
/// projection backward's chain in f64 for Gaussians of 2D condition above
/// `raster::backward::wide::WIDE_CONDITION` (issue #70: the f32 chain contradicted the
/// forward on needles).
pub const NUMERICS_REVISION: u32 = 8;
