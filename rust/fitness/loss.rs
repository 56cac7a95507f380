//! The loss: how a pixel's difference is penalised (`Norm`), in which space values are compared
//! (`Space`, the sRGB table `SrgbLut`, the compile-time `Encoding`), and the kernels' vectorised sums.
//!
//! sRGB weighs an error as an 8-bit photo quantises it. The kernels encode through a table (error below
//! 2e-5); the objective goes through the same table, so a model equal to it costs exactly 0.

use std::sync::LazyLock;

use glam::Vec3A;

use crate::render::film::srgb_encode_exact;

/// How a pixel's difference d = model - objective is penalised. `L1` is the paper's; `L2` is the maximum
/// likelihood under Gaussian noise; `Huber(h)` is quadratic within `h` and linear beyond (d²/(2h), then
/// |d| - h/2), robust to a few pixels the scene does not model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Norm {
    L1,
    L2,
    Huber(f32),
}

impl Norm {
    /// "l1", "l2", "huber" (h = 0.02) or "huber:H".
    pub fn parse(s: &str) -> Result<Norm, String> {
        match s {
            "l1" => Ok(Norm::L1),
            "l2" => Ok(Norm::L2),
            "huber" => Ok(Norm::Huber(0.02)),
            _ => match s.strip_prefix("huber:").map(str::parse::<f32>) {
                Some(Ok(h)) if h > 0.0 && h.is_finite() => Ok(Norm::Huber(h)),
                _ => Err(format!(
                    "unknown norm {s:?} (known: \"l1\", \"l2\", \"huber\", \"huber:H\" with H > 0)"
                )),
            },
        }
    }

    #[inline(always)]
    pub fn penalty(self, d: f32) -> f32 {
        match self {
            Norm::L1 => d.abs(),
            Norm::L2 => d * d,
            Norm::Huber(h) => {
                let a = d.abs();
                if a <= h {
                    0.5 * d * d / h
                } else {
                    a - 0.5 * h
                }
            }
        }
    }

    /// The derivative of `penalty` (a subgradient for L1: 0 at 0).
    #[inline(always)]
    pub fn slope(self, d: f64) -> f64 {
        match self {
            Norm::L1 => {
                if d > 0.0 {
                    1.0
                } else if d < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            }
            Norm::L2 => 2.0 * d,
            Norm::Huber(h) => (d / h as f64).clamp(-1.0, 1.0),
        }
    }
}

/// Objective values at or above this are saturated: they only say "at least this bright".
pub const SATURATED: f32 = 0.999;

/// Where pixel differences are penalised.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Space {
    /// Linear radiance, as rendered (the default).
    #[default]
    Linear,
    /// sRGB code values (IEC 61966-2-1) of the (clipped) model and of the objective.
    Srgb,
}

impl Space {
    /// "linear" or "srgb".
    pub fn parse(s: &str) -> Result<Space, String> {
        match s {
            "linear" => Ok(Space::Linear),
            "srgb" => Ok(Space::Srgb),
            _ => Err(format!(
                "space: unknown loss space {s:?} (known: \"linear\", \"srgb\")"
            )),
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Space::Linear => "linear",
            Space::Srgb => "srgb",
        }
    }
}

/// Table intervals over [0, 1]: a power of two, so `i & (SRGB_LUT_SIZE - 1)` is in bounds without a check.
/// 4096 intervals keep the interpolation error below 2e-5 (largest just above the 0.0031308 kink, where
/// x^(1/2.4) bends most) in 32 KiB.
pub const SRGB_LUT_SIZE: usize = 4096;

/// The sRGB encoding by linear interpolation in a table: per interval its start value and slope, side
/// by side so that one lookup touches one cache line.
pub struct SrgbLut {
    table: [[f32; 2]; SRGB_LUT_SIZE],
}

static SRGB_LUT: LazyLock<Box<SrgbLut>> = LazyLock::new(|| {
    let n = SRGB_LUT_SIZE;
    let node = |i: usize| srgb_encode_exact(i as f64 / n as f64);
    let mut t = Box::new(SrgbLut {
        table: [[0.0; 2]; SRGB_LUT_SIZE],
    });
    for (i, entry) in t.table.iter_mut().enumerate() {
        let (v0, v1) = (node(i), node(i + 1));
        *entry = [v0 as f32, (v1 - v0) as f32];
    }
    t
});

