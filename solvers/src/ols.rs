//! Ordinary least squares by singular value decomposition.
//!
//! The columns of X are first scaled to unit norm (X = X̃ D), so that rank and condition number
//! measure identifiability rather than units; then X̃ = U Σ Vᵀ and
//!
//! ```text
//! θ̂ = D⁻¹ V Σ⁻¹ Uᵀ y,       Cov(θ̂) = D⁻¹ V Σ⁻¹ Uᵀ S U Σ⁻¹ Vᵀ D⁻¹
//! ```
//!
//! with S = σ̂² I for independent residuals (σ̂² = RSS/(n − p)), or the Newey–West estimate
//! S = Σ_{|l| ≤ L} (1 − |l|/(L+1)) e_k e_{k+l} (Bartlett kernel) when the problem declares
//! residuals correlated over L samples, as filtered data are. This never forms (XᵀX)⁻¹
//! (eq. 4.5 of the thesis), whose condition number is the square of X's.
//!
//! The Bartlett-weighted sum is computed in O((n + L) p²), not O(n p² L): with g_t = U_tᵀ e_t
//! (zero outside 0 ≤ t < n) and the moving sums B_s = Σ_{t=s}^{s+L} g_t, s = −L … n−1,
//!
//! ```text
//! Σ_{|l| ≤ L} (1 − |l|/(L+1)) Σ_t g_t g_{t+l}ᵀ = (1/(L+1)) Σ_s B_s B_sᵀ
//! ```
//!
//! exactly, because the pair (t, u) lies in L + 1 − |t − u| of the windows (the Bartlett
//! kernel is the autocorrelation of a box, Newey & West 1987).
//!
//! A singular value below `rank_tol · σ_max` makes the problem rank-deficient: the error names
//! the parameters with weight in the corresponding right singular vectors.

use nalgebra::{DMatrix, DVector};
use wheelid_core::{BoundState, LinearFit, LinearProblem, SolveError, SolveStatus, Solver};

/// Ordinary least squares (`ols`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ols {
    /// Relative singular-value threshold for rank (of the column-normalised X).
    pub rank_tol: f64,
}

impl Default for Ols {
    fn default() -> Self {
        Self { rank_tol: 1e-9 }
    }
}

/// Column norms of X (zero columns keep scale 1 so they show up as rank loss).
pub(crate) fn column_scales(x: &DMatrix<f64>) -> DVector<f64> {
    DVector::from_iterator(
        x.ncols(),
        x.column_iter().map(|c| {
            let n = c.norm();
            if n > 0.0 && n.is_finite() { n } else { 1.0 }
        }),
    )
}

pub(crate) fn check_problem(p: &LinearProblem<'_>) -> Result<(), SolveError> {
    let (n, k) = p.x.shape();
    if p.y.len() != n {
        return Err(SolveError::InvalidProblem(format!(
            "X has {n} rows, y has {}",
            p.y.len()
        )));
    }
    if p.names.len() != k {
        return Err(SolveError::InvalidProblem(format!(
            "{k} columns but {} names",
            p.names.len()
        )));
    }
    if n <= k {
        return Err(SolveError::InvalidProblem(format!(
            "{n} samples cannot determine {k} parameters"
        )));
    }
    if p.x.iter().chain(p.y.iter()).any(|v| !v.is_finite()) {
        return Err(SolveError::InvalidProblem(
            "X or y has a non-finite value".into(),
        ));
    }
    Ok(())
}

