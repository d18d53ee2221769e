//! Least squares over rows that arrive in blocks: a long recording's regression, built block
//! by block, solved without ever holding it.
//!
//! **Pass 1, compression.** [X | y] (n × (k+1)) = Q R with R upper triangular ((k+1) × (k+1)),
//! updated block by block: [R; X_b | y_b] = Q′ R′ (Householder QR of the stacked rows, a
//! row-blocked TSQR as in [`crate::Ols`]). With R_x = R[:, :k] and r_y = R[:, k], for every θ
//!
//! ```text
//! ‖y − Xθ‖ = ‖Qᵀ(y − Xθ)‖ = ‖r_y − R_x θ‖
//! ```
//!
//! so the (k+1)-row problem (R_x, r_y) has the same least-squares and bounded least-squares
//! solutions as the n-row one, the same column norms, singular values, condition number and
//! rank, and the same residual sum of squares: any [`wheelid_core::Solver`] solves it in place of
//! the whole problem ([`QrRows::compressed`]).
//!
//! **Standard errors.** The residuals are gone from the compressed problem, and with them
//! what a solver's standard errors need. Either a second pass over the same rows, with θ̂
//! known, gives e_t = y_t − X_t θ̂ and the Newey–West meat of h_t = X̃_tᵀ e_t (X̃ = X D⁻¹, D
//! the column norms) row by row ([`crate::ols::NeweyWest`], L + 1 rows held); or, in the same
//! pass as the compression, the rows' window moments ([`WindowMoments`]) give that meat at
//! any θ afterwards — the meat is a quadratic in θ. [`covariance`] forms
//! Cov(θ̂) = D⁻¹ H̃⁻¹ S_h H̃⁻¹ D⁻¹ · n/(n − k), H̃ = R̃ᵀR̃ — what [`crate::Ols`] computes from the
//! whole X (test).

use nalgebra::{DMatrix, DVector};
use wheelid_core::{LinearProblem, SolveError};

use crate::ols::{self, Spread};

mod moments;
pub use moments::WindowMoments;

/// Rows per Householder step of [`QrRows::push`].
const QR_CHUNK: usize = 4096;

/// Pass 1: the triangular factor of [X | y] over the rows pushed so far.
#[derive(Debug, Clone)]
pub struct QrRows {
    k: usize,
    /// R, at most (k+1) × (k+1).
    r: DMatrix<f64>,
    n: usize,
}

impl QrRows {
    /// No rows yet, for `k` regressors.
    pub fn new(k: usize) -> Self {
        Self {
            k,
            r: DMatrix::zeros(0, k + 1),
            n: 0,
        }
    }

    /// Rows pushed.
    pub fn rows(&self) -> usize {
        self.n
    }

    /// Adds the rows of `x` (m × k) and `y` (m).
    ///
    /// # Errors
    /// [`SolveError::InvalidProblem`] for shapes that disagree or a non-finite value.
    pub fn push(&mut self, x: &DMatrix<f64>, y: &DVector<f64>) -> Result<(), SolveError> {
        let (m, k) = x.shape();
        if k != self.k || y.len() != m {
            return Err(SolveError::InvalidProblem(format!(
                "a block of {m} × {k} regressors and {} values, for {} regressors",
                y.len(),
                self.k
            )));
        }
        if x.iter().chain(y.iter()).any(|v| !v.is_finite()) {
            return Err(SolveError::InvalidProblem(
                "X or y has a non-finite value".into(),
            ));
        }
        let mut start = 0;
        while start < m {
            let len = QR_CHUNK.min(m - start);
            self.r = ols::qr_update(&self.r, len, |mut block| {
                block
                    .columns_mut(0, k)
                    .copy_from(&x.view((start, 0), (len, k)));
                block.column_mut(k).copy_from(&y.rows(start, len));
            });
            start += len;
        }
        self.n += m;
        Ok(())
    }

    /// The equivalent (k+1)-row problem (R_x, r_y) of the module doc (zero rows where fewer
    /// than k + 1 rows were pushed).
    pub fn compressed(&self) -> (DMatrix<f64>, DVector<f64>) {
        let k = self.k;
        let mut r = DMatrix::zeros(k + 1, k + 1);
        r.view_mut((0, 0), self.r.shape()).copy_from(&self.r);
        (r.columns(0, k).into_owned(), r.column(k).into_owned())
    }
}

/// Cov(θ̂) (k × k) of least squares on `n` rows whose compressed problem is `x_compressed`
/// ((k+1) × k, [`QrRows::compressed`]), from the Newey–West meat `meat_h` of
/// h_t = X̃_tᵀ e_t with X̃ = X D⁻¹, D = [`column_norms`] (`lags` > 0), or from the residual sum
/// of squares `rss` (`lags` = 0): the covariance [`crate::Ols`] gives the whole problem.
///
/// # Errors
/// [`SolveError::RankDeficient`] or [`SolveError::Numerical`] as [`crate::Ols`] would give.
pub fn covariance(
    x_compressed: &DMatrix<f64>,
    n: usize,
    names: &[&str],
    meat_h: Option<DMatrix<f64>>,
    rss: f64,
) -> Result<DMatrix<f64>, SolveError> {
    let y = DVector::zeros(x_compressed.nrows());
    let p = LinearProblem {
        x: x_compressed,
        y: &y,
        names,
        bounds: None,
        correlation_lags: 0,
    };
    let d = ols::decompose(&p, crate::Ols::default().rank_tol)?;
    let spread = match meat_h {
        Some(m) => Spread::Meat(m),
        None => Spread::White(rss),
    };
    Ok(ols::covariance_of(&d, n, spread))
}

