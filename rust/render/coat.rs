//! The coated (plastic) material: a Lambertian base under a dielectric coat with a rough GGX interface,
//! the model of Mitsuba 3's `roughplastic` (isotropic GGX, `nonlinear` false):
//!
//! f(l, v) = k_s · F(v·h, η) D(h) G₁(v, h) G₁(l, h) / (4 cos_v cos_l)
//!         + ρ/π · T(cos_v) T(cos_l) / (η² (1 − R_i)),
//!
//! with T(μ) the coat's transmittance from outside at incidence cos μ (one minus what its rough interface
//! reflects, Smith masking on the way in included), R_i the base's light that the coat sends back in
//! (the internal rough reflectance's cosine-weighted mean), η the coat's relative index of refraction and
//! D, G₁ the GGX distribution and Smith's masking with roughness α. The diffuse factor is linear in ρ,
//! so the closed form's products stay linear.
//!
//! T is tabulated at 64 cosines (0, 1/63, ..., 1) and read by linear interpolation, and R_i is twice the
//! mean of R(μ)μ over the same 64 cosines, as Mitsuba defines them (that mean is about 1.5 % below the
//! integral 2∫R(μ)μ dμ, and Mitsuba's renders follow the mean). T and R are expectations over GGX's
//! visible normals, integrated by a Gauss–Legendre product rule over the visible-normal sample square,
//! 16 nodes in its radius and 8 in half its angle (the integrand is symmetric about the plane of
//! incidence). Mitsuba takes 32² from outside and 128² from inside: T is within 3e-4 of that, R_i within
//! 2.5e-3 (total internal reflection makes its integrand a step), 0.4 % of the diffuse term at most. A
//! coat's tables cost 2 × 64 × 128 samples, about a millisecond, so that a fit can try several
//! roughnesses. This is the only
//! place these formulas live: the renderer (`shade`) and the fitness (`fitness::projected`) call
//! [`Coat::diffuse`] and [`Coat::specular`].

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use glam::Vec3A;

/// Cosines in the transmittance table.
pub const TABLE: usize = 64;
/// The roughness range a coat accepts (GGX α).
pub const ALPHA_RANGE: (f64, f64) = (1e-3, 1.0);
/// The relative index of refraction a coat accepts (coat over the outside medium).
pub const IOR_RANGE: (f64, f64) = (1.01, 3.0);
/// The default relative index of refraction (polypropylene in air, Mitsuba's `roughplastic` default).
pub const DEFAULT_IOR: f64 = 1.49;

/// A coat of roughness `alpha` and relative IOR `eta`, with its tables (shared between clones).
#[derive(Clone, Debug)]
pub struct Coat {
    pub alpha: f32,
    pub eta: f32,
    tables: Arc<Tables>,
}

impl PartialEq for Coat {
    fn eq(&self, other: &Self) -> bool {
        self.alpha == other.alpha && self.eta == other.eta
    }
}

#[derive(Debug)]
struct Tables {
    /// T(μ_k), μ_k = k / 63 (at least 1e-6).
    transmittance: [f32; TABLE],
    /// 1 / (π η² (1 − R_i)): the diffuse factor's constant.
    diffuse_scale: f32,
    internal_reflectance: f64,
}

impl Coat {
    /// The coat of roughness `alpha` and relative IOR `eta` (the scene's checks keep both in range; out
    /// of range they are clamped into it). Tables are computed once per (α, η) and cached.
    pub fn new(alpha: f64, eta: f64) -> Coat {
        let alpha = (alpha as f32).clamp(ALPHA_RANGE.0 as f32, ALPHA_RANGE.1 as f32);
        let eta = (eta as f32).clamp(IOR_RANGE.0 as f32, IOR_RANGE.1 as f32);
        Coat {
            alpha,
            eta,
            tables: cached(alpha, eta),
        }
    }

    /// T(cos) by linear interpolation in the table (cos clamped to [0, 1]).
    #[inline(always)]
    pub fn transmittance(&self, cos: f32) -> f32 {
        let t = &self.tables.transmittance;
        let x = cos.clamp(0.0, 1.0) * (TABLE - 1) as f32;
        let i = (x as usize).min(TABLE - 2);
        let f = x - i as f32;
        t[i] + (t[i + 1] - t[i]) * f
    }

