//! The field's text–motion metrics on evaluator embeddings: R-precision (Guo et al. 2022) and
//! the Fréchet distance of two sets of embeddings (FID).

use candle_core::{DType, Result, Tensor};
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::SeedableRng;

/// R-precision at `ks` with pools of `pool` texts: for each motion `i` (rows of unit `motion`
/// `[n, e]`), its own text (row `i` of unit `text`) and `pool − 1` others drawn at random
/// (seeded) are ranked by Euclidean distance to the motion; the share of motions whose own text
/// is among the `k` nearest, for each `k`. Needs `n ≥ pool`.
pub fn r_precision(motion: &Tensor, text: &Tensor, pool: usize, ks: &[usize], seed: u64) -> Result<Vec<f64>> {
    let n = motion.dim(0)?;
    if n < pool || pool == 0 {
        candle_core::bail!("R-precision needs at least {pool} motion–text pairs, got {n}");
    }
    // Unit rows: distance order is the reverse of the dot product's.
    let similarity: Vec<Vec<f32>> = motion.matmul(&text.t()?)?.to_vec2()?;
    let mut rng = StdRng::seed_from_u64(seed);
    let mut hits = vec![0usize; ks.len()];
    let others: Vec<usize> = (0..n).collect();
    for (i, row) in similarity.iter().enumerate() {
        let mut candidates: Vec<usize> = others.iter().copied().filter(|&j| j != i).collect();
        candidates.shuffle(&mut rng);
        let own = row[i];
        let better = candidates.iter().take(pool - 1).filter(|&&j| row[j] > own).count();
        for (h, &k) in hits.iter_mut().zip(ks) {
            if better < k {
                *h += 1;
            }
        }
    }
    Ok(hits.into_iter().map(|h| h as f64 / n as f64).collect())
}

/// Fréchet distance between Gaussians fitted to two sets of embeddings `[n, e]` and `[m, e]`:
/// `‖μa − μb‖² + Tr(Σa + Σb − 2 (Σa^½ Σb Σa^½)^½)` (the FID of Heusel et al. 2017 on our
/// evaluator's space). Needs at least 2 rows in each set.
pub fn frechet_distance(a: &Tensor, b: &Tensor) -> Result<f64> {
    let (mean_a, cov_a) = moments(a)?;
    let (mean_b, cov_b) = moments(b)?;
    let e = mean_a.len();
    let shift: f64 = mean_a.iter().zip(&mean_b).map(|(x, y)| (x - y).powi(2)).sum();
    let root_a = symmetric_function(&cov_a, e, |l| l.max(0.0).sqrt());
    let inner = multiply(&multiply(&root_a, &cov_b, e), &root_a, e);
    let (values, _) = jacobi_eigen(&inner, e);
    let trace_root: f64 = values.iter().map(|l| l.max(0.0).sqrt()).sum();
    let trace = |m: &[f64]| (0..e).map(|i| m[i * e + i]).sum::<f64>();
    Ok((shift + trace(&cov_a) + trace(&cov_b) - 2.0 * trace_root).max(0.0))
}

/// Mean `[e]` and covariance `[e·e]` (row-major, divided by n − 1) of rows `[n, e]`.
fn moments(x: &Tensor) -> Result<(Vec<f64>, Vec<f64>)> {
    let rows: Vec<Vec<f64>> = x.to_dtype(DType::F64)?.to_vec2()?;
    let n = rows.len();
    if n < 2 {
        candle_core::bail!("the Fréchet distance needs at least 2 embeddings per set, got {n}");
    }
    let e = rows[0].len();
    let mut mean = vec![0.0; e];
    for r in &rows {
        for (m, v) in mean.iter_mut().zip(r) {
            *m += v / n as f64;
        }
    }
    let mut cov = vec![0.0; e * e];
    for r in &rows {
        for i in 0..e {
            for j in 0..e {
                cov[i * e + j] += (r[i] - mean[i]) * (r[j] - mean[j]) / (n - 1) as f64;
            }
        }
    }
    Ok((mean, cov))
}

fn multiply(a: &[f64], b: &[f64], e: usize) -> Vec<f64> {
    let mut out = vec![0.0; e * e];
    for i in 0..e {
        for k in 0..e {
            let aik = a[i * e + k];
            for j in 0..e {
                out[i * e + j] += aik * b[k * e + j];
            }
        }
    }
    out
}

/// `V f(Λ) Vᵀ` of a symmetric matrix `[e·e]`.
fn symmetric_function(m: &[f64], e: usize, f: impl Fn(f64) -> f64) -> Vec<f64> {
    let (values, vectors) = jacobi_eigen(m, e);
    let mut out = vec![0.0; e * e];
    for (k, l) in values.iter().enumerate() {
        let fl = f(*l);
        for i in 0..e {
            for j in 0..e {
                out[i * e + j] += vectors[i * e + k] * fl * vectors[j * e + k];
            }
        }
    }
    out
}

