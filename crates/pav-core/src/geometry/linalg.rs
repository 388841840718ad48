//! Dense symmetric positive-definite systems (normal equations of least-squares fits): the
//! Cholesky factor once, then as many right-hand sides as needed.

/// The lower-triangular Cholesky factor of an `n × n` row-major matrix.
pub struct Cholesky {
    l: Vec<f64>,
    n: usize,
}

impl Cholesky {
    /// Factors `a`; `None` if it is not positive definite (singular, within 1e-18).
    pub fn factor(mut a: Vec<f64>, n: usize) -> Option<Cholesky> {
        for j in 0..n {
            let mut d = a[j * n + j];
            for k in 0..j {
                d -= a[j * n + k] * a[j * n + k];
            }
            if d.is_nan() || d <= 1e-18 {
                return None;
            }
            let d = d.sqrt();
            a[j * n + j] = d;
            for i in j + 1..n {
                let mut s = a[i * n + j];
                for k in 0..j {
                    s -= a[i * n + k] * a[j * n + k];
                }
                a[i * n + j] = s / d;
            }
        }
        Some(Cholesky { l: a, n })
    }

    /// The solution of `a·x = b`.
    pub fn solve(&self, mut b: Vec<f64>) -> Vec<f64> {
        let (a, n) = (&self.l, self.n);
        for i in 0..n {
            for k in 0..i {
                b[i] -= a[i * n + k] * b[k];
            }
            b[i] /= a[i * n + i];
        }
        for i in (0..n).rev() {
            for k in i + 1..n {
                b[i] -= a[k * n + i] * b[k];
            }
            b[i] /= a[i * n + i];
        }
        b
    }
}

/// Solves `a·x = b` for a dense symmetric positive-definite `a` (`n × n`, row-major); `None` if
/// singular.
pub fn cholesky_solve(a: Vec<f64>, b: Vec<f64>, n: usize) -> Option<Vec<f64>> {
    Some(Cholesky::factor(a, n)?.solve(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_positive_definite_system_is_solved_and_a_singular_one_refused() {
        // a = mᵀm + I for a fixed m; x known.
        let m = [[1.0, 2.0, 0.5], [0.0, 1.0, -1.0], [3.0, 0.2, 1.0]];
        let a: Vec<f64> = (0..9)
            .map(|k| (0..3).map(|t| m[t][k / 3] * m[t][k % 3]).sum::<f64>() + if k % 4 == 0 { 1.0 } else { 0.0 })
            .collect();
        let x = [0.3, -1.2, 2.0];
        let b: Vec<f64> = (0..3).map(|i| (0..3).map(|j| a[i * 3 + j] * x[j]).sum()).collect();
        let got = cholesky_solve(a, b, 3).unwrap();
        assert!((0..3).all(|i| (got[i] - x[i]).abs() < 1e-12), "{got:?}");
        assert!(cholesky_solve(vec![1.0, 1.0, 1.0, 1.0], vec![1.0, 1.0], 2).is_none());
    }
}
