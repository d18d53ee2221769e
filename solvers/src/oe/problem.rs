//! The output-error least-squares problem in the minimiser's variables u = (u_θ, x0_1, …):
//! its residuals (one simulation per recording), its normal equations (one simulation with
//! sensitivities, summed without forming the Jacobian) and, at θ̂, its Jacobian.

use std::cell::RefCell;

use nalgebra::{DMatrix, DVector};
use wheelid_core::{DynamicModel, Recording, Sensitivities, Simulation};

use super::lm::NormalProblem;
use super::transform::Transform;

/// Raw residuals y − ŷ per recording and channel, every sample.
pub(super) type Raw = Vec<Vec<Vec<f64>>>;

/// One evaluation of the problem: the simulations (per recording, ŷ per channel) and the raw
/// residuals y − ŷ.
pub(super) struct Evaluated {
    pub raw: Raw,
    pub sims: Vec<Simulation>,
}

/// One central-difference column: parameter index, step, outputs at +step and −step.
type FdColumn = (usize, f64, Vec<Vec<f64>>, Vec<Vec<f64>>);

/// Rows of the normal equations summed per task (a fixed split: the sums, and so θ̂, are the
/// same bits whatever the number of threads).
const GRAM_CHUNK: usize = 8192;

/// The output-error problem: parameters u = (u_θ, x0_1, …).
pub(super) struct Problem<'a, M: ?Sized> {
    pub model: &'a M,
    pub recs: &'a [Recording],
    /// 1/σ_c per channel.
    pub weight: Vec<f64>,
    pub transform: Vec<Transform>,
    /// Initial states when they are not estimated.
    pub fixed_initial: Option<Vec<Vec<f64>>>,
    /// The start.
    pub u0: DVector<f64>,
    /// Offsets of each recording's rows (its samples in the cost, both channels).
    pub offsets: Vec<usize>,
    /// Per recording, the samples that enter the cost (the mask's), in time order: row
    /// `offsets[r] + i·s + c` is sample `index[r][i]`, channel c.
    pub index: Vec<Vec<usize>>,
    /// Per recording, whether each sample enters the cost.
    pub mask: Vec<Vec<bool>>,
    /// Forward instead of central differences.
    pub forward: bool,
    pub rows: usize,
    /// The last sensitivities (per recording) and the u they were taken at: a new pass at the
    /// same u and the covariance at θ̂ use them.
    pub last_sensitivities: RefCell<Option<(DVector<f64>, Vec<Sensitivities>)>>,
}

/// The measured output columns of a recording, in channel order (v, ω).
pub(super) fn measured(rec: &Recording) -> [&[f64]; 2] {
    [&rec.v, &rec.w]
}