/// Everything [`Ols`] computes, reused by the bounded solver for its covariance: the SVD
/// R̃ = U_R Σ Vᵀ of the triangular factor of the column-scaled X̃ = Q R̃ (so X̃ = (Q U_R) Σ Vᵀ,
/// the thin SVD of X̃, without the n × k factor Q U_R ever being formed).
pub(crate) struct Decomposition {
    /// Column norms D of X (k).
    pub scales: DVector<f64>,
    /// Singular values Σ of X̃ (k), largest first.
    pub sv: DVector<f64>,
    /// Vᵀ (k × k).
    pub v_t: DMatrix<f64>,
    /// (Q U_R)ᵀ y = U_Rᵀ Qᵀ y (k): the data's coordinates on the left singular vectors.
    pub uty: DVector<f64>,
    /// Numerical rank (= k: a rank-deficient X is an error).
    pub rank: usize,
    /// Condition number σ_max / σ_min of X̃.
    pub cond: f64,
}

/// Rows per block of the blocked QR factorisation.
const QR_BLOCK: usize = 4096;

/// The triangular factor R ((k+1) × (k+1)) of [X̃ | y] = Q R, X̃ = X D⁻¹, by Householder QR of
/// row blocks: each block is stacked under the R so far and reduced again (a row-blocked
/// "TSQR", Demmel et al. 2012; as stable as one Householder QR), with the rows split between
/// the available cores and their factors combined by one more QR. Row q of [X | y] (n rows,
/// X unscaled) is what `row(q, out)` writes into `out` (k + 1 values): the rows are read where
/// they lie, never gathered into an n × (k + 1) matrix.
fn tall_r(
    n: usize,
    k: usize,
    scales: &DVector<f64>,
    row: &(impl Fn(usize, &mut [f64]) + Sync),
) -> DMatrix<f64> {
    let threads = rayon::current_num_threads().clamp(1, (n / (16 * QR_BLOCK)).max(1));
    let part = n.div_ceil(threads);
    let reduce = |rows: std::ops::Range<usize>| {
        let mut r = DMatrix::<f64>::zeros(0, k + 1);
        let mut start = rows.start;
        let mut buf = vec![0.0; k + 1];
        while start < rows.end {
            let len = QR_BLOCK.min(rows.end - start);
            r = qr_update(&r, len, |mut block| {
                for i in 0..len {
                    row(start + i, &mut buf);
                    for j in 0..k {
                        block[(i, j)] = buf[j] / scales[j];
                    }
                    block[(i, k)] = buf[k];
                }
            });
            start += len;
        }
        r
    };
    if threads == 1 {
        return reduce(0..n);
    }
    let parts: Vec<DMatrix<f64>> = {
        use rayon::prelude::*;
        (0..threads)
            .into_par_iter()
            .map(|i| reduce(i * part..((i + 1) * part).min(n)))
            .collect()
    };
    let rows: usize = parts.iter().map(|r| r.nrows()).sum();
    let mut stacked = DMatrix::zeros(rows, k + 1);
    let mut at = 0;
    for r in &parts {
        stacked.view_mut((at, 0), r.shape()).copy_from(r);
        at += r.nrows();
    }
    stacked.qr().r()
}

