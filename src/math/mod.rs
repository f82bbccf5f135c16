//! Small fixed-size maths: the crate's own `exp`/`ln`, libm-free `floor`/`ceil`, real
//! spherical harmonics, and the lane type per-Gaussian code is written in.

pub mod fastexp;
pub mod lanes;
pub mod round;
pub mod sh;

/// The widest vector unit the CPU offers to auto-vectorized loops compiled per instruction
/// set (Adam's update, the SSIM blur): code that does the same IEEE operations per element
/// at any width gives the same bits under each (detected once per call site).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Isa {
    Baseline,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Isa {
    pub(crate) fn detect() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx512f") {
                return Isa::Avx512;
            }
            if std::is_x86_feature_detected!("avx2") {
                return Isa::Avx2;
            }
        }
        Isa::Baseline
    }
}