impl SrgbLut {
    /// The shared table (built on first use).
    #[inline]
    pub fn get() -> &'static SrgbLut {
        &SRGB_LUT
    }

    /// enc(x) for x <= 1 (the clipped model): branch-free, so loops over it vectorise (with gathers).
    /// Below 0 the first interval extends linearly, which is the exact 12.92 x.
    #[inline(always)]
    pub fn encode_unit(&self, x: f32) -> f32 {
        const N: f32 = SRGB_LUT_SIZE as f32;
        let u = x * N;
        // max/min return the non-NaN operand, so `c` is finite and in [0, N - 1] (`clamp` would keep a NaN).
        #[allow(clippy::manual_clamp)]
        let c = u.max(0.0).min(N - 1.0);
        // SAFETY: `c` is finite and within i32's range (see above).
        let i = unsafe { c.to_int_unchecked::<i32>() } as usize & (SRGB_LUT_SIZE - 1);
        let [value, slope] = self.table[i];
        value + (u - i as f32) * slope
    }

    /// enc(x) and its right derivative (the table's slope up to 1, the formula's above).
    #[inline]
    pub fn encode_slope(&self, x: f32) -> (f32, f32) {
        const N: f32 = SRGB_LUT_SIZE as f32;
        if x <= 1.0 {
            let u = x * N;
            #[allow(clippy::manual_clamp)]
            let c = u.max(0.0).min(N - 1.0);
            // SAFETY: as in `encode_unit`.
            let i = unsafe { c.to_int_unchecked::<i32>() } as usize & (SRGB_LUT_SIZE - 1);
            let [value, slope] = self.table[i];
            (value + (u - i as f32) * slope, slope * N)
        } else {
            let x = x as f64;
            let d = 1.055 / 2.4 * x.powf(1.0 / 2.4 - 1.0);
            (srgb_encode_exact(x) as f32, d as f32)
        }
    }

    /// enc(x) for any x: the table up to 1, the formula above (an unclipped model).
    #[inline(always)]
    pub fn encode(&self, x: f32) -> f32 {
        if x <= 1.0 {
            self.encode_unit(x)
        } else {
            srgb_encode_exact(x as f64) as f32
        }
    }
}

/// How the kernels encode a model value before the penalty, chosen at compile time so that the linear
/// space's loops are exactly what they were without this option: [`Identity`] compiles away, `&SrgbLut`
/// encodes.
pub trait Encoding: Copy {
    /// False for [`Identity`]: the objective is used as it is.
    const ENCODES: bool;
    /// enc(x) for x <= 1 (a clipped model).
    fn unit(self, x: f32) -> f32;
    /// enc(x) for any x.
    fn any(self, x: f32) -> f32;
}

/// The linear space: values are compared as they are.
#[derive(Clone, Copy)]
pub struct Identity;

impl Encoding for Identity {
    const ENCODES: bool = false;
    #[inline(always)]
    fn unit(self, x: f32) -> f32 {
        x
    }
    #[inline(always)]
    fn any(self, x: f32) -> f32 {
        x
    }
}

impl Encoding for &SrgbLut {
    const ENCODES: bool = true;
    #[inline(always)]
    fn unit(self, x: f32) -> f32 {
        self.encode_unit(x)
    }
    #[inline(always)]
    fn any(self, x: f32) -> f32 {
        self.encode(x)
    }
}

/// Lanes of the explicit partial sums: float addition is not associative, so the compiler will not
/// vectorise a plain running sum; eight independent accumulators let it (and fix the summation order, so
/// results stay bit-reproducible).
pub(crate) const LANES: usize = 8;

/// Σ penalty(enc(min(a_c + e·k_c, top)) - t_c) for the three channels, `t` already encoded (the linear
/// space's [`Identity`] compiles the encoding away), one loop per norm so each vectorises.
#[inline(always)]
pub(crate) fn rgb_loss_in<E: Encoding>(
    norm: Norm,
    e: &[f32],
    t: [&[f32]; 3],
    a: [f32; 3],
    k: [f32; 3],
    top: f32,
    enc: E,
) -> [f32; 3] {
    let terms = Terms {
        e,
        t,
        a,
        k,
        top,
        enc,
    };
    match norm {
        // One closure per norm with the norm a constant, so each loop vectorises on its own.
        Norm::L1 => terms.sum(|d| Norm::L1.penalty(d)),
        Norm::L2 => terms.sum(|d| Norm::L2.penalty(d)),
        Norm::Huber(h) => terms.sum(move |d| Norm::Huber(h).penalty(d)),
    }
}

/// The model terms enc(min(a_c + e·k_c, top)) of a run of pixels against the encoded objective `t`.
#[derive(Clone, Copy)]
struct Terms<'a, E> {
    e: &'a [f32],
    t: [&'a [f32]; 3],
    a: [f32; 3],
    k: [f32; 3],
    top: f32,
    enc: E,
}

