//! Training (SPEC.md §13–14): losses ([`loss`], [`ssim`]), Adam ([`adam`]), adaptive
//! density control ([`densify`]), the loop ([`trainer`]), checkpoints ([`checkpoint`]) and the
//! run directory ([`run`]).

pub mod adam;
pub mod attribution;
pub mod checkpoint;
pub mod densify;
pub mod knn;
pub mod loss;
pub mod run;
pub mod ssim;
pub mod trainer;