impl<M: DynamicModel + ?Sized> Problem<'_, M> {
    pub fn p(&self) -> usize {
        self.transform.len()
    }
    pub fn nch(&self) -> usize {
        self.model.channels().len()
    }
    /// Unknowns: θ, then each recording's initial state when estimated.
    pub fn unknowns(&self) -> usize {
        self.u0.len()
    }
    pub fn theta_of(&self, u: &DVector<f64>) -> Vec<f64> {
        self.transform
            .iter()
            .zip(u.iter())
            .map(|(t, &x)| t.theta(x))
            .collect()
    }
    pub fn initial_of(&self, u: &DVector<f64>, r: usize) -> Vec<f64> {
        match &self.fixed_initial {
            Some(x) => x[r].clone(),
            None => {
                let (p, s) = (self.p(), self.nch());
                u.as_slice()[p + r * s..p + (r + 1) * s].to_vec()
            }
        }
    }
    /// The simulations at u and the unweighted residuals y − ŷ per recording and channel, or
    /// `None` if a simulation failed or diverged.
    pub fn evaluated(&self, u: &DVector<f64>) -> Option<Evaluated> {
        let theta = self.theta_of(u);
        let model = self.model;
        let sims = self.per_recording(u, |rec, x0| model.simulate(&theta, rec, x0).ok())?;
        self.residuals_of(sims)
    }

    /// `run` on every recording with its initial state at u, the recordings shared out over
    /// the available cores (a long recording searched on an excerpt is many short ones),
    /// the results in recording order; `None` if one is.
    fn per_recording<T: Send>(
        &self,
        u: &DVector<f64>,
        run: impl Fn(&Recording, &[f64]) -> Option<T> + Sync,
    ) -> Option<Vec<T>> {
        use rayon::prelude::*;
        let x0: Vec<Vec<f64>> = (0..self.recs.len())
            .map(|r| self.initial_of(u, r))
            .collect();
        self.recs
            .par_iter()
            .zip(&x0)
            .map(|(rec, x0)| run(rec, x0))
            .collect()
    }

    /// The residuals y − ŷ of the simulations `sims` (one per recording), or `None` if one is
    /// not finite or not as long as its recording.
    fn residuals_of(&self, sims: Vec<Simulation>) -> Option<Evaluated> {
        let mut out = Vec::with_capacity(self.recs.len());
        for (rec, sim) in self.recs.iter().zip(&sims) {
            let meas = measured(rec);
            let mut per = Vec::with_capacity(sim.len());
            for (c, y) in sim.iter().enumerate() {
                if y.len() != rec.len() || y.iter().any(|x| !x.is_finite()) {
                    return None;
                }
                per.push(meas[c].iter().zip(y).map(|(m, s)| m - s).collect());
            }
            out.push(per);
        }
        Some(Evaluated { raw: out, sims })
    }

    /// [`Problem::evaluated`] from the model's simulation with sensitivities, which are kept for
    /// the normal equations at u (the same outputs: the state is integrated by the same
    /// steps); `None` where the model has no sensitivities or a simulation fails (the caller
    /// then simulates alone).
    fn evaluated_with_sensitivities(&self, u: &DVector<f64>) -> Option<Evaluated> {
        let theta = self.theta_of(u);
        self.last_sensitivities.replace(None);
        let model = self.model;
        let (sims, all): (Vec<Simulation>, Vec<Sensitivities>) = self
            .per_recording(u, |rec, x0| {
                let (sim, sens) = model.simulate_with_sensitivities(&theta, rec, x0).ok()??;
                let finite = |m: &DMatrix<f64>| m.iter().all(|x| x.is_finite());
                (sens.theta.iter().all(finite) && sens.initial.iter().all(finite))
                    .then_some((sim, sens))
            })?
            .into_iter()
            .unzip();
        let point = self.residuals_of(sims)?;
        self.last_sensitivities.replace(Some((u.clone(), all)));
        Some(point)
    }

    /// The weighted residual rows of `raw`: the cost's rows in order.
    pub fn weighted_rows(&self, raw: &Raw) -> DVector<f64> {
        let s = self.nch();
        let mut e = DVector::zeros(self.rows);
        for (r, per) in raw.iter().enumerate() {
            for (c, ec) in per.iter().enumerate() {
                for (i, &k) in self.index[r].iter().enumerate() {
                    e[self.offsets[r] + i * s + c] = self.weight[c] * ec[k];
                }
            }
        }
        e
    }
    /// Runs of consecutive samples in the cost, as (first row, samples): the lags of the
    /// long-run covariance stay inside them.
    pub fn spans(&self) -> Vec<(usize, usize)> {
        let s = self.nch();
        let mut spans: Vec<(usize, usize)> = Vec::new();
        for (&o, ix) in self.offsets.iter().zip(&self.index) {
            for (i, &k) in ix.iter().enumerate() {
                match spans.last_mut() {
                    Some((start, n))
                        if i > 0 && ix[i - 1] + 1 == k && *start + *n * s == o + i * s =>
                    {
                        *n += 1
                    }
                    _ => spans.push((o + i * s, 1)),
                }
            }
        }
        spans
    }
    /// ∂ŷ/∂θ and ∂ŷ/∂x0 of every recording at u, into the cache: the cached ones when they
    /// were taken within `reuse` ‖u‖ of u (0: at u exactly), else new ones (forward
    /// differences start from `sims`, the simulations at u); `None` if a simulation fails or a
    /// value is not finite.
    pub fn sensitivities_at(
        &self,
        u: &DVector<f64>,
        reuse: f64,
        sims: &[Simulation],
    ) -> Option<()> {
        let near = |at: &DVector<f64>| at == u || (at - u).norm() <= reuse * u.norm();
        if matches!(&*self.last_sensitivities.borrow(), Some((at, _)) if near(at)) {
            return Some(());
        }
        // Not held through the peak of the new ones.
        self.last_sensitivities.replace(None);
        let theta = self.theta_of(u);
        let mut all = Vec::with_capacity(self.recs.len());
        for (r, rec) in self.recs.iter().enumerate() {
            let sens = self.sensitivities(&theta, &self.initial_of(u, r), rec, sims.get(r))?;
            let finite = |m: &DMatrix<f64>| m.iter().all(|x| x.is_finite());
            if !(sens.theta.iter().all(finite) && sens.initial.iter().all(finite)) {
                return None;
            }
            all.push(sens);
        }
        self.last_sensitivities.replace(Some((u.clone(), all)));
        Some(())
    }
    /// ∂ŷ/∂θ and ∂ŷ/∂x0 of recording `rec` (per channel n × p and n × s), the model's own
    /// when it has them (used as returned, not copied), else by differences.
    fn sensitivities(
        &self,
        theta: &[f64],
        x0: &[f64],
        rec: &Recording,
        cached: Option<&Simulation>,
    ) -> Option<Sensitivities> {
        if let Ok(Some((_, sens))) = self.model.simulate_with_sensitivities(theta, rec, x0) {
            return Some(sens);
        }
        self.difference_sensitivities(theta, x0, rec, cached)
    }
    /// Central differences (forward ones when asked, from the `cached` simulation at θ), step
    /// ~ 1e-5 relative (above the integrator's sub-step jitter), the columns shared out over
    /// the available cores.
    fn difference_sensitivities(
        &self,
        theta: &[f64],
        x0: &[f64],
        rec: &Recording,
        cached: Option<&Simulation>,
    ) -> Option<Sensitivities> {
        let (p, s, n) = (self.p(), self.nch(), rec.len());
        let scale = theta.iter().fold(0.0f64, |a, x| a.max(x.abs())).max(1e-12);
        let owned;
        let base_sim = match (self.forward, cached) {
            (true, Some(sim)) => Some(sim),
            (true, None) => {
                owned = self.model.simulate(theta, rec, x0).ok()?;
                Some(&owned)
            }
            (false, _) => None,
        };
        let column = |j: usize| -> Option<FdColumn> {
            let mut th = theta.to_vec();
            let mut x = x0.to_vec();
            let base = if j < p { th[j] } else { x[j - p] };
            let h = 1e-5 * (base.abs() + 1e-3 * scale);
            let mut eval = |delta: f64| {
                if j < p {
                    th[j] = base + delta;
                } else {
                    x[j - p] = base + delta;
                }
                self.model.simulate(&th, rec, &x).ok()
            };
            let up = eval(h)?;
            match &base_sim {
                // (up − base)/h written as (up − dn)/(2h) with dn = 2 base − up.
                Some(b) => {
                    let dn = up
                        .iter()
                        .zip(b.iter())
                        .map(|(u, b)| u.iter().zip(b).map(|(u, b)| 2.0 * b - u).collect())
                        .collect();
                    Some((j, h, up, dn))
                }
                None => Some((j, h, up, eval(-h)?)),
            }
        };
        // On the pool's threads, in column order; a column whose simulation panicked (inside
        // a model) counts as a failed simulation.
        use rayon::prelude::*;
        let done: Vec<Option<FdColumn>> = (0..p + s)
            .into_par_iter()
            .map(|j| {
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| column(j)))
                    .ok()
                    .flatten()
            })
            .collect();
        let mut out = Sensitivities {
            theta: vec![DMatrix::zeros(n, p); s],
            initial: vec![DMatrix::zeros(n, s); s],
        };
        for item in done {
            let (j, h, up, dn) = item?;
            for c in 0..s {
                let (m, col) = if j < p {
                    (&mut out.theta[c], j)
                } else {
                    (&mut out.initial[c], j - p)
                };
                for k in 0..n {
                    m[(k, col)] = (up[c][k] - dn[c][k]) / (2.0 * h);
                }
            }
        }
        Some(out)
    }
    /// Columns of the Jacobian: θ's, then the estimated initial states.
    pub fn columns(&self) -> usize {
        self.p()
            + self
                .fixed_initial
                .as_ref()
                .map_or(self.nch() * self.recs.len(), |_| 0)
    }
    /// The weighted Jacobian of the residuals with respect to (θ, x0) — not u — time-major
    /// rows, from the sensitivities at u (the cached ones if taken within `reuse` ‖u‖; `sims`
    /// are the simulations at u).
    pub fn jacobian_theta(
        &self,
        u: &DVector<f64>,
        reuse: f64,
        sims: &[Simulation],
    ) -> Option<DMatrix<f64>> {
        self.sensitivities_at(u, reuse, sims)?;
        let (p, s) = (self.p(), self.nch());
        let mut jac = DMatrix::zeros(self.rows, self.columns());
        let cache = self.last_sensitivities.borrow();
        let (_, all) = cache.as_ref()?;
        for (r, sens) in all.iter().enumerate() {
            let channels = sens.theta.iter().zip(&sens.initial).zip(&self.weight);
            // Column by column (both matrices are column-major): row offsets[r] + i·s + c of
            // column j is −w_c ∂ŷ_c(t_k)/∂(θ, x0)_j, k = index[r][i].
            for (c, ((st, si), &w)) in channels.enumerate() {
                let mut fill = |col: usize, src: &[f64]| {
                    let dst = &mut jac.column_mut(col);
                    for (i, &k) in self.index[r].iter().enumerate() {
                        dst[self.offsets[r] + i * s + c] = -w * src[k];
                    }
                };
                let n = st.nrows();
                for j in 0..p {
                    fill(j, &st.as_slice()[j * n..(j + 1) * n]);
                }
                if self.fixed_initial.is_none() {
                    for i in 0..s {
                        fill(p + r * s + i, &si.as_slice()[i * n..(i + 1) * n]);
                    }
                }
            }
        }
        Some(jac)
    }
    /// JᵀJ and Jᵀe in u of the weighted residuals `raw`, from the cached sensitivities at u,
    /// recording by recording and channel by channel (module doc of [`super::lm`]).
    fn normal_equations_at(&self, u: &DVector<f64>, raw: &Raw) -> (DMatrix<f64>, DVector<f64>) {
        let (p, s, cols) = (self.p(), self.nch(), self.columns());
        let mut a = DMatrix::zeros(cols, cols);
        let mut g = DVector::zeros(cols);
        let cache = self.last_sensitivities.borrow();
        let Some((_, all)) = cache.as_ref() else {
            return (a, g);
        };
        // dθ/du for the θ columns; the x0 columns are u's own.
        let chain: Vec<f64> = (0..p).map(|j| self.transform[j].dtheta_du(u[j])).collect();
        for (r, sens) in all.iter().enumerate() {
            // Global column of each local one (θ…, then this recording's x0 when estimated).
            let mut global: Vec<usize> = (0..p).collect();
            if self.fixed_initial.is_none() {
                global.extend((0..s).map(|i| p + r * s + i));
            }
            for (c, (st, si)) in sens.theta.iter().zip(&sens.initial).enumerate() {
                let n = st.nrows();
                let mut locals: Vec<&[f64]> =
                    (0..p).map(|j| &st.as_slice()[j * n..(j + 1) * n]).collect();
                if self.fixed_initial.is_none() {
                    locals.extend((0..s).map(|i| &si.as_slice()[i * n..(i + 1) * n]));
                }
                let (la, lg) = gram(&locals, &raw[r][c], &self.index[r]);
                // J = −w ∂ŷ/∂(θ, x0)·chain, e = w·raw: JᵀJ = w² chain² Σ s sᵀ, Jᵀe = −w² chain Σ s·raw.
                let w2 = self.weight[c] * self.weight[c];
                let factor = |a: usize| if a < p { chain[a] } else { 1.0 };
                let m = locals.len();
                for a_ in 0..m {
                    g[global[a_]] -= w2 * factor(a_) * lg[a_];
                    for b_ in 0..m {
                        let (lo, hi) = (a_.min(b_), a_.max(b_));
                        a[(global[a_], global[b_])] +=
                            w2 * factor(a_) * factor(b_) * la[lo * m + hi];
                    }
                }
            }
        }
        (a, g)
    }
}