/// The column norms D of X from its compressed problem (k; 1 for a zero column, as
/// [`crate::Ols`] scales): the Newey–West meat is of the rows scaled by them.
pub fn column_norms(x_compressed: &DMatrix<f64>) -> Vec<f64> {
    ols::column_scales(x_compressed).iter().copied().collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Ols;
    use approx::assert_relative_eq;
    use wheelid_core::Solver;

    /// 30,011 rows pushed in uneven blocks: θ from the compressed problem, and the Newey–West
    /// covariance from a second pass or from pass 1's window moments, equal `Ols` on the whole
    /// problem.
    #[test]
    fn blocks_equal_ols_on_the_whole_problem_in_two_passes_or_one() {
        let n = 30_011;
        let (x, y) = ols::ill_scaled_problem(n);
        let names = ["a", "b", "c"];
        for lags in [0usize, 12] {
            let whole = Ols::default()
                .solve(&LinearProblem {
                    x: &x,
                    y: &y,
                    names: &names,
                    bounds: None,
                    correlation_lags: lags,
                })
                .expect("solves");
            let cuts = [0, 5, 4_100, 9_000, 30_000, n];
            let mut qr = QrRows::new(3);
            for w in cuts.windows(2) {
                let rows: Vec<usize> = (w[0]..w[1]).collect();
                qr.push(&x.select_rows(&rows), &y.select_rows(&rows))
                    .expect("finite");
            }
            assert_eq!(qr.rows(), n);
            let (xc, yc) = qr.compressed();
            let fit = Ols::default()
                .solve(&LinearProblem {
                    x: &xc,
                    y: &yc,
                    names: &names,
                    bounds: None,
                    correlation_lags: 0,
                })
                .expect("solves");
            // Both are rounding away from the exact θ by up to cond(X̃)·ε·‖θ‖ (cond ≈ 1e5).
            assert_relative_eq!(fit.theta, whole.theta, max_relative = 1e-8);
            assert_relative_eq!(fit.rss, whole.rss, max_relative = 1e-8);
            assert_relative_eq!(
                fit.condition_number,
                whole.condition_number,
                max_relative = 1e-10
            );
            // Pass 2.
            let d = column_norms(&xc);
            let mut nw = ols::NeweyWest::new(3, lags);
            let mut rss = 0.0;
            for t in 0..n {
                let e = y[t] - (0..3).map(|j| x[(t, j)] * fit.theta[j]).sum::<f64>();
                rss += e * e;
                let h: Vec<f64> = (0..3).map(|j| x[(t, j)] / d[j] * e).collect();
                nw.push(&h);
            }
            let meat = (lags > 0).then(|| nw.finish());
            let cov = covariance(&xc, n, &names, meat, rss).expect("full rank");
            assert_relative_eq!(cov, whole.covariance, max_relative = 1e-7);
            // Or in pass 1: the window moments around a pilot (least squares on the first
            // 4,100 rows, as identify takes the first block's), and the compressed problem's RSS.
            let head: Vec<usize> = (0..4_100).collect();
            let (xh, yh) = (x.select_rows(&head), y.select_rows(&head));
            let pilot = Ols::default()
                .solve(&LinearProblem {
                    x: &xh,
                    y: &yh,
                    names: &names,
                    bounds: None,
                    correlation_lags: 0,
                })
                .expect("solves")
                .theta;
            let pilot: Vec<f64> = pilot.iter().copied().collect();
            let r0 = xh.qr().r();
            let mut moments = WindowMoments::new(lags, &pilot, Some(&r0));
            for w in cuts.windows(2) {
                let rows: Vec<usize> = (w[0]..w[1]).collect();
                moments.push(&x.select_rows(&rows), &y.select_rows(&rows));
            }
            let meat = (lags > 0).then(|| moments.meat(fit.theta.as_slice(), &d));
            let cov = covariance(&xc, n, &names, meat, fit.rss).expect("full rank");
            assert_relative_eq!(cov, whole.covariance, max_relative = 1e-7);
        }
    }

    #[test]
    fn a_bad_block_is_an_error() {
        let mut qr = QrRows::new(2);
        let x = DMatrix::from_element(3, 2, 1.0);
        assert!(qr.push(&x, &DVector::from_element(2, 1.0)).is_err());
        let y = DVector::from_vec(vec![1.0, f64::NAN, 0.0]);
        assert!(qr.push(&x, &y).is_err());
        assert_eq!(qr.rows(), 0);
    }
}
