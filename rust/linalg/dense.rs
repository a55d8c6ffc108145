//! Small dense matrices (row-major): products, solves by Gaussian elimination, the
//! matrix exponential by Padé-13 scaling and squaring (Higham 2005), and the product that steps a
//! bank of small filters sample by sample.

/// `a · b` of row-major `n × n` matrices.
pub fn matmul(a: &[f64], b: &[f64], n: usize) -> Vec<f64> {
    let mut out = vec![0.0; n * n];
    for i in 0..n {
        for k in 0..n {
            let aik = a[i * n + k];
            for j in 0..n {
                out[i * n + j] += aik * b[k * n + j];
            }
        }
    }
    out
}

/// Solves `a x = b` (`a` n × n, `b` n × r, row-major) by LU with partial pivoting; None when a
/// pivot vanishes.
pub fn solve(mut a: Vec<f64>, mut b: Vec<f64>, n: usize, r: usize) -> Option<Vec<f64>> {
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| a[i * n + c].abs().total_cmp(&a[j * n + c].abs()))?;
        if a[p * n + c] == 0.0 || !a[p * n + c].is_finite() {
            return None;
        }
        if p != c {
            for j in 0..n {
                a.swap(p * n + j, c * n + j);
            }
            for j in 0..r {
                b.swap(p * r + j, c * r + j);
            }
        }
        let piv = a[c * n + c];
        for i in c + 1..n {
            let f = a[i * n + c] / piv;
            if f == 0.0 {
                continue;
            }
            for j in c..n {
                a[i * n + j] -= f * a[c * n + j];
            }
            for j in 0..r {
                b[i * r + j] -= f * b[c * r + j];
            }
        }
    }
    for c in (0..n).rev() {
        for j in 0..r {
            let mut s = b[c * r + j];
            for k in c + 1..n {
                s -= a[c * n + k] * b[k * r + j];
            }
            b[c * r + j] = s / a[c * n + c];
        }
    }
    Some(b)
}

/// Padé-13 coefficients of the matrix exponential (Higham 2005).
const PADE13: [f64; 14] = [
    64764752532480000.0,
    32382376266240000.0,
    7771770303897600.0,
    1187353796428800.0,
    129060195264000.0,
    10559470521600.0,
    670442572800.0,
    33522128640.0,
    1323241920.0,
    40840800.0,
    960960.0,
    16380.0,
    182.0,
    1.0,
];
const THETA13: f64 = 5.371920351148152;

/// `e^a` of a row-major `n × n` matrix by scaling and squaring with the degree-13 Padé
/// approximant (Higham, "The scaling and squaring method for the matrix exponential revisited",
/// SIAM J. Matrix Anal. Appl. 26(4), 2005); None for a non-finite matrix.
pub fn expm(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let norm = (0..n).map(|j| (0..n).map(|i| a[i * n + j].abs()).sum::<f64>()).fold(0.0, f64::max);
    if !norm.is_finite() {
        return None;
    }
    let s = if norm > THETA13 { (norm / THETA13).log2().ceil() as i32 } else { 0 };
    let scale = 0.5f64.powi(s);
    let a: Vec<f64> = a.iter().map(|v| v * scale).collect();
    let a2 = matmul(&a, &a, n);
    let a4 = matmul(&a2, &a2, n);
    let a6 = matmul(&a4, &a2, n);
    let b = &PADE13;
    let eye = |i: usize| if i.is_multiple_of(n + 1) { 1.0 } else { 0.0 };
    let inner_u: Vec<f64> = (0..n * n).map(|i| b[13] * a6[i] + b[11] * a4[i] + b[9] * a2[i]).collect();
    let mut u_arg = matmul(&a6, &inner_u, n);
    for (i, v) in u_arg.iter_mut().enumerate() {
        *v += b[7] * a6[i] + b[5] * a4[i] + b[3] * a2[i] + b[1] * eye(i);
    }
    let u = matmul(&a, &u_arg, n);
    let inner_v: Vec<f64> = (0..n * n).map(|i| b[12] * a6[i] + b[10] * a4[i] + b[8] * a2[i]).collect();
    let mut v = matmul(&a6, &inner_v, n);
    for (i, x) in v.iter_mut().enumerate() {
        *x += b[6] * a6[i] + b[4] * a4[i] + b[2] * a2[i] + b[0] * eye(i);
    }
    let lhs: Vec<f64> = (0..n * n).map(|i| v[i] - u[i]).collect();
    let rhs: Vec<f64> = (0..n * n).map(|i| v[i] + u[i]).collect();
    let mut e = solve(lhs, rhs, n, n)?;
    for _ in 0..s {
        e = matmul(&e, &e, n);
    }
    Some(e)
}