/// Residual rows from which a trial point is simulated with its sensitivities
/// ([`NormalProblem::evaluate`]): a 1e6-sample fit's, not its head's.
const OPTIMISTIC_ROWS: usize = 400_000;

/// Σ_k s_k s_kᵀ (upper triangle, row-major m × m) and Σ_k s_k e_k over the samples `index`,
/// s_k = (cols[0][k], …): on the available cores in fixed chunks summed in order.
fn gram(cols: &[&[f64]], e: &[f64], index: &[usize]) -> (Vec<f64>, Vec<f64>) {
    use rayon::prelude::*;
    let m = cols.len();
    let parts: Vec<(Vec<f64>, Vec<f64>)> = index
        .par_chunks(GRAM_CHUNK)
        .map(|chunk| match m {
            6 => gram_chunk::<6>(cols, e, chunk),
            8 => gram_chunk::<8>(cols, e, chunk),
            _ => gram_chunk_any(cols, e, chunk),
        })
        .collect();
    let (mut a, mut g) = (vec![0.0; m * m], vec![0.0; m]);
    for (pa, pg) in parts {
        a.iter_mut().zip(pa).for_each(|(x, y)| *x += y);
        g.iter_mut().zip(pg).for_each(|(x, y)| *x += y);
    }
    (a, g)
}

