//! The Newey–West meat at a θ not known yet: window moments gathered in pass 1.
//!
//! The Bartlett-weighted meat of g_t = x_t e_t (e_t = y_t − x_tᵀθ, rows x_t ∈ ℝᵏ) is, by the
//! moving sums B_s of L + 1 consecutive g_t ([`crate::NeweyWest`]),
//!
//! ```text
//! S(θ) = Σ_s B_s(θ) B_s(θ)ᵀ / (L + 1).
//! ```
//!
//! g_t is affine in θ. With a pilot θ₀ (an early estimate: the first block's least squares),
//! r_t = y_t − x_tᵀθ₀ and δ = θ − θ₀,
//!
//! ```text
//! g_t = p_t − Q_t δ,   p_t = x_t r_t,   Q_t = x_t x_tᵀ
//! B_s = P_s − Q̄_s δ,   P_s, Q̄_s the window sums of p_t, Q_t
//! S(θ)·(L+1) = Σ P Pᵀ − Σ_j δ_j (Σ P Q̄_{·j}ᵀ + Σ Q̄_{·j} Pᵀ) + Σ_{j,l} δ_j δ_l Σ Q̄_{·j} Q̄_{·l}ᵀ
//! ```
//!
//! so three sums over the windows — Σ P Pᵀ (k × k), Σ P ⊗ Q̄ (k × k(k+1)/2) and Σ Q̄ ⊗ Q̄
//! (k(k+1)/2 squared, symmetric) — gathered in the pass that compresses the rows, give S at
//! the θ̂ solved afterwards: no second pass over the data.
//!
//! S is a difference of larger moments unless δ is small: the pilot keeps the terms the size of
//! the residuals. Where the columns are nearly collinear, the covariance H⁻¹ S H⁻¹ then
//! magnifies what rounding is left (a pilot 0.2 % off gave 7e-4 of the covariance on a test
//! problem of condition 1e5), so the moments are taken of whitened rows z_t = R₀⁻ᵀ x_t, R₀ the
//! triangular factor of the rows that gave the pilot: z has near-identity moments, B_s =
//! P_s − Q̄_s δ_z with δ_z = R₀ δ, and S_x = R₀ᵀ S_z R₀. Equal to the second pass's
//! [`crate::NeweyWest`] to rounding (test).

use nalgebra::{DMatrix, DVector};

/// Pass 1's window moments of the rows (module doc): the Newey–West meat at any θ afterwards.
#[derive(Debug, Clone)]
pub struct WindowMoments {
    k: usize,
    lags: usize,
    /// θ₀ (k), set before the first row.
    pilot: Vec<f64>,
    /// R₀ (k × k, upper triangular; the identity when none is given) and A = R₀⁻ᵀ, row-major:
    /// the rows are whitened as z = A x.
    r0: DMatrix<f64>,
    a: Vec<f64>,
    /// The last L + 1 rows' p_t and upper-triangular Q_t (k + k(k+1)/2 values each), row t in
    /// slot t mod (L + 1).
    ring: Vec<f64>,
    slot: usize,
    /// The window sums P_s and Q̄_s (upper triangle, row by row).
    window: Vec<f64>,
    /// Σ P Pᵀ (k × k, row-major), Σ P ⊗ Q̄ (k × q, row-major) and Σ Q̄ ⊗ Q̄ (q × q, row-major),
    /// q = k(k+1)/2; the symmetric ones filled on their upper triangle.
    pp: Vec<f64>,
    pq: Vec<f64>,
    qq: Vec<f64>,
    rows: usize,
}

impl WindowMoments {
    /// No rows yet, for `lags` lags (L), around the pilot θ₀ = `pilot` (k values), the rows
    /// whitened by `r0` (k × k upper triangular, the R of the QR factor of the rows that gave
    /// the pilot; not whitened when it is `None`, of another shape or not invertible).
    pub fn new(lags: usize, pilot: &[f64], r0: Option<&DMatrix<f64>>) -> Self {
        let k = pilot.len();
        let q = k * (k + 1) / 2;
        let r0 = r0.filter(|r| r.shape() == (k, k)).and_then(|r| {
            let r = r.upper_triangle();
            let a = r.transpose().try_inverse()?;
            a.iter().all(|v| v.is_finite()).then_some((r, a))
        });
        let (r0, a) = r0.unwrap_or_else(|| (DMatrix::identity(k, k), DMatrix::identity(k, k)));
        Self {
            k,
            lags,
            pilot: pilot.to_vec(),
            a: a.transpose().as_slice().to_vec(),
            r0,
            ring: vec![0.0; (lags + 1) * (k + q)],
            slot: 0,
            window: vec![0.0; k + q],
            pp: vec![0.0; k * k],
            pq: vec![0.0; k * q],
            qq: vec![0.0; q * q],
            rows: 0,
        }
    }

