//! The crate's one SIMD vocabulary. [`Kernel`] is what a caller asks for; `Isa` is the
//! instruction set that then runs, resolved once per call site from the CPU's features;
//! the `ISA_*` tags are the same three sets as const-generic parameters of the kernels
//! written once for all widths. Every form gives the same bits (SPEC.md §5.7).

/// Which compiled form of the per-Gaussian (projection) and per-pixel (blend) kernels runs.
/// All give identical bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Kernel {
    /// The fastest form this CPU supports, detected at run time: AVX-512F for the forward
    /// and backward blends and both projections (forward and backward), AVX2 elsewhere.
    #[default]
    Auto,
    /// AVX2 where detected, never AVX-512 (tests and benches compare the forms).
    Avx2,
    /// One pixel (one Gaussian) at a time, no vectorization: the reference form.
    Scalar,
}

impl Kernel {
    /// The instruction set this choice runs on this CPU.
    pub(crate) fn isa(self) -> Isa {
        match self {
            Kernel::Auto => Isa::detect(),
            Kernel::Avx2 => Isa::detect().min(Isa::AVX2_OR_BASELINE),
            Kernel::Scalar => Isa::Baseline,
        }
    }
    /// Whether the AVX2 forms run.
    pub(crate) fn avx2(self) -> bool {
        self.isa() != Isa::Baseline
    }
    /// Whether the AVX-512F forms run, where one exists.
    pub(crate) fn avx512(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        return self.isa() == Isa::Avx512;
        #[cfg(not(target_arch = "x86_64"))]
        false
    }
}

/// The widest vector unit the CPU offers, ordered by width. Kernels written with
/// intrinsics dispatch on it; loops compiled once per instruction set and auto-vectorized
/// (Adam's update, the SSIM blur) do the same IEEE operations per element at any width,
/// so they give the same bits under each.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
pub(crate) enum Isa {
    /// The target's baseline (SSE2 on x86-64): the scalar reference forms.
    Baseline,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Isa {
    /// AVX2 where the target has the variant, else the baseline ([`Kernel::Avx2`]'s cap).
    #[cfg(target_arch = "x86_64")]
    const AVX2_OR_BASELINE: Isa = Isa::Avx2;
    #[cfg(not(target_arch = "x86_64"))]
    const AVX2_OR_BASELINE: Isa = Isa::Baseline;

    /// The widest set this CPU has (the detection is cached by the standard library),
    /// capped by [`MAX_ISA_VAR`].
    pub(crate) fn detect() -> Isa {
        Isa::cpu().min(Isa::cap())
    }

    fn cpu() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            // The AVX-512F forms use AVX2 too (and `Kernel::avx2` reads "at least AVX2").
            if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx2") {
                return Isa::Avx512;
            }
            if std::is_x86_feature_detected!("avx2") {
                return Isa::Avx2;
            }
        }
        Isa::Baseline
    }

    /// The cap [`MAX_ISA_VAR`] sets, read once per process (none when unset; a value it
    /// does not know is reported once on stderr and sets none).
    fn cap() -> Isa {
        static CAP: std::sync::OnceLock<Isa> = std::sync::OnceLock::new();
        *CAP.get_or_init(|| {
            let widest = Isa::Baseline.max(Isa::AVX2_OR_BASELINE);
            #[cfg(target_arch = "x86_64")]
            let widest = widest.max(Isa::Avx512);
            match std::env::var(MAX_ISA_VAR).as_deref() {
                Err(_) | Ok("") | Ok("avx512f") => widest,
                Ok("avx2") => Isa::AVX2_OR_BASELINE,
                Ok("scalar") => Isa::Baseline,
                Ok(other) => {
                    eprintln!(
                        "{MAX_ISA_VAR}={other:?} is not one of avx512f, avx2, scalar: ignored"
                    );
                    widest
                }
            }
        })
    }

    /// The set's name as benches print it.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Isa::Baseline => "no AVX2",
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => "AVX2",
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => "AVX-512F",
        }
    }
}

/// The environment variable that caps the instruction set every kernel runs on (`avx2`, or
/// `scalar` for the baseline; `avx512f` or unset: the CPU's widest), so that the narrower
/// forms can be measured on a wider CPU. Every form gives the same bits (SPEC.md §5.7).
pub const MAX_ISA_VAR: &str = "UNSEEN_MAX_ISA";

/// The instruction set [`Kernel::Auto`] runs on here (after [`MAX_ISA_VAR`]): "AVX-512F",
/// "AVX2" or "no AVX2".
pub fn auto_isa_name() -> &'static str {
    Isa::detect().name()
}

/// [`Isa::Baseline`] as a const-generic tag: kernels written once for all widths take the
/// instruction set as a `const ISA: u8` (an enum cannot be a const parameter).
pub(crate) const ISA_SCALAR: u8 = 0;
/// [`Isa::Avx2`] as a const-generic tag.
pub(crate) const ISA_AVX2: u8 = 1;
/// [`Isa::Avx512`] as a const-generic tag.
pub(crate) const ISA_AVX512: u8 = 2;