    /// The base's light that the coat reflects back inside, R_i.
    pub fn internal_reflectance(&self) -> f64 {
        self.tables.internal_reflectance
    }

    /// The diffuse part per unit albedo, T(cos_v) T(cos_l) / (π η² (1 − R_i)) (0 below either horizon):
    /// Lambert's 1/π under the coat.
    #[inline(always)]
    pub fn diffuse(&self, cos_l: f32, cos_v: f32) -> f32 {
        if cos_l <= 0.0 || cos_v <= 0.0 {
            return 0.0;
        }
        self.transmittance(cos_v) * self.transmittance(cos_l) * self.tables.diffuse_scale
    }

    /// The coat's specular lobe per unit weight, F(v·h) D(h) G₁(v,h) G₁(l,h) / (4 cos_v cos_l), for the
    /// unit normal `n` and unit directions to the light `l` and to the eye `v` (0 below either horizon).
    #[inline(always)]
    pub fn specular(&self, n: Vec3A, l: Vec3A, v: Vec3A) -> f32 {
        let (cl, cv) = (n.dot(l), n.dot(v));
        if cl <= 0.0 || cv <= 0.0 {
            return 0.0;
        }
        let h = (l + v).normalize_or_zero();
        let ch = n.dot(h);
        if ch <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        // GGX: D = 1 / (π α² (tan²θ/α² + 1)² cos⁴θ) = α² / (π (cos²θ (α² − 1) + 1)²)
        let ch2 = ch * ch;
        let den = ch2 * (a2 - 1.0) + 1.0;
        let d = a2 / (std::f32::consts::PI * den * den);
        let g1 = |c: f32, hc: f32| -> f32 {
            if hc <= 0.0 {
                return 0.0;
            }
            let t2 = (1.0 - c * c).max(0.0) / (c * c);
            2.0 / (1.0 + (1.0 + a2 * t2).sqrt())
        };
        let g = g1(cv, v.dot(h)) * g1(cl, l.dot(h));
        let f = fresnel(v.dot(h) as f64, self.eta as f64).0 as f32;
        let out = f * d * g / (4.0 * cv * cl);
        if out.is_finite() {
            out
        } else {
            0.0
        }
    }
}

fn cached(alpha: f32, eta: f32) -> Arc<Tables> {
    static CACHE: OnceLock<Mutex<HashMap<(u32, u32), Arc<Tables>>>> = OnceLock::new();
    let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
    let key = (alpha.to_bits(), eta.to_bits());
    if let Some(t) = cache.lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return t.clone();
    }
    let t = Arc::new(tables(alpha as f64, eta as f64));
    let mut c = cache.lock().unwrap_or_else(|e| e.into_inner());
    if c.len() >= 512 {
        c.clear();
    }
    c.entry(key).or_insert(t).clone()
}

fn tables(alpha: f64, eta: f64) -> Tables {
    let incident = |m: f64| [(1.0 - m * m).max(0.0).sqrt(), 0.0, m];
    let (radius, angle) = (gauss_legendre(16), gauss_legendre(8));
    let nodes = (&radius[..], &angle[..]);
    let mut transmittance = [0.0f32; TABLE];
    let mut ri = 0.0;
    for (k, t) in transmittance.iter_mut().enumerate() {
        let m = (k as f64 / (TABLE - 1) as f64).max(1e-6);
        *t = through(alpha, incident(m), eta, nodes, true) as f32;
        ri += through(alpha, incident(m), 1.0 / eta, nodes, false) * m;
    }
    let internal_reflectance = 2.0 * ri / TABLE as f64;
    let diffuse_scale =
        (1.0 / (std::f64::consts::PI * eta * eta * (1.0 - internal_reflectance))) as f32;
    Tables {
        transmittance,
        diffuse_scale,
        internal_reflectance,
    }
}

