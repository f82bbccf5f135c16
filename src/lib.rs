//! # unseen
//!
//! A pure-CPU, deterministic reference implementation of *Filling the Unseen: Scene
//! Extrapolation via 3D Gaussian Splatting*. The contract — every constant, convention and
//! tolerance, with its source and the test that pins it — is `SPEC.md`.
//!
//! Conventions (SPEC.md §2): camera frame +x right, +y down, +z forward (OpenCV / gsplat);
//! pixel centres at `(j + 0.5, i + 0.5)`; quaternions wxyz; transforms named `b_from_a`.
//!
//! Modules: [`gaussian`] (parameters, INRIA PLY), [`camera`] (pinhole cameras and readers),
//! [`math`] (own `exp`, spherical harmonics), [`raster`] (projection, tiles, blending),
//! [`io`] (atomic writes, PNG, EXR, manifests), [`scene`] (procedural scenes for demos,
//! tests, benches), [`train`] (INRIA's recipe), [`qamask`] (the Quality-Aware Mask),
//! [`warp`] (DIBR, depth alignment), [`collide`] (frustums, GJK, independent views),
//! [`models`] (generator slots), [`eval`], [`oracle`] (array dumps), and on top
//! [`pipeline`]: the paper's system — independent views, stage 1, stage 2, interpolation —
//! with a resumable run directory and stage-by-stage comparison (SPEC.md §20) — and above it
//! [`batch`] (a run's waves on a batch engine, its cost, Slurm) and [`audit`] (the paper's
//! claims checked on a dataset with ground truth, SPEC.md §21).

pub mod audit;
pub mod batch;
pub mod camera;
pub mod collide;
pub mod dataset;
pub mod error;
pub mod eval;
pub mod gaussian;
pub mod io;
pub mod math;
pub mod models;
pub mod oracle;
pub mod pipeline;
pub mod qamask;
pub mod raster;
pub mod rng;
pub mod scene;
pub mod sys;
pub mod train;
pub mod version;
pub mod warp;

pub use error::{Error, ErrorKind, Result};

/// The crate's version (`Cargo.toml`), recorded in manifests and reports.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