/// `out = m · s` over the columns `from..` of `w`-wide rows (`m` row-major r × n, `s` row-major
/// n × w, `out` r × w; its columns before `from` are set to zero): r·n contiguous axpys, in AVX2
/// vectors where the CPU has them (the same sums in the same order, so the same bits).
pub fn rows_product(m: &[f64], s: &[f64], n: usize, from: usize, out: &mut [f64]) {
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    if crate::linalg::simd::avx2_fma() {
        // SAFETY: the CPU supports the features the function is compiled for.
        return unsafe { rows_product_avx2(m, s, n, from, out) };
    }
    rows_product_impl(m, s, n, from, out);
}

#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn rows_product_avx2(m: &[f64], s: &[f64], n: usize, from: usize, out: &mut [f64]) {
    rows_product_impl(m, s, n, from, out);
}

/// Loops, not closures: a closure is compiled without the caller's target features. Each output
/// holds [`LANES`] sums in a register across the n products (`0 + m₀s₀ + m₁s₁ + …`, the order of n
/// axpys, so the same bits), where axpys would load and store the output row n times.
#[inline(always)]
fn rows_product_impl(m: &[f64], s: &[f64], n: usize, from: usize, out: &mut [f64]) {
    let w = s.len() / n.max(1);
    for (weights, target) in m.chunks_exact(n).zip(out.chunks_exact_mut(w)) {
        target[..from.min(w)].fill(0.0);
        let mut c = from;
        while c + LANES <= w {
            let mut acc = [0.0; LANES];
            for (k, &weight) in weights.iter().enumerate() {
                let row = &s[k * w + c..k * w + c + LANES];
                for l in 0..LANES {
                    acc[l] += weight * row[l];
                }
            }
            target[c..c + LANES].copy_from_slice(&acc);
            c += LANES;
        }
        for (c, v) in target.iter_mut().enumerate().skip(c) {
            let mut acc = 0.0;
            for (k, &weight) in weights.iter().enumerate() {
                acc += weight * s[k * w + c];
            }
            *v = acc;
        }
    }
}

/// Sums a register holds in [`rows_product`] (one AVX2 vector).
const LANES: usize = 4;

#[cfg(test)]
mod tests {
    use super::*;

    /// The product equals the n axpys it replaces, to the bit, for widths with and without a tail
    /// and any first column.
    #[test]
    fn rows_product_equals_the_axpys_to_the_bit() {
        let (r, n) = (3, 5);
        let m: Vec<f64> = (0..r * n).map(|i| ((i * 37) % 11) as f64 / 7.0 - 0.6).collect();
        for (w, from) in [(12, 0), (13, 3), (3, 1), (8, 8)] {
            let s: Vec<f64> = (0..n * w).map(|i| ((i * 53) % 17) as f64 / 3.0 - 2.1).collect();
            let mut want = vec![0.0; r * w];
            for i in 0..r {
                for k in 0..n {
                    for c in from..w {
                        want[i * w + c] += m[i * n + k] * s[k * w + c];
                    }
                }
            }
            let mut got = vec![f64::NAN; r * w];
            rows_product(&m, &s, n, from, &mut got);
            assert_eq!(got, want, "w {w} from {from}");
        }
    }

    #[test]
    fn expm_of_a_rotation_and_a_large_matrix() {
        // exp([[0, -w], [w, 0]]) = rotation by w.
        let w = 7.3;
        let e = expm(&[0.0, -w, w, 0.0], 2).unwrap();
        let exact = [w.cos(), -w.sin(), w.sin(), w.cos()];
        for (a, b) in e.iter().zip(exact) {
            assert!((a - b).abs() < 1e-13, "{a} vs {b}");
        }
        // Diagonal with a large entry (scaling and squaring).
        let e = expm(&[-40.0, 0.0, 0.0, 0.5], 2).unwrap();
        assert!((e[0] - (-40.0f64).exp()).abs() < 1e-25 && (e[3] - 0.5f64.exp()).abs() < 1e-14);
    }
}
