//! AVX2: the one dispatch of the kernels onto an `avx2,fma` build of themselves. The loops written with
//! intrinsics (those the compiler does not vectorise on its own) stand beside their scalar forms.

/// A kernel compiled twice: `run::<true>` inside an `avx2,fma` function, `run::<false>` for any CPU.
pub(crate) trait Simd {
    type Output;
    fn run<const AVX2: bool>(self) -> Self::Output;
}

thread_local! {
    /// Set inside [`scalar_paths`] on the thread that runs it.
    static SCALAR_HERE: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// True where `RTLOOP_SIMD=scalar` was set (read once per process): every kernel then takes its
/// portable path. Any other value, or none, lets the CPU decide.
fn scalar_by_environment() -> bool {
    static SCALAR: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *SCALAR.get_or_init(|| {
        std::env::var("RTLOOP_SIMD").is_ok_and(|v| v.trim().eq_ignore_ascii_case("scalar"))
    })
}

/// True where the CPU has AVX2 and FMA (std caches the check), unless the scalar paths were asked for
/// (`RTLOOP_SIMD=scalar`, or [`scalar_paths`] on this thread).
#[inline]
pub(crate) fn detected() -> bool {
    if SCALAR_HERE.get() || scalar_by_environment() {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// The kernel path a loss computed on this thread takes now: `"avx2"` or `"scalar"`.
pub fn path() -> &'static str {
    if detected() {
        "avx2"
    } else {
        "scalar"
    }
}

/// Runs `f` with every loss it computes on this thread on the scalar (non-AVX2) paths (the tasks such a
/// loss hands the thread pool follow it); other threads are unaffected. For tests comparing the paths.
pub fn scalar_paths<R>(f: impl FnOnce() -> R) -> R {
    struct Restore(bool);
    impl Drop for Restore {
        fn drop(&mut self) {
            SCALAR_HERE.set(self.0);
        }
    }
    let _restore = Restore(SCALAR_HERE.replace(true));
    f()
}

/// `k.run::<true>()` built for AVX2 + FMA when `avx2`, else `k.run::<false>()`. `avx2` must come from
/// [`detected`] or from the `AVX2` of a `Simd::run` reached through here (a task of the thread pool
/// re-enters this way).
#[inline(always)]
pub(crate) fn dispatch<K: Simd>(k: K, avx2: bool) -> K::Output {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is only true once the CPU's features were checked (see above).
        return unsafe { run_avx2(k) };
    }
    let _ = avx2;
    k.run::<false>()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn run_avx2<K: Simd>(k: K) -> K::Output {
    k.run::<true>()
}