    /// Rows pushed.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Adds the rows of `x` (m × k, rows in order) and `y` (m); shapes that disagree with the
    /// pilot's k add nothing (the caller's QR pass reports them).
    pub fn push(&mut self, x: &DMatrix<f64>, y: &DVector<f64>) {
        if x.ncols() != self.k || x.nrows() != y.len() {
            return;
        }
        match self.k {
            1 => self.push_k::<1, 1, 2>(x, y),
            2 => self.push_k::<2, 3, 5>(x, y),
            3 => self.push_k::<3, 6, 9>(x, y),
            4 => self.push_k::<4, 10, 14>(x, y),
            _ => self.push_any(x, y),
        }
    }

    /// [`WindowMoments::push`] for k = K ≤ 4 (Q = K(K+1)/2 values of Q_t, W = K + Q a row), the
    /// sums held in local arrays (registers) over the block.
    fn push_k<const K: usize, const Q: usize, const W: usize>(
        &mut self,
        x: &DMatrix<f64>,
        y: &DVector<f64>,
    ) {
        let m = y.len();
        let xs = x.as_slice();
        let theta0: [f64; K] = std::array::from_fn(|j| self.pilot[j]);
        let a: [[f64; K]; K] = std::array::from_fn(|i| std::array::from_fn(|j| self.a[i * K + j]));
        let mut win = [0.0; W];
        win.copy_from_slice(&self.window);
        let (mut pp, mut pq, mut qq) = ([0.0; 16], [0.0; 40], [0.0; 100]);
        pp[..K * K].copy_from_slice(&self.pp);
        pq[..K * Q].copy_from_slice(&self.pq);
        qq[..Q * Q].copy_from_slice(&self.qq);
        let mut slot = self.slot;
        for t in 0..m {
            let xt: [f64; K] = std::array::from_fn(|j| xs[j * m + t]);
            let mut r = y[t];
            for j in 0..K {
                r -= xt[j] * theta0[j];
            }
            let xt: [f64; K] = std::array::from_fn(|i| {
                let mut z = 0.0;
                for j in 0..K {
                    z += a[i][j] * xt[j];
                }
                z
            });
            let mut row = [0.0; W];
            for j in 0..K {
                row[j] = xt[j] * r;
            }
            let mut c = K;
            for a in 0..K {
                for b in a..K {
                    row[c] = xt[a] * xt[b];
                    c += 1;
                }
            }
            let old: &mut [f64; W] = (&mut self.ring[slot * W..(slot + 1) * W])
                .try_into()
                .expect("ring slots of W values");
            for ((b, o), r) in win.iter_mut().zip(old.iter_mut()).zip(&row) {
                *b += r - *o;
                *o = *r;
            }
            slot = if slot == self.lags { 0 } else { slot + 1 };
            for a in 0..K {
                for b in a..K {
                    pp[a * K + b] += win[a] * win[b];
                }
                for c in 0..Q {
                    pq[a * Q + c] += win[a] * win[K + c];
                }
            }
            for c in 0..Q {
                for d in c..Q {
                    qq[c * Q + d] += win[K + c] * win[K + d];
                }
            }
        }
        self.slot = slot;
        self.window.copy_from_slice(&win);
        self.pp.copy_from_slice(&pp[..K * K]);
        self.pq.copy_from_slice(&pq[..K * Q]);
        self.qq.copy_from_slice(&qq[..Q * Q]);
        self.rows += m;
    }

    /// [`WindowMoments::push`] for any k.
    fn push_any(&mut self, x: &DMatrix<f64>, y: &DVector<f64>) {
        let (m, k) = x.shape();
        let q = k * (k + 1) / 2;
        let mut row = vec![0.0; k + q];
        for t in 0..m {
            let xr = x.row(t);
            let r = y[t] - (0..k).map(|j| xr[j] * self.pilot[j]).sum::<f64>();
            let xt: Vec<f64> = (0..k)
                .map(|i| (0..k).map(|j| self.a[i * k + j] * xr[j]).sum())
                .collect();
            let mut c = k;
            for a in 0..k {
                row[a] = xt[a] * r;
                for b in a..k {
                    row[c] = xt[a] * xt[b];
                    c += 1;
                }
            }
            self.slide_any(&row);
        }
        self.rows += m;
    }