/// The triangular factor of [r; B] (Householder QR), where `fill` writes the `len` new rows B
/// (as many columns as r) into the view it is given: one step of the row-blocked QR.
pub(crate) fn qr_update(
    r: &DMatrix<f64>,
    len: usize,
    fill: impl FnOnce(nalgebra::DMatrixViewMut<'_, f64>),
) -> DMatrix<f64> {
    let (top, cols) = r.shape();
    let mut stacked = DMatrix::<f64>::zeros(top + len, cols);
    stacked.view_mut((0, 0), (top, cols)).copy_from(r);
    fill(stacked.view_mut((top, 0), (len, cols)));
    stacked.qr().r()
}

pub(crate) fn decompose(p: &LinearProblem<'_>, rank_tol: f64) -> Result<Decomposition, SolveError> {
    let (n, k) = p.x.shape();
    let row = |q: usize, out: &mut [f64]| {
        for (j, o) in out[..k].iter_mut().enumerate() {
            *o = p.x[(q, j)];
        }
        out[k] = p.y[q];
    };
    decompose_rows(n, p.names, column_scales(p.x), rank_tol, &row)
}

/// [`decompose`] of the n rows of [X | y] that `row(q, out)` writes (k + 1 values, X
/// unscaled), given X's column norms `scales` (k) and its columns' `names` (k).
///
/// # Errors
/// As [`decompose`].
pub(crate) fn decompose_rows(
    n: usize,
    names: &[&str],
    scales: DVector<f64>,
    rank_tol: f64,
    row: &(impl Fn(usize, &mut [f64]) + Sync),
) -> Result<Decomposition, SolveError> {
    let k = scales.len();
    let r = tall_r(n, k, &scales, row);
    if r.nrows() < k {
        return Err(SolveError::InvalidProblem(format!(
            "{n} samples cannot determine {k} parameters"
        )));
    }
    let svd = r.view((0, 0), (k, k)).into_owned().svd(true, true);
    let (Some(u_r), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(SolveError::Numerical("SVD did not converge".into()));
    };
    let sv = svd.singular_values;
    let smax = sv.max();
    let rank = sv.iter().filter(|s| **s > rank_tol * smax).count();
    if rank < sv.len() {
        // Parameters with weight > 0.1 in a null-space direction.
        let mut involved = vec![false; sv.len()];
        for (i, s) in sv.iter().enumerate() {
            if *s <= rank_tol * smax {
                for (j, flag) in involved.iter_mut().enumerate() {
                    if v_t[(i, j)].abs() > 0.1 {
                        *flag = true;
                    }
                }
            }
        }
        return Err(SolveError::RankDeficient {
            names: names
                .iter()
                .zip(involved)
                .filter(|(_, f)| *f)
                .map(|(n, _)| (*n).to_owned())
                .collect(),
            rank,
            p: sv.len(),
        });
    }
    let cond = smax / sv.min();
    let uty = u_r.transpose() * r.view((0, k), (k, 1));
    Ok(Decomposition {
        scales,
        sv,
        v_t,
        uty: uty.column(0).into_owned(),
        rank,
        cond,
    })
}

/// Cov(θ̂) of the module doc for the residuals `e` of the problem with regressors `x` (n × k):
/// with H̃⁻¹ = V Σ⁻² Vᵀ the inverse of X̃ᵀX̃ and h_t = X̃_tᵀ e_t,
/// Cov = D⁻¹ H̃⁻¹ S_h H̃⁻¹ D⁻¹ (k × k), S_h = σ̂² X̃ᵀX̃ without lags, else the Bartlett-weighted
/// sum of h_t h_{t+l}ᵀ over |l| ≤ `lags`, scaled by n/(n − k). (U_t = Σ⁻¹ Vᵀ X̃_tᵀ, so this is
/// the U-coordinate form of the module doc, computed without U.)
pub(crate) fn covariance(
    d: &Decomposition,
    x: &DMatrix<f64>,
    e: &DVector<f64>,
    lags: usize,
) -> DMatrix<f64> {
    let n = x.nrows();
    let spread = if lags == 0 {
        Spread::White(e.norm_squared())
    } else {
        // S_h over h_t = X̃_tᵀ e_t.
        Spread::Meat(bartlett_meat_with(n, d.sv.len(), lags, |t, j| {
            x[(t, j)] / d.scales[j] * e[t]
        }))
    };
    covariance_of(d, n, spread)
}

/// What [`covariance_of`] needs of the residuals.
pub(crate) enum Spread {
    /// Independent residuals: their sum of squares (RSS).
    White(f64),
    /// Correlated residuals: the Newey–West meat S_h (k × k) of h_t = X̃_tᵀ e_t.
    Meat(DMatrix<f64>),
}

/// [`covariance`] from the decomposition of X (n rows) and the residuals' [`Spread`]:
/// σ̂² H⁻¹ with σ̂² = RSS/(n − k), or the sandwich D⁻¹ H̃⁻¹ S_h H̃⁻¹ D⁻¹ · n/(n − k).
pub(crate) fn covariance_of(d: &Decomposition, n: usize, spread: Spread) -> DMatrix<f64> {
    let k = d.sv.len();
    let dof = (n - k).max(1) as f64;
    // A = D⁻¹ V Σ⁻¹ (k × k): Cov = A Sᵤ Aᵀ with Sᵤ the meat in U coordinates.
    let mut a = d.v_t.transpose();
    for (j, mut c) in a.column_iter_mut().enumerate() {
        c /= d.sv[j];
    }
    for (i, mut r) in a.row_iter_mut().enumerate() {
        r /= d.scales[i];
    }
    match spread {
        Spread::White(rss) => &a * a.transpose() * (rss / dof),
        Spread::Meat(meat_h) => {
            // Sᵤ = Σ⁻¹ Vᵀ S_h V Σ⁻¹.
            let mut b = d.v_t.clone();
            for (i, mut r) in b.row_iter_mut().enumerate() {
                r /= d.sv[i];
            }
            let meat_u = &b * meat_h * b.transpose() * (n as f64 / dof);
            &a * meat_u * a.transpose()
        }
    }
}

/// The Newey–West meat Σ_{|l| ≤ L} (1 − |l|/(L+1)) Σ_t g_t g_{t+l}ᵀ (k × k) of the rows g_t
/// of `g` (n × k), by moving sums in O((n + L) k²) (module doc).
pub(crate) fn bartlett_meat(g: &DMatrix<f64>, lags: usize) -> DMatrix<f64> {
    let (n, k) = g.shape();
    bartlett_meat_with(n, k, lags, |t, j| g[(t, j)])
}

/// [`bartlett_meat`] of the rows g_t that `g(t, out)` writes (k values each, t < n), each
/// computed once: the last L + 1 are kept to leave the moving window ([`NeweyWest`]).
pub(crate) fn bartlett_meat_rows(
    n: usize,
    k: usize,
    lags: usize,
    mut g: impl FnMut(usize, &mut [f64]),
) -> DMatrix<f64> {
    let mut nw = NeweyWest::new(k, lags);
    let mut row = vec![0.0; k];
    for t in 0..n {
        g(t, &mut row);
        nw.push(&row);
    }
    nw.finish()
}

/// [`bartlett_meat_rows`] with the rows cut into `parts` runs of consecutive rows summed at
/// once on the available cores: each run's moving window is first filled with the L rows
/// before it (not summed there), and only the last slides past the end; `g(t, out, scratch)`
/// writes row t (`scratch`: each run's own buffer). The same sum, added in another order.
pub(crate) fn bartlett_meat_parts(
    n: usize,
    k: usize,
    lags: usize,
    parts: usize,
    g: impl Fn(usize, &mut [f64], &mut Vec<f64>) + Sync,
) -> DMatrix<f64> {
    use rayon::prelude::*;
    let parts = parts.clamp(1, n.max(1));
    let runs: Vec<NeweyWest> = (0..parts)
        .into_par_iter()
        .map(|j| {
            let (a, b) = (j * n / parts, (j + 1) * n / parts);
            let mut nw = NeweyWest::new(k, lags);
            let (mut row, mut scratch) = (vec![0.0; k], Vec::new());
            for t in a.saturating_sub(lags)..a {
                g(t, &mut row, &mut scratch);
                nw.preload(&row);
            }
            for t in a..b {
                g(t, &mut row, &mut scratch);
                nw.push(&row);
            }
            nw
        })
        .collect();
    let mut runs = runs.into_iter().rev();
    let Some(last) = runs.next() else {
        return DMatrix::zeros(k, k);
    };
    let mut meat = last.finish();
    for nw in runs {
        meat += nw.sum() / (lags + 1) as f64;
    }
    meat
}

/// The Newey–West meat of the module doc, Σ_{|l| ≤ L} (1 − |l|/(L+1)) Σ_t g_t g_{t+l}ᵀ (k × k),
/// over rows g_t pushed one at a time in order, by the moving sums B_s of L + 1 rows: it keeps
/// the last L + 1 rows and nothing else, so the rows can come from a pass over data never
/// held whole.
#[derive(Debug, Clone)]
pub struct NeweyWest {
    k: usize,
    lags: usize,
    /// The last L + 1 rows, row t in slot t mod (L + 1).
    ring: Vec<f64>,
    /// The slot the next row goes to.
    slot: usize,
    /// B: the sum of the rows in the window.
    window: Vec<f64>,
    /// Σ_s B_s B_sᵀ so far, row-major k × k (upper triangle).
    m: Vec<f64>,
}

impl NeweyWest {
    /// An empty sum for rows of `k` values and `lags` lags (L; 0: the plain Σ g_t g_tᵀ).
    pub fn new(k: usize, lags: usize) -> Self {
        Self {
            k,
            lags,
            ring: vec![0.0; (lags + 1) * k],
            slot: 0,
            window: vec![0.0; k],
            m: vec![0.0; k * k],
        }
    }

    /// Adds row g_t (its first k values; t is the count of rows pushed before).
    #[inline]
    pub fn push(&mut self, g: &[f64]) {
        match self.k {
            1 => self.push_k::<1>(g),
            2 => self.push_k::<2>(g),
            3 => self.push_k::<3>(g),
            4 => self.push_k::<4>(g),
            5 => self.push_k::<5>(g),
            6 => self.push_k::<6>(g),
            7 => self.push_k::<7>(g),
            8 => self.push_k::<8>(g),
            _ => self.push_any(g),
        }
    }

    /// [`NeweyWest::push`] for k = K, unrolled: the same operations in the same order.
    #[inline]
    fn push_k<const K: usize>(&mut self, g: &[f64]) {
        let g: &[f64; K] = g[..K].try_into().expect("k values");
        let old: &mut [f64; K] = (&mut self.ring[self.slot * K..(self.slot + 1) * K])
            .try_into()
            .expect("k values");
        let window: &mut [f64; K] = self.window.as_mut_slice().try_into().expect("k values");
        for ((b, x), new) in window.iter_mut().zip(old.iter_mut()).zip(g) {
            *b += new - *x;
            *x = *new;
        }
        self.slot = if self.slot == self.lags {
            0
        } else {
            self.slot + 1
        };
        for a in 0..K {
            for b in a..K {
                self.m[a * K + b] += window[a] * window[b];
            }
        }
    }

    fn push_any(&mut self, g: &[f64]) {
        self.preload(g);
        self.accumulate();
    }

    fn accumulate(&mut self) {
        let k = self.k;
        for (a, row) in self.m.chunks_exact_mut(k).enumerate() {
            let wa = self.window[a];
            for (mb, wb) in row[a..].iter_mut().zip(&self.window[a..]) {
                *mb += wa * wb;
            }
        }
    }

    /// Puts row g_t in the window without summing the window's products: a run of rows that
    /// starts after others first takes the L rows before it this way.
    fn preload(&mut self, g: &[f64]) {
        let k = self.k;
        let old = &mut self.ring[self.slot * k..(self.slot + 1) * k];
        // The slot held row t − (L + 1), which leaves the window now (zero before it filled).
        for ((b, x), new) in self.window.iter_mut().zip(old.iter_mut()).zip(&g[..k]) {
            *b += new - *x;
            *x = *new;
        }
        self.slot = if self.slot == self.lags {
            0
        } else {
            self.slot + 1
        };
    }

    /// Σ_s B_s B_sᵀ over the rows pushed so far (k × k, symmetric), not sliding past the last.
    fn sum(&self) -> DMatrix<f64> {
        let k = self.k;
        DMatrix::from_fn(k, k, |a, b| self.m[a.min(b) * k + a.max(b)])
    }

    /// The meat (k × k, symmetric): the window slides L steps past the last row first (a
    /// slot not filled yet holds zeros).
    pub fn finish(mut self) -> DMatrix<f64> {
        let k = self.k;
        for _ in 0..self.lags {
            let slot = self.slot;
            for (b, x) in self
                .window
                .iter_mut()
                .zip(&self.ring[slot * k..(slot + 1) * k])
            {
                *b -= x;
            }
            self.ring[slot * k..(slot + 1) * k].fill(0.0);
            self.slot = if slot == self.lags { 0 } else { slot + 1 };
            self.accumulate();
        }
        let m = DMatrix::from_fn(k, k, |a, b| self.m[a.min(b) * k + a.max(b)]);
        m / (self.lags + 1) as f64
    }
}

/// [`bartlett_meat`] of the rows g_t[j] = `g(t, j)`, t < n, j < k, never stored (each value
/// asked for once).
pub(crate) fn bartlett_meat_with(
    n: usize,
    k: usize,
    lags: usize,
    g: impl Fn(usize, usize) -> f64,
) -> DMatrix<f64> {
    bartlett_meat_rows(n, k, lags, |t, out| {
        for (j, o) in out.iter_mut().enumerate() {
            *o = g(t, j);
        }
    })
}

impl Solver for Ols {
    fn name(&self) -> &str {
        "ols"
    }

    fn solve(&self, p: &LinearProblem<'_>) -> Result<LinearFit, SolveError> {
        check_problem(p)?;
        let d = decompose(p, self.rank_tol)?;
        let z = d.uty.component_div(&d.sv);
        let theta = (d.v_t.transpose() * z).component_div(&d.scales);
        let e = p.y - p.x * &theta;
        let cov = covariance(&d, p.x, &e, p.correlation_lags);
        Ok(LinearFit {
            std_err: cov.diagonal().map(|v| v.max(0.0).sqrt()),
            covariance: cov,
            rss: e.norm_squared(),
            n: p.x.nrows(),
            rank: d.rank,
            condition_number: d.cond,
            bound_state: vec![BoundState::Free; theta.len()],
            theta,
            status: SolveStatus::Solved,
        })
    }
}

/// A test problem of `n` rows: three columns of scales 1e3, 1e3 and 1e-2, the first two
/// nearly collinear (condition number > 1e3), y = X [0.5, −1.5, 40] plus a bounded
/// deterministic noise.
#[cfg(test)]
pub(crate) fn ill_scaled_problem(n: usize) -> (DMatrix<f64>, DVector<f64>) {
    let x = DMatrix::from_fn(n, 3, |t, j| {
        let s = t as f64 * 1e-3;
        match j {
            0 => 1e3 * (s.sin() + 1e-4 * (7.3 * s).cos()),
            1 => 1e3 * s.sin() + 0.3 * (3.1 * s).sin(),
            _ => 1e-2 * (0.7 * s).cos(),
        }
    });
    let noise = DVector::from_fn(n, |t, _| ((t * 7919) % 1009) as f64 / 1009.0 - 0.5);
    let y = &x * DVector::from_vec(vec![0.5, -1.5, 40.0]) + noise;
    (x, y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn moving_sums_equal_the_direct_bartlett_sum() {
        // The direct O(n k² L) sum of the Newey–West meat, against the moving-window form,
        // for lags shorter and longer than the data.
        let n = 57;
        let u = DMatrix::from_fn(n, 3, |t, j| ((t * 7 + j * 13) % 11) as f64 - 5.0);
        let e = DVector::from_fn(n, |t, _| ((t * 5) % 9) as f64 * 0.1 - 0.4);
        for lags in [1usize, 4, 20, 80] {
            let mut direct = DMatrix::<f64>::zeros(3, 3);
            for t in 0..n {
                for v in 0..n {
                    let l = t.abs_diff(v);
                    if l <= lags {
                        let w = 1.0 - l as f64 / (lags + 1) as f64;
                        for a in 0..3 {
                            for b in 0..3 {
                                direct[(a, b)] += w * u[(t, a)] * e[t] * u[(v, b)] * e[v];
                            }
                        }
                    }
                }
            }
            let g = DMatrix::from_fn(n, 3, |t, j| u[(t, j)] * e[t]);
            let fast = bartlett_meat(&g, lags);
            assert_relative_eq!(fast, direct, max_relative = 1e-12, epsilon = 1e-9);
            // The row-at-a-time form with its ring of the last L + 1 rows.
            let rows = bartlett_meat_rows(n, 3, lags, |t, out| {
                for (j, o) in out.iter_mut().enumerate() {
                    *o = g[(t, j)];
                }
            });
            assert_relative_eq!(rows, direct, max_relative = 1e-12, epsilon = 1e-9);
            // In runs of rows summed at once, each starting from the L rows before it.
            for parts in [1, 2, 3, 7] {
                let split = bartlett_meat_parts(n, 3, lags, parts, |t, out, _| {
                    for (j, o) in out.iter_mut().enumerate() {
                        *o = g[(t, j)];
                    }
                });
                assert_relative_eq!(split, direct, max_relative = 1e-12, epsilon = 1e-9);
            }
        }
    }

    #[test]
    fn blocked_qr_over_many_blocks_and_cores_matches_a_direct_svd() {
        // 200,003 rows (49 blocks, split between cores), columns of very different scales and
        // a condition number > 1e3: θ and the Newey–West covariance against one SVD of the
        // whole column-scaled X with U formed.
        let n = 200_003;
        let (x, y) = ill_scaled_problem(n);
        let names = ["a", "b", "c"];
        let lags = 12;
        let p = LinearProblem {
            x: &x,
            y: &y,
            names: &names,
            bounds: None,
            correlation_lags: lags,
        };
        let fit = Ols::default().solve(&p).expect("solves");
        // The previous implementation: SVD of the column-scaled X̃ with U formed.
        let d = column_scales(&x);
        let mut xs = x.clone();
        for (j, mut c) in xs.column_iter_mut().enumerate() {
            c /= d[j];
        }
        let svd = xs.svd(true, true);
        let theta = svd.solve(&y, 0.0).expect("solves").component_div(&d);
        let e = &y - &x * &theta;
        let u = svd.u.expect("u");
        let mut a = svd.v_t.expect("v").transpose();
        for (j, mut c) in a.column_iter_mut().enumerate() {
            c /= svd.singular_values[j];
        }
        for (i, mut r) in a.row_iter_mut().enumerate() {
            r /= d[i];
        }
        let g = DMatrix::from_fn(n, 3, |t, j| u[(t, j)] * e[t]);
        let cov = &a * bartlett_meat(&g, lags) * a.transpose() * (n as f64 / (n - 3) as f64);
        // θ from the normal equations in 80-bit long double (numpy, `np.longdouble`, the same
        // data): 0.5000018074559209, −1.500001809872624, 39.999660829533155 (LAPACK's
        // `lstsq` agrees to 5e-11). κ(X̃) ≈ 6.3e3 with two near-collinear columns: the SVD of
        // the scaled X (the previous implementation) is 2.7e-9 off in θ1, this 2.6e-9.
        assert!(fit.condition_number > 1e3, "{}", fit.condition_number);
        let reference = [0.5000018074559209, -1.500001809872624, 39.999660829533155];
        for (j, r) in reference.iter().enumerate() {
            assert_relative_eq!(fit.theta[j], *r, max_relative = 5e-9);
            assert_relative_eq!(theta[j], *r, max_relative = 5e-9);
        }
        assert_relative_eq!(fit.covariance, cov, max_relative = 1e-6);
    }

    #[test]
    fn fits_a_line_through_three_points_with_textbook_errors() {
        // y = a + b x through (0,1), (1,2), (2,4): b = 1.5, a = 5/6; RSS = 1/6,
        // σ² = 1/6, Var(b) = σ²/Σ(x − x̄)² = 1/12, Var(a) = σ²(1/3 + 1/2) = 5/36.
        let x = DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 1.0, 1.0, 1.0, 2.0]);
        let y = DVector::from_vec(vec![1.0, 2.0, 4.0]);
        let p = LinearProblem {
            x: &x,
            y: &y,
            names: &["a", "b"],
            bounds: None,
            correlation_lags: 0,
        };
        let f = Ols::default().solve(&p).expect("solves");
        assert_relative_eq!(f.theta[0], 5.0 / 6.0, max_relative = 1e-12);
        assert_relative_eq!(f.theta[1], 1.5, max_relative = 1e-12);
        assert_relative_eq!(f.rss, 1.0 / 6.0, max_relative = 1e-12);
        assert_relative_eq!(f.std_err[1], (1.0f64 / 12.0).sqrt(), max_relative = 1e-12);
        assert_relative_eq!(f.std_err[0], (5.0f64 / 36.0).sqrt(), max_relative = 1e-12);
    }

    #[test]
    fn rank_deficiency_names_the_inseparable_parameters() {
        // Column 0 constant zero (ω̇ of a constant ω), columns 1, 2 independent.
        let n = 50;
        let x = DMatrix::from_fn(n, 3, |i, j| match j {
            0 => 0.0,
            1 => (i as f64 * 0.1).sin(),
            _ => 1.0,
        });
        let y = DVector::from_fn(n, |i, _| i as f64);
        let p = LinearProblem {
            x: &x,
            y: &y,
            names: &["theta2", "theta5", "theta6"],
            bounds: None,
            correlation_lags: 0,
        };
        match Ols::default().solve(&p) {
            Err(SolveError::RankDeficient { names, rank, p }) => {
                assert_eq!(names, vec!["theta2".to_owned()]);
                assert_eq!((rank, p), (2, 3));
            }
            other => panic!("expected rank deficiency, got {other:?}"),
        }
        // Two proportional columns: both named.
        let x = DMatrix::from_fn(n, 2, |i, j| (i as f64 + 1.0) * (j as f64 + 1.0));
        let p = LinearProblem {
            x: &x,
            y: &y,
            names: &["a", "b"],
            bounds: None,
            correlation_lags: 0,
        };
        assert!(
            matches!(Ols::default().solve(&p), Err(SolveError::RankDeficient { names, .. }) if names.len() == 2)
        );
    }

    #[test]
    fn newey_west_matches_the_textbook_sum_for_a_mean() {
        // For x = 1 (estimating a mean): Var = n/(n−1) · (1/n²) Σ_{|l|≤L} w_l Σ_t e_t e_{t+l},
        // w_l = 1 − |l|/(L+1). Residuals that repeat in blocks widen the error.
        let n = 1000;
        let lags = 10;
        let x = DMatrix::from_fn(n, 1, |_, _| 1.0);
        let y = DVector::from_fn(n, |i, _| ((i / 10) * 7919 % 13) as f64 - 6.0);
        let p0 = LinearProblem {
            x: &x,
            y: &y,
            names: &["c"],
            bounds: None,
            correlation_lags: 0,
        };
        let p1 = LinearProblem {
            correlation_lags: lags,
            ..p0
        };
        let f0 = Ols::default().solve(&p0).expect("ok");
        let f1 = Ols::default().solve(&p1).expect("ok");
        let e: Vec<f64> = y.iter().map(|v| v - f1.theta[0]).collect();
        let mut s = e.iter().map(|v| v * v).sum::<f64>();
        for l in 1..=lags {
            let w = 1.0 - l as f64 / (lags + 1) as f64;
            s += 2.0 * w * (0..n - l).map(|t| e[t] * e[t + l]).sum::<f64>();
        }
        let var = s / (n * n) as f64 * n as f64 / (n - 1) as f64;
        assert_relative_eq!(f1.std_err[0], var.sqrt(), max_relative = 1e-10);
        assert!(f1.std_err[0] > 2.0 * f0.std_err[0]);
    }
}
