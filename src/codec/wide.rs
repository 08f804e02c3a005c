//! The decoders' row kernels built twice: for the baseline x86-64 the crate targets (SSE2:
//! two `f64` a vector) and for AVX2 (four), the one chosen at run time per call.
//!
//! A kernel's loops (predictions summed across a row, roundings, conversions of codes to
//! heights) are what the compiler vectorises, and with AVX2 each vector holds twice the
//! numbers. Building the whole crate for `x86-64-v3` is no answer: pco's decoder, built that
//! way, was slower (2.0 → 2.9 ns a sample, `docs/benchmarks.md`). So only the kernels get an
//! AVX2 build, and pco is called outside them, before.
//!
//! The two builds give the same bits: Rust's `f64` and `f32` operations are IEEE's whatever
//! the instruction set, and Rust never fuses a multiply and an add into one rounding (the
//! `fma` feature is not enabled here in any case). The tests decode through both builds and
//! compare them with each other and with the general per-sample loops.

/// Defines `fn $name` as a dispatcher to the body given, compiled twice: with AVX2 when the
/// CPU has it (checked at each call, a load of a cached flag), else for the baseline. The
/// body is inlined into both, with every helper it calls that is `#[inline(always)]`;
/// anything not inlined runs as the baseline build.
macro_rules! wide {
    ($(#[$attr:meta])* $vis:vis fn $name:ident $(<$($lt:lifetime),+>)? ($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? $body:block) => {
        $(#[$attr])*
        $vis fn $name $(<$($lt),+>)? ($($arg: $ty),*) $(-> $ret)? {
            #[inline(always)]
            fn kernel $(<$($lt),+>)? ($($arg: $ty),*) $(-> $ret)? $body
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2")]
                fn avx2 $(<$($lt),+>)? ($($arg: $ty),*) $(-> $ret)? {
                    kernel($($arg),*)
                }
                if $crate::codec::wide::avx2() {
                    // SAFETY: the CPU has AVX2 (`avx2()` just checked), the one feature
                    // `avx2`'s build assumes.
                    return unsafe { avx2($($arg),*) };
                }
            }
            kernel($($arg),*)
        }
    };
}

#[cfg(any(test, feature = "testing"))]
thread_local! {
    /// Set by a test or a bench to run this thread's kernels as their baseline build.
    pub(crate) static BASELINE: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f` with this thread's kernels as their baseline build, whatever the CPU: the tests
/// compare the two builds' output, `benches/decode.rs` their speed, side by side.
#[cfg(any(test, feature = "testing"))]
pub fn baseline<R>(f: impl FnOnce() -> R) -> R {
    struct Reset;
    impl Drop for Reset {
        fn drop(&mut self) {
            BASELINE.with(|b| b.set(false));
        }
    }
    BASELINE.with(|b| b.set(true));
    let _reset = Reset;
    f()
}

/// Whether the kernels run as their AVX2 build: the CPU has AVX2 (and, in the tests, this
/// thread has not asked for the baseline).
#[cfg(target_arch = "x86_64")]
#[inline]
pub(crate) fn avx2() -> bool {
    #[cfg(any(test, feature = "testing"))]
    if BASELINE.with(std::cell::Cell::get) {
        return false;
    }
    std::arch::is_x86_feature_detected!("avx2")
}