/// One chunk of [`gram`] for m = M columns, in registers: the same operations in the same
/// order as [`gram_chunk_any`].
fn gram_chunk<const M: usize>(cols: &[&[f64]], e: &[f64], chunk: &[usize]) -> (Vec<f64>, Vec<f64>) {
    let cols: &[&[f64]; M] = cols.try_into().expect("M columns");
    let (mut a, mut g) = ([[0.0; M]; M], [0.0; M]);
    for &k in chunk {
        let row: [f64; M] = std::array::from_fn(|i| cols[i][k]);
        for i in 0..M {
            let ri = row[i];
            g[i] += ri * e[k];
            for j in i..M {
                a[i][j] += ri * row[j];
            }
        }
    }
    (a.iter().flatten().copied().collect(), g.to_vec())
}

/// One chunk of [`gram`], any number of columns.
fn gram_chunk_any(cols: &[&[f64]], e: &[f64], chunk: &[usize]) -> (Vec<f64>, Vec<f64>) {
    let m = cols.len();
    let (mut a, mut g, mut row) = (vec![0.0; m * m], vec![0.0; m], vec![0.0; m]);
    for &k in chunk {
        for (x, c) in row.iter_mut().zip(cols) {
            *x = c[k];
        }
        for i in 0..m {
            let ri = row[i];
            g[i] += ri * e[k];
            for j in i..m {
                a[i * m + j] += ri * row[j];
            }
        }
    }
    (a, g)
}

