//! Training building blocks. For now: SSIM and its gradient (`ssim`), used by the oracle's
//! `l1-dssim` loss; the optimizer and densification arrive with the training issue.

pub mod ssim;
