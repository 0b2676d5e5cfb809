//! The vector instruction set the CPU kernels (`super::kernels`) run on: the best this CPU
//! has, or AVX2/FMA on request ([`Isa::ENV`]), so that an AVX-512 machine can measure the
//! path a CPU without AVX-512 runs.

use std::sync::OnceLock;

/// An x86 vector instruction set for the CPU kernels: the matrix products
/// (`kernels::gemm_into`) and the row loops (LayerNorm, softmax, GELU).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Isa {
    /// AVX-512F (16 f32 lanes per register): the gemm crate's AVX-512 microkernels, row loops
    /// compiled for x86-64-v4.
    Avx512,
    /// AVX2 and FMA (8 f32 lanes per register), row loops compiled for x86-64-v3: what a CPU
    /// without AVX-512 runs, and what an AVX-512 CPU runs when asked to.
    Avx2,
    /// Neither (SSE2, or not x86-64): the gemm crate's and pulp's own choice.
    Baseline,
}

/// A value of [`Isa::ENV`] that names no instruction set.
#[derive(Debug, thiserror::Error)]
#[error("{var}={value:?} names no instruction set (expected `native` or `avx2`)", var = Isa::ENV)]
pub struct UnknownIsa {
    /// The value as read.
    pub value: String,
}

/// What [`Isa::ENV`] asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IsaRequest {
    /// The best this CPU has (also when the variable is unset or empty).
    Native,
    /// AVX2/FMA, even on a CPU with AVX-512.
    Avx2,
}

impl std::str::FromStr for IsaRequest {
    type Err = UnknownIsa;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "" | "native" => Ok(IsaRequest::Native),
            "avx2" => Ok(IsaRequest::Avx2),
            _ => Err(UnknownIsa { value: s.to_owned() }),
        }
    }
}

impl std::fmt::Display for Isa {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Isa::Avx512 => "avx512",
            Isa::Avx2 => "avx2",
            Isa::Baseline => "baseline",
        })
    }
}

impl Isa {
    /// The environment variable that picks the set for a whole process: `avx2`, or `native`
    /// (also when unset).
    pub const ENV: &'static str = "MOGEN_SIMD";

    /// The best set this CPU has.
    pub fn best() -> Isa {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f") {
            return Isa::Avx512;
        }
        if Isa::Avx2.is_available() {
            Isa::Avx2
        } else {
            Isa::Baseline
        }
    }

    /// The set `request` asks for on this CPU: the best it has, capped at AVX2 for
    /// [`IsaRequest::Avx2`].
    pub fn for_request(request: IsaRequest) -> Isa {
        match (request, Isa::best()) {
            (IsaRequest::Avx2, Isa::Avx512) => Isa::Avx2,
            (_, best) => best,
        }
    }

    /// What [`Isa::ENV`] asks for ([`IsaRequest::Native`] when unset).
    pub fn request_from_env() -> Result<IsaRequest, UnknownIsa> {
        std::env::var(Self::ENV).map_or(Ok(IsaRequest::Native), |v| v.parse())
    }

    /// The set the kernels use unless a caller picks one: [`Isa::for_request`] of
    /// [`Isa::request_from_env`], read once per process (an unknown value is logged and read
    /// as `native`).
    pub fn selected() -> Isa {
        static SELECTED: OnceLock<Isa> = OnceLock::new();
        *SELECTED.get_or_init(|| {
            let request = Isa::request_from_env().unwrap_or_else(|e| {
                tracing::warn!("{e}; running the best set this CPU has");
                IsaRequest::Native
            });
            Isa::for_request(request)
        })
    }

    /// Whether this CPU runs the set.
    pub fn is_available(self) -> bool {
        match self {
            Isa::Avx512 => Isa::best() == Isa::Avx512,
            Isa::Avx2 => avx2_fma().is_some(),
            Isa::Baseline => true,
        }
    }

    /// Runs `f` compiled for this set, so that plain loops inside it auto-vectorise beyond
    /// the SSE2 baseline. `f` and the loops it calls must be `#[inline(always)]` so they are
    /// compiled inside the dispatched function. A set the CPU lacks runs pulp's own choice.
    #[inline(always)]
    pub(crate) fn vectorize<R>(self, f: impl FnOnce() -> R) -> R {
        struct Op<F>(F);
        impl<R, F: FnOnce() -> R> pulp::WithSimd for Op<F> {
            type Output = R;
            #[inline(always)]
            fn with_simd<S: pulp::Simd>(self, _simd: S) -> R {
                (self.0)()
            }
        }
        #[cfg(target_arch = "x86_64")]
        if let (Isa::Avx2, Some(simd)) = (self, avx2_fma()) {
            return pulp::Simd::vectorize(simd, Op(f));
        }
        pulp::Arch::new().dispatch(Op(f))
    }
}

/// pulp's AVX2/FMA token (x86-64-v3), where this CPU has those.
#[cfg(target_arch = "x86_64")]
pub(crate) fn avx2_fma() -> Option<pulp::x86::V3> {
    pulp::x86::V3::try_new()
}

#[cfg(not(target_arch = "x86_64"))]
pub(crate) fn avx2_fma() -> Option<()> {
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_names_and_rejects_others() {
        assert_eq!("avx2".parse::<IsaRequest>().ok(), Some(IsaRequest::Avx2));
        assert_eq!(" AVX2 ".parse::<IsaRequest>().ok(), Some(IsaRequest::Avx2));
        assert_eq!("native".parse::<IsaRequest>().ok(), Some(IsaRequest::Native));
        assert_eq!("".parse::<IsaRequest>().ok(), Some(IsaRequest::Native));
        let err = "avx1024".parse::<IsaRequest>().err().map(|e| e.to_string());
        assert!(err.is_some_and(|e| e.contains("MOGEN_SIMD") && e.contains("avx1024")));
    }

    #[test]
    fn a_request_never_exceeds_the_cpu() {
        let best = Isa::best();
        assert!(best.is_available());
        assert_eq!(Isa::for_request(IsaRequest::Native), best);
        let capped = Isa::for_request(IsaRequest::Avx2);
        assert!(capped.is_available());
        assert_ne!(capped, Isa::Avx512);
    }
}