impl<E: Encoding> Terms<'_, E> {
    /// Σ f(enc(min(a_c + e·k_c, top)) - t_c) for the three channels in one pass over `e`, in `LANES` partial
    /// sums (the table lookups are scalar; the rest vectorises). An encoding without a clip (`top` > 1)
    /// sends every value through [`Encoding::any`], which branches above 1.
    #[inline(always)]
    fn sum(self, f: impl Fn(f32) -> f32) -> [f32; 3] {
        let Terms {
            e,
            t,
            a,
            k,
            top,
            enc,
        } = self;
        let n = e.len();
        let (t0, t1, t2) = (&t[0][..n], &t[1][..n], &t[2][..n]);
        let (mut s0, mut s1, mut s2) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
        let full = if !E::ENCODES || top <= 1.0 {
            n - n % LANES
        } else {
            0
        };
        let mut i = 0;
        while i < full {
            let (ec, c0, c1, c2) = (
                &e[i..i + LANES],
                &t0[i..i + LANES],
                &t1[i..i + LANES],
                &t2[i..i + LANES],
            );
            for j in 0..LANES {
                let ej = ec[j];
                s0[j] += f(enc.unit((a[0] + ej * k[0]).min(top)) - c0[j]);
                s1[j] += f(enc.unit((a[1] + ej * k[1]).min(top)) - c1[j]);
                s2[j] += f(enc.unit((a[2] + ej * k[2]).min(top)) - c2[j]);
            }
            i += LANES;
        }
        if E::ENCODES {
            for (j, s) in (full..n).enumerate() {
                let (es, l) = (e[s], j % LANES);
                s0[l] += f(enc.any((a[0] + es * k[0]).min(top)) - t0[s]);
                s1[l] += f(enc.any((a[1] + es * k[1]).min(top)) - t1[s]);
                s2[l] += f(enc.any((a[2] + es * k[2]).min(top)) - t2[s]);
            }
        } else {
            // Linear: fewer than LANES left, one to a lane (the loop the compiler unrolls best).
            for j in 0..n - full {
                let ej = e[full + j];
                s0[j] += f((a[0] + ej * k[0]).min(top) - t0[full + j]);
                s1[j] += f((a[1] + ej * k[1]).min(top) - t1[full + j]);
                s2[j] += f((a[2] + ej * k[2]).min(top) - t2[full + j]);
            }
        }
        [s0.iter().sum(), s1.iter().sum(), s2.iter().sum()]
    }
}

/// Per-channel sums of `norm`'s penalty over fixed (model, objective) pairs, compared in `space` with
/// the kernel's encoding.
pub(crate) fn penalty_sums(fixed: &[(Vec3A, Vec3A)], norm: Norm, space: Space) -> [f64; 3] {
    let mut acc = [0.0f64; 3];
    for &(m, t) in fixed {
        let d = match space {
            Space::Linear => m - t,
            Space::Srgb => {
                let lut = SrgbLut::get();
                Vec3A::from_array(std::array::from_fn(|c| lut.encode(m[c]) - lut.encode(t[c])))
            }
        };
        for c in 0..3 {
            acc[c] += norm.penalty(d[c]) as f64;
        }
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::film::srgb_encode_exact;

    #[test]
    fn table_matches_the_formula_everywhere() {
        let lut = SrgbLut::get();
        let kink = 0.003_130_8f64;
        let mut worst: f64 = 0.0;
        // Dense everywhere, denser around the kink, and every table node and midpoint.
        let mut xs: Vec<f64> = (0..=2_000_000).map(|i| i as f64 / 2e6).collect();
        xs.extend((0..=200_000).map(|i| kink * (0.9 + 0.2 * i as f64 / 2e5)));
        xs.extend((0..=2 * SRGB_LUT_SIZE).map(|i| i as f64 / (2 * SRGB_LUT_SIZE) as f64));
        for x in xs {
            let x32 = x as f32;
            let err = (lut.encode_unit(x32) as f64 - srgb_encode_exact(x32 as f64)).abs();
            worst = worst.max(err);
        }
        assert!(worst < 2e-5, "worst {worst}");
        // Ends, negatives (linear segment), above 1 (formula), monotone.
        assert_eq!(lut.encode_unit(0.0), 0.0);
        assert!((lut.encode_unit(1.0) - 1.0).abs() < 1e-6);
        assert!((lut.encode_unit(-0.01) + 0.1292).abs() < 1e-6);
        assert!((lut.encode(4.0) as f64 - srgb_encode_exact(4.0)).abs() < 1e-6);
        assert!(lut.encode_unit(f32::NAN).is_nan());
        let mut prev = f32::NEG_INFINITY;
        for i in 0..=100_000 {
            let v = lut.encode(i as f32 / 50_000.0);
            assert!(v >= prev);
            prev = v;
        }
    }
}
