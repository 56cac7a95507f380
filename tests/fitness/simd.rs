//! The scalar and AVX2 paths.

use super::*;

/// The scalar paths (`rtloop::fitness::scalar_paths`, as `RTLOOP_SIMD=scalar` forces everywhere) against
/// the AVX2 ones this CPU picks: direct and closed-form losses, linear and sRGB, every norm. They differ
/// only in the intrinsics loops (fused multiply-adds in the dot products and the normal equations), so
/// the sums over ~7000 pixels agree to 1e-5 relative;
/// the shadow tests and everything else compile to the same arithmetic (Rust never contracts to FMA).
#[test]
fn scalar_and_avx2_paths_agree() {
    use rtloop::fitness::{scalar_paths, simd_path};
    use rtloop::{Norm, Space};
    let cpu_avx2 = std::env::var("RTLOOP_SIMD").map_or(true, |v| v != "scalar")
        && cfg!(target_arch = "x86_64")
        && is_avx2_fma();
    assert_eq!(simd_path(), if cpu_avx2 { "avx2" } else { "scalar" });
    assert_eq!(scalar_paths(simd_path), "scalar");
    assert_eq!(simd_path(), if cpu_avx2 { "avx2" } else { "scalar" });
    let mut rng = Rng::new(16);
    let (mut cases, mut identical) = (0, 0);
    for trial in 0..6 {
        // The matte closed form refuses a specular term and ambient light: those trials are direct only.
        let (specular, ambient) = (trial % 2 == 1, trial == 2);
        let scene = random_scene(&mut rng, 1 + trial % 3, specular, ambient);
        let target = clipped_render(&scene);
        let layout = ParamLayout::all(&scene);
        let direct = fitness(&scene, &layout, &target, LossKind::L1PerChannel, true);
        let light = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
        let mut fits = vec![(direct, &layout)];
        if !specular && !ambient {
            let solved = matte_projected(&scene, light.clone(), &target, true);
            fits.push((solved, &light));
        }
        for (mut f, layout) in fits {
            for space in [Space::Linear, Space::Srgb] {
                for norm in [Norm::L1, Norm::L2, Norm::Huber(0.01)] {
                    f.set_space(space);
                    f.set_norm(norm);
                    for _ in 0..2 {
                        let x = random_candidate(&mut rng, layout);
                        let fast = f.channel_losses(&x);
                        let slow = scalar_paths(|| f.channel_losses(&x));
                        for c in 0..3 {
                            assert!(
                                close(fast[c], slow[c], 1e-5),
                                "trial {trial} {space:?} {norm:?}: {fast:?} vs {slow:?}"
                            );
                        }
                        identical += usize::from(fast == slow);
                        cases += 1;
                    }
                }
            }
        }
    }
    assert_eq!(cases, (6 + 2) * 2 * 3 * 2);
    eprintln!(
        "scalar vs {}: {identical} of {cases} bit for bit",
        simd_path()
    );
}

pub(crate) fn is_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
