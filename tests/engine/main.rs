//! The engine's integration tests (package `unseen`, test `engine`): the suites that use
//! only the library, so `cargo test -p unseen` runs them, also without default features
//! (then without the ONNX suite). The suites that run the `unseen` program belong to the
//! command-line package (`tests/tests.rs`); both include the helpers of `tests/support/`.
#[path = "../support/mod.rs"]
mod support;

mod align;
mod architecture;
mod audit_rule;
mod collide;
mod dibr;
mod docs;
mod golden_drjit;
mod golden_grad;
mod gradients;
mod hard_cases;
mod hard_gradients;
mod limits;
mod mitsuba_crosscheck;
mod models;
#[cfg(feature = "onnx")]
mod onnx;
mod polytope;
mod qamask;
mod raster;
mod readers;
mod telea;
mod tile;
mod training;
mod twin;
