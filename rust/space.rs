//! The space in which pixel values are compared: linear radiance (the default) or sRGB code values.
//!
//! An 8-bit photo quantises (and JPEG compresses) uniformly in sRGB code values, not in radiance: one
//! code step is 0.0003 of linear range in the shadows and 0.009 in the highlights. Comparing in sRGB
//! weighs a pixel's error as the file (and the eye) resolve it. The loss is then
//! penalty(enc(min(model, 1)) - enc(objective)) with enc the IEC 61966-2-1 encoding, also above 1 when the
//! model is not clipped.
//!
//! The kernels encode every model value of every candidate, so the encoding must be cheap: [`SrgbLut`]
//! interpolates a table of `SRGB_LUT_SIZE` + 1 exact values over [0, 1] linearly (error below 2e-5
//! absolute, tested against [`srgb_encode_exact`]); the objective goes through the same function, once
//! per fit, so a model equal to the objective costs exactly 0 and the breakpoints of the refine's line
//! searches stay where the model equals the objective. Measured on an AMD EPYC (Zen 3), the scalar
//! lookup costs about 1 ns per value; AVX2 gathers of the same table were slower (1.15 ns), and a
//! vectorised polynomial pow (m^(5/12) per octave times a polynomial 2^(5e/12), error 2e-6) no faster
//! in the kernel, and not monotone at the last bit.

use std::sync::LazyLock;

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

/// The sRGB encoding of IEC 61966-2-1: 12.92 x for x <= 0.0031308, else 1.055 x^(1/2.4) - 0.055 (the same
/// formula above 1 and, linearly, below 0).
pub fn srgb_encode_exact(x: f64) -> f64 {
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
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

#[cfg(test)]
mod tests {
    use super::*;

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