impl<M: DynamicModel + ?Sized> NormalProblem for Problem<'_, M> {
    type Point = Evaluated;

    /// A long problem's point is simulated with its sensitivities at once (module doc of
    /// [`super`], *Long recordings*): near the optimum nearly every step is taken, and the
    /// normal equations there then need no second integration of the state.
    fn evaluate(&self, u: &DVector<f64>) -> Option<Evaluated> {
        if self.rows >= OPTIMISTIC_ROWS
            && let Some(point) = self.evaluated_with_sensitivities(u)
        {
            return Some(point);
        }
        self.evaluated(u)
    }

    fn cost(&self, point: &Evaluated) -> f64 {
        let mut f = 0.0;
        for (r, per) in point.raw.iter().enumerate() {
            for (c, ec) in per.iter().enumerate() {
                let w2 = self.weight[c] * self.weight[c];
                f += w2 * self.index[r].iter().map(|&k| ec[k] * ec[k]).sum::<f64>();
            }
        }
        f
    }

    fn normal_equations(
        &self,
        u: &DVector<f64>,
        point: &Evaluated,
    ) -> Option<(DMatrix<f64>, DVector<f64>)> {
        self.sensitivities_at(u, 0.0, &point.sims)?;
        Some(self.normal_equations_at(u, &point.raw))
    }
}