/// The expectation over GGX's visible normals m seen from `wi` (z up, in the xz-plane) of
/// (1 − F)·G₁(refracted, m) (`transmit`) or F·G₁(reflected, m): a product rule over the sample square, the
/// radius's `u1` on `n1` Gauss–Legendre nodes and the angle's `u2` on `n2` over half the circle (the
/// integrand is symmetric about the plane of `wi`: u2 → 1/2 − u2), doubled.
fn through(
    alpha: f64,
    wi: [f64; 3],
    eta: f64,
    (n1, n2): (&[(f64, f64)], &[(f64, f64)]),
    transmit: bool,
) -> f64 {
    let mut sum = 0.0;
    for &(x1, w1) in n1 {
        for &(x2, w2) in n2 {
            let m = sample_visible(alpha, wi, 0.5 * x1 + 0.5, 0.25 * x2);
            let c = dot(wi, m);
            let (f, cos_t) = fresnel(c, eta);
            let value = if transmit {
                // refraction: wo = m (c / η + cos_t) − wi / η, below the surface
                let inv = if c >= 0.0 { 1.0 / eta } else { eta };
                let wo = std::array::from_fn(|i| m[i] * (c * inv + cos_t) - wi[i] * inv);
                if wo[2] * wi[2] >= 0.0 {
                    0.0
                } else {
                    smith_g1(alpha, wo, m) * (1.0 - f)
                }
            } else {
                let wo = std::array::from_fn(|i| 2.0 * c * m[i] - wi[i]);
                if wo[2] <= 0.0 || wi[2] <= 0.0 {
                    0.0
                } else {
                    smith_g1(alpha, wo, m) * f
                }
            };
            // Jacobians 1/2 (u1) and 1/4 (u2), times 2 for the other half
            sum += value * w1 * w2 * 0.25;
        }
    }
    sum
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalize(v: [f64; 3]) -> [f64; 3] {
    let l = dot(v, v).sqrt();
    [v[0] / l, v[1] / l, v[2] / l]
}

/// Smith's GGX masking G₁ of direction `v` for the microfacet normal `m` (either side of the surface).
fn smith_g1(alpha: f64, v: [f64; 3], m: [f64; 3]) -> f64 {
    if dot(v, m) * v[2] <= 0.0 {
        return 0.0;
    }
    let xy = alpha * alpha * (v[0] * v[0] + v[1] * v[1]);
    if xy == 0.0 {
        return 1.0;
    }
    2.0 / (1.0 + (1.0 + xy / (v[2] * v[2])).sqrt())
}

/// A GGX visible normal for the direction `wi` (z up) at the sample (u1, u2) in [0, 1]² (Heitz 2018,
/// "Sampling the GGX distribution of visible normals").
fn sample_visible(alpha: f64, wi: [f64; 3], u1: f64, u2: f64) -> [f64; 3] {
    let vh = normalize([alpha * wi[0], alpha * wi[1], wi[2]]);
    let len2 = vh[0] * vh[0] + vh[1] * vh[1];
    let t1 = if len2 > 0.0 {
        let r = 1.0 / len2.sqrt();
        [-vh[1] * r, vh[0] * r, 0.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let t2 = [
        vh[1] * t1[2] - vh[2] * t1[1],
        vh[2] * t1[0] - vh[0] * t1[2],
        vh[0] * t1[1] - vh[1] * t1[0],
    ];
    let r = u1.sqrt();
    let phi = 2.0 * std::f64::consts::PI * u2;
    let p1 = r * phi.cos();
    let s = 0.5 * (1.0 + vh[2]);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
    let p3 = (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
    let nh: [f64; 3] = std::array::from_fn(|i| p1 * t1[i] + p2 * t2[i] + p3 * vh[i]);
    normalize([alpha * nh[0], alpha * nh[1], nh[2].max(0.0)])
}

/// The unpolarised Fresnel reflectance of a dielectric interface of relative IOR `eta` (inside over
/// outside) at the cosine `cos_i` (negative: from inside), and the signed cosine of the refracted
/// direction (0 under total internal reflection).
pub fn fresnel(cos_i: f64, eta: f64) -> (f64, f64) {
    let outside = cos_i >= 0.0;
    let (eta_it, eta_ti) = if outside {
        (eta, 1.0 / eta)
    } else {
        (1.0 / eta, eta)
    };
    let cos_t2 = 1.0 - eta_ti * eta_ti * (1.0 - cos_i * cos_i);
    let ci = cos_i.abs();
    let ct = cos_t2.max(0.0).sqrt();
    let a_s = (ci - eta_it * ct) / (ci + eta_it * ct);
    let a_p = (eta_it * ci - ct) / (eta_it * ci + ct);
    let mut r = 0.5 * (a_s * a_s + a_p * a_p);
    if ci == 0.0 || cos_t2 <= 0.0 {
        r = 1.0;
    }
    let cos_t = if outside { -ct } else { ct };
    (r, cos_t)
}

/// Gauss–Legendre nodes and weights on [−1, 1] (Newton's iteration on the Legendre polynomial).
fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|i| {
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                    p0 = p1;
                    p1 = p2;
                }
                dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let dx = p1 / dp;
                x -= dx;
                if dx.abs() < 1e-15 {
                    break;
                }
            }
            (x, 2.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        let q = gauss_legendre(32);
        let w: f64 = q.iter().map(|p| p.1).sum();
        assert!((w - 2.0).abs() < 1e-13);
        let x6: f64 = q.iter().map(|p| p.1 * p.0.powi(6)).sum();
        assert!((x6 - 2.0 / 7.0).abs() < 1e-13);
    }

    #[test]
    fn fresnel_at_normal_incidence_and_total_internal_reflection() {
        let eta: f64 = 1.5;
        let r0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
        assert!((fresnel(1.0, eta).0 - r0).abs() < 1e-12);
        assert!((fresnel(-1.0, eta).0 - r0).abs() < 1e-12);
        // from inside beyond the critical angle (sin > 1/1.5)
        assert_eq!(fresnel(-0.5, eta).0, 1.0);
        assert_eq!(fresnel(0.5, 1.0 / eta).0, 1.0);
    }

    #[test]
    fn a_smooth_coat_transmits_one_minus_fresnel() {
        // α → 0: every visible normal is the surface's; T(μ) = 1 − F(μ) and the masking is 1.
        let c = Coat::new(1e-3, 1.5);
        for mu in [0.2f32, 0.5, 0.8, 1.0] {
            let want = 1.0 - fresnel(mu as f64, 1.5).0;
            assert!(
                (c.transmittance(mu) as f64 - want).abs() < 2e-3,
                "mu {mu}: {} against {want}",
                c.transmittance(mu)
            );
        }
        // R_i of a smooth interface: twice the mean of R(μ)μ from inside over the 64 table cosines, with
        // R the smooth Fresnel reflectance from inside (total beyond the critical angle)
        let want: f64 = (0..TABLE)
            .map(|k| {
                let m = (k as f64 / (TABLE - 1) as f64).max(1e-6);
                2.0 * fresnel(-m, 1.5).0 * m / TABLE as f64
            })
            .sum();
        let ri = c.internal_reflectance();
        assert!((ri - want).abs() < 0.005, "{ri} against {want}");
    }

    #[test]
    fn specular_lobe_integrates_to_its_directional_albedo() {
        // ∫ f_s cos_l dω over the hemisphere is what the rough interface reflects: the visible normals'
        // expectation of F·G₁(reflected), checked at α = 0.3 by a midpoint rule over the hemisphere.
        let c = Coat::new(0.3, 1.5);
        let n = Vec3A::Z;
        for mu in [0.4f32, 0.9] {
            let v = Vec3A::new((1.0 - mu * mu).sqrt(), 0.0, mu);
            let (nt, np) = (400, 800);
            let mut sum = 0.0f64;
            for i in 0..nt {
                let th = (i as f64 + 0.5) / nt as f64 * std::f64::consts::FRAC_PI_2;
                for j in 0..np {
                    let ph = (j as f64 + 0.5) / np as f64 * 2.0 * std::f64::consts::PI;
                    let l = Vec3A::new(
                        (th.sin() * ph.cos()) as f32,
                        (th.sin() * ph.sin()) as f32,
                        th.cos() as f32,
                    );
                    let dw = th.sin()
                        * (std::f64::consts::FRAC_PI_2 / nt as f64)
                        * (2.0 * std::f64::consts::PI / np as f64);
                    sum += c.specular(n, l, v) as f64 * th.cos() * dw;
                }
            }
            let wi = [v.x as f64, v.y as f64, v.z as f64];
            let q = gauss_legendre(64);
            let want = through(0.3, wi, 1.5, (&q, &q), false);
            assert!((sum - want).abs() < 0.01, "mu {mu}: {sum} against {want}");
        }
    }

    #[test]
    fn no_light_below_the_horizon() {
        let c = Coat::new(0.1, 1.49);
        let n = Vec3A::Y;
        assert_eq!(c.specular(n, -n, n), 0.0);
        assert_eq!(c.diffuse(-0.1, 0.5), 0.0);
        assert!(c.diffuse(1.0, 1.0) > 0.0);
    }
}