    fn slide_any(&mut self, row: &[f64]) {
        let k = self.k;
        let q = k * (k + 1) / 2;
        let w = k + q;
        let old = &mut self.ring[self.slot * w..(self.slot + 1) * w];
        for ((b, o), r) in self.window.iter_mut().zip(old.iter_mut()).zip(row) {
            *b += r - *o;
            *o = *r;
        }
        self.slot = if self.slot == self.lags {
            0
        } else {
            self.slot + 1
        };
        let (p, qb) = self.window.split_at(k);
        for a in 0..k {
            for b in a..k {
                self.pp[a * k + b] += p[a] * p[b];
            }
            for (pq, qc) in self.pq[a * q..(a + 1) * q].iter_mut().zip(qb) {
                *pq += p[a] * qc;
            }
        }
        for (c, qc) in qb.iter().enumerate() {
            for (qq, qd) in self.qq[c * q + c..(c + 1) * q].iter_mut().zip(&qb[c..]) {
                *qq += qc * qd;
            }
        }
    }

    /// The Newey–West meat (k × k, symmetric) at `theta` of h_t = x̃_t e_t, the columns of X
    /// divided by `scales` (k; [`super::column_norms`]), as [`crate::NeweyWest`] over a second
    /// pass would give it: the window slides L steps past the last row first.
    pub fn meat(&self, theta: &[f64], scales: &[f64]) -> DMatrix<f64> {
        let k = self.k;
        let q = k * (k + 1) / 2;
        let mut tail = self.clone();
        let zero = vec![0.0; k + q];
        for _ in 0..self.lags {
            tail.slide_any(&zero);
        }
        // idx[a k + b]: where Q̄_ab is among the upper triangle's values, row by row.
        let idx = {
            let mut idx = vec![0usize; k * k];
            let mut c = 0;
            for a in 0..k {
                for b in a..k {
                    idx[a * k + b] = c;
                    idx[b * k + a] = c;
                    c += 1;
                }
            }
            idx
        };
        let delta = DVector::from_iterator(k, theta.iter().zip(&self.pilot).map(|(t, p)| t - p));
        let delta = &self.r0 * delta;
        let sym = |v: &[f64], n: usize, i: usize, j: usize| v[i.min(j) * n + i.max(j)];
        let s_z = DMatrix::from_fn(k, k, |i, m| {
            let mut s = sym(&tail.pp, k, i, m);
            for j in 0..k {
                s -= delta[j] * (tail.pq[i * q + idx[m * k + j]] + tail.pq[m * q + idx[i * k + j]]);
                for l in 0..k {
                    s += delta[j] * delta[l] * sym(&tail.qq, q, idx[i * k + j], idx[m * k + l]);
                }
            }
            s
        });
        let s_x = self.r0.transpose() * s_z * &self.r0;
        DMatrix::from_fn(k, k, |i, m| {
            0.5 * (s_x[(i, m)] + s_x[(m, i)]) / (scales[i] * scales[m] * (self.lags + 1) as f64)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::NeweyWest;

    /// 20,011 rows of three correlated regressors in uneven blocks, lags 0, 1 and 7, pilots at
    /// θ̂ + 3 % (whitened or not) and at 0: the meat at θ̂ equals a second pass of
    /// [`NeweyWest`] over h_t = x̃_t e_t.
    #[test]
    fn window_moments_give_the_second_pass_meat() {
        let (x, y) = crate::ols::ill_scaled_problem(20_011);
        let theta = [0.52, -1.49, 39.0];
        let scales = [2.0e5, 1.9e5, 3.0];
        for lags in [0usize, 1, 7] {
            let mut nw = NeweyWest::new(3, lags);
            for t in 0..x.nrows() {
                let e = y[t] - (0..3).map(|j| x[(t, j)] * theta[j]).sum::<f64>();
                let h: Vec<f64> = (0..3).map(|j| x[(t, j)] / scales[j] * e).collect();
                nw.push(&h);
            }
            let want = nw.finish();
            let head = x.rows(0, 4_000).into_owned();
            let r0 = head.qr().r();
            for (pilot, r0) in [
                (theta.map(|v| v * 1.03), Some(&r0)),
                (theta.map(|v| v * 1.03), None),
                ([0.0; 3], None),
            ] {
                let mut wm = WindowMoments::new(lags, &pilot, r0);
                let mut start = 0;
                for len in [1usize, 4_000, 9_999, 6_011] {
                    let xb = x.rows(start, len).into_owned();
                    let yb = y.rows(start, len).into_owned();
                    wm.push(&xb, &yb);
                    start += len;
                }
                assert_eq!(wm.rows(), 20_011);
                let got = wm.meat(&theta, &scales);
                let tol = 1e-9 * want.abs().max();
                for (g, w) in got.iter().zip(want.iter()) {
                    assert!(
                        (g - w).abs() < tol,
                        "lags {lags} pilot {pilot:?}: {g} vs {w}"
                    );
                }
            }
        }
    }
}
