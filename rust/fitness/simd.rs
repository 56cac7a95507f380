//! AVX2: the one dispatch of the kernels onto an `avx2,fma` build of themselves, and the two loops the
//! compiler does not vectorise on its own (written with intrinsics).

#[cfg(target_arch = "x86_64")]
use super::light_terms::irradiance_exact;
#[cfg(target_arch = "x86_64")]
use super::loss::LANES;
use super::pixels::{Group, Light};

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

/// AVX2 form of `irradiance`: 1/d³ from the hardware reciprocal square root refined by one Newton step
/// (relative error about 1e-7, the same as the exact `nl / (d2 * sqrt(d2))` in f32), eight pixels at a
/// time; the tail goes through the exact form.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) unsafe fn irradiance_avx2(
    g: &Group,
    r: std::ops::Range<usize>,
    light: &Light,
    e: &mut [f32],
) {
    use std::arch::x86_64::*;
    let n = e.len();
    let full = n - n % 8;
    let s = r.start;
    let (lx, ly, lz) = (
        _mm256_set1_ps(light.pos[0]),
        _mm256_set1_ps(light.pos[1]),
        _mm256_set1_ps(light.pos[2]),
    );
    let (tiny, big, zero) = (
        _mm256_set1_ps(f32::MIN_POSITIVE),
        _mm256_set1_ps(f32::MAX),
        _mm256_setzero_ps(),
    );
    let mut i = 0;
    while i < full {
        let ld = |v: &Vec<f32>| _mm256_loadu_ps(v.as_ptr().add(s + i));
        let dx = _mm256_sub_ps(lx, ld(&g.p[0]));
        let dy = _mm256_sub_ps(ly, ld(&g.p[1]));
        let dz = _mm256_sub_ps(lz, ld(&g.p[2]));
        let d2 = _mm256_fmadd_ps(dz, dz, _mm256_fmadd_ps(dy, dy, _mm256_mul_ps(dx, dx)));
        let nl = _mm256_fmadd_ps(
            ld(&g.n[2]),
            dz,
            _mm256_fmadd_ps(ld(&g.n[1]), dy, _mm256_mul_ps(ld(&g.n[0]), dx)),
        );
        let nl = _mm256_max_ps(nl, zero);
        // nl / (d2 sqrt(d2)), as `point_irradiance`: correctly rounded sqrt and division, the same bits
        // on every x86-64 CPU (an rsqrt estimate differs between vendors, and so would every fit).
        let v = _mm256_min_ps(
            _mm256_div_ps(nl, _mm256_mul_ps(d2, _mm256_sqrt_ps(d2))),
            big,
        );
        let ok = _mm256_cmp_ps::<_CMP_GT_OQ>(d2, tiny);
        _mm256_storeu_ps(e.as_mut_ptr().add(i), _mm256_and_ps(v, ok));
        i += 8;
    }
    irradiance_exact(g, s + full..r.end, light, &mut e[full..]);
}

/// The lane sums of `solve::environment_lane_sums` over whole runs of `SUM_LANES` (4) pixels, in f64, each
/// lane and each sum the scalar loop's operations in its order (so the same values); with `specular` false
/// the lobe's four sums (whose factor is 0) are left at 0.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) unsafe fn environment_lanes_avx2(
    col: &[f32],
    b: &[f32],
    v: &[f32],
    t: &[f32],
    sat: f32,
    specular: bool,
) -> [[f64; 4]; 9] {
    use std::arch::x86_64::*;
    let mut s = [_mm256_setzero_pd(); 9];
    let satv = _mm_set1_ps(sat);
    let n = col.len() - col.len() % 4;
    let mut i = 0;
    while i < n {
        let y = _mm_loadu_ps(t[i..i + 4].as_ptr());
        // Where t >= sat (or t = +inf) every value becomes 0, as the scalar select.
        let keep = _mm_cmplt_ps(y, satv);
        let a = _mm256_cvtps_pd(_mm_and_ps(_mm_loadu_ps(col[i..i + 4].as_ptr()), keep));
        let yv = _mm256_cvtps_pd(_mm_and_ps(y, keep));
        let vv = _mm256_cvtps_pd(_mm_and_ps(_mm_loadu_ps(v[i..i + 4].as_ptr()), keep));
        s[0] = _mm256_add_pd(s[0], _mm256_mul_pd(a, a));
        s[3] = _mm256_add_pd(s[3], _mm256_mul_pd(yv, a));
        s[5] = _mm256_add_pd(s[5], _mm256_mul_pd(a, vv));
        s[6] = _mm256_add_pd(s[6], _mm256_mul_pd(vv, vv));
        s[7] = _mm256_add_pd(s[7], _mm256_mul_pd(yv, vv));
        if specular {
            let bv = _mm256_cvtps_pd(_mm_and_ps(_mm_loadu_ps(b[i..i + 4].as_ptr()), keep));
            s[1] = _mm256_add_pd(s[1], _mm256_mul_pd(a, bv));
            s[2] = _mm256_add_pd(s[2], _mm256_mul_pd(bv, bv));
            s[4] = _mm256_add_pd(s[4], _mm256_mul_pd(yv, bv));
            s[8] = _mm256_add_pd(s[8], _mm256_mul_pd(vv, bv));
        }
        i += 4;
    }
    let mut out = [[0.0f64; 4]; 9];
    for (o, v) in out.iter_mut().zip(s) {
        _mm256_storeu_pd(o.as_mut_ptr(), v);
    }
    out
}

/// The lane sums of `projected::normal_equations` over whole runs of `LANES` pixels.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) unsafe fn normal_equation_lanes_avx2(
    e: &[f32],
    t: &[f32],
    sat: f32,
) -> ([f32; LANES], [f32; LANES]) {
    use std::arch::x86_64::*;
    let (mut a, mut b) = (_mm256_setzero_ps(), _mm256_setzero_ps());
    let satv = _mm256_set1_ps(sat);
    for (x, y) in e.chunks_exact(LANES).zip(t.chunks_exact(LANES)) {
        let (x, y) = (_mm256_loadu_ps(x.as_ptr()), _mm256_loadu_ps(y.as_ptr()));
        // Where t >= sat (or t = +inf) both factors become 0: the lane adds 0, as the scalar select.
        let keep = _mm256_cmp_ps::<_CMP_LT_OQ>(y, satv);
        let (x, y) = (_mm256_and_ps(x, keep), _mm256_and_ps(y, keep));
        a = _mm256_add_ps(a, _mm256_mul_ps(x, y));
        b = _mm256_add_ps(b, _mm256_mul_ps(x, x));
    }
    let (mut sa, mut sb) = ([0.0f32; LANES], [0.0f32; LANES]);
    _mm256_storeu_ps(sa.as_mut_ptr(), a);
    _mm256_storeu_ps(sb.as_mut_ptr(), b);
    (sa, sb)
}