/// Eigenvalues and eigenvectors (columns of `[e·e]`) of a symmetric matrix by cyclic Jacobi
/// rotations, until the off-diagonal mass is below 1e-22 of the total or 100 sweeps.
fn jacobi_eigen(m: &[f64], e: usize) -> (Vec<f64>, Vec<f64>) {
    let mut a = m.to_vec();
    // Symmetrise what rounding left asymmetric.
    for i in 0..e {
        for j in 0..i {
            let s = 0.5 * (a[i * e + j] + a[j * e + i]);
            a[i * e + j] = s;
            a[j * e + i] = s;
        }
    }
    let mut v = vec![0.0; e * e];
    for i in 0..e {
        v[i * e + i] = 1.0;
    }
    let total: f64 = a.iter().map(|x| x * x).sum::<f64>().max(f64::MIN_POSITIVE);
    for _ in 0..100 {
        let off: f64 = (0..e)
            .flat_map(|i| (0..e).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i * e + j].powi(2))
            .sum();
        if off <= 1e-22 * total {
            break;
        }
        for p in 0..e {
            for q in p + 1..e {
                let apq = a[p * e + q];
                if apq.abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q * e + q] - a[p * e + p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..e {
                    let (akp, akq) = (a[k * e + p], a[k * e + q]);
                    a[k * e + p] = c * akp - s * akq;
                    a[k * e + q] = s * akp + c * akq;
                }
                for k in 0..e {
                    let (apk, aqk) = (a[p * e + k], a[q * e + k]);
                    a[p * e + k] = c * apk - s * aqk;
                    a[q * e + k] = s * apk + c * aqk;
                }
                for k in 0..e {
                    let (vkp, vkq) = (v[k * e + p], v[k * e + q]);
                    v[k * e + p] = c * vkp - s * vkq;
                    v[k * e + q] = s * vkp + c * vkq;
                }
            }
        }
    }
    ((0..e).map(|i| a[i * e + i]).collect(), v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn r_precision_is_one_for_identical_pairs_and_chance_for_unrelated_ones() {
        let dev = Device::Cpu;
        let n = 64;
        let x = crate::diffusion::noise::gaussian((n, 16), 1, &dev).unwrap();
        let x = x.broadcast_div(&x.sqr().unwrap().sum_keepdim(1).unwrap().sqrt().unwrap()).unwrap();
        let r = r_precision(&x, &x, 32, &[1, 3], 0).unwrap();
        assert_eq!(r, vec![1.0, 1.0]);
        let y = crate::diffusion::noise::gaussian((n, 16), 2, &dev).unwrap();
        let y = y.broadcast_div(&y.sqr().unwrap().sum_keepdim(1).unwrap().sqrt().unwrap()).unwrap();
        let r = r_precision(&x, &y, 32, &[1, 3], 0).unwrap();
        assert!(r[0] < 0.15 && r[1] < 0.3, "chance is 1/32 and 3/32: {r:?}");
        assert!(r_precision(&x.narrow(0, 0, 8).unwrap(), &y.narrow(0, 0, 8).unwrap(), 32, &[1], 0).is_err());
    }

    #[test]
    fn frechet_distance_of_gaussians_matches_the_closed_form() {
        let dev = Device::Cpu;
        let a = crate::diffusion::noise::gaussian((4000, 3), 1, &dev).unwrap();
        assert!(frechet_distance(&a, &a).unwrap() < 1e-6);
        // N(0, I) against N(m, 4 I): |m|² + 3·(1 + 4 − 2·2) = |m|² + 3.
        let b = ((crate::diffusion::noise::gaussian((4000, 3), 2, &dev).unwrap() * 2.0).unwrap() + 1.0).unwrap();
        let d = frechet_distance(&a, &b).unwrap();
        assert!((d - 6.0).abs() < 0.4, "expected about 6, got {d}");
        assert!(frechet_distance(&a.narrow(0, 0, 1).unwrap(), &b).is_err());
    }

    #[test]
    fn jacobi_finds_the_eigenvalues_of_a_symmetric_matrix() {
        let m = [2.0, 1.0, 0.0, 1.0, 2.0, 0.0, 0.0, 0.0, 5.0];
        let (mut values, _) = jacobi_eigen(&m, 3);
        values.sort_by(f64::total_cmp);
        for (v, want) in values.iter().zip([1.0, 3.0, 5.0]) {
            assert!((v - want).abs() < 1e-9, "{values:?}");
        }
        let root = symmetric_function(&m, 3, f64::sqrt);
        let back = multiply(&root, &root, 3);
        assert!(back.iter().zip(&m).all(|(a, b)| (a - b).abs() < 1e-9));
    }
}
