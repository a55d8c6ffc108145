//! What the vectorised kernels share: whether this CPU runs their AVX2 + FMA builds, the
//! multiply-add they are generic over, and a finiteness test that vectorises.

/// Values summed side by side by [`all_finite`].
const LANES: usize = 8;

/// `acc + c · x`, fused (one rounding) when the caller runs with FMA.
#[inline(always)]
pub fn madd<const FMA: bool>(c: f64, x: f64, acc: f64) -> f64 {
    if FMA {
        c.mul_add(x, acc)
    } else {
        acc + c * x
    }
}

/// Whether this CPU runs the AVX2 + FMA builds of the kernels.
pub fn avx2_fma() -> bool {
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "x86")))]
    {
        false
    }
}

/// Whether every value is finite: 0 · v is NaN for an infinite or NaN v, summed in [`LANES`] lanes
/// that vectorise (one running sum would wait for each addition, a fifth of a free run's time).
#[inline(always)]
pub fn all_finite(x: &[f64]) -> bool {
    let mut lanes = [0.0f64; LANES];
    let chunks = x.chunks_exact(LANES);
    let tail = chunks.remainder().iter().fold(0.0, |z, &v| z + 0.0 * v);
    for c in chunks {
        for l in 0..LANES {
            lanes[l] += 0.0 * c[l];
        }
    }
    lanes.iter().fold(tail, |z, &v| z + v) == 0.0
}
