//! Sensitivities by forward differences, for stages without sensitivity equations (the
//! traction stage, [`super::traction`]): each column of θ and of the initial state is one more
//! simulation, run on the rayon pool.

use wheelid_core::{DynamicModel, Error, Recording, Result, Sensitivities, Simulation};

use super::{Extended, guarded};

impl Extended {
    /// [`Extended::sensitivities_of`] by forward differences of [`DynamicModel::simulate`] in
    /// every column and in the initial state (the traction stage has no sensitivity
    /// equations): steps 1e-5 (|β| + 10⁻³ max|θ1…6|) for θ, 1e-5 (|x0| + 10⁻³) for x0; one
    /// task of the rayon pool per column.
    pub(super) fn differenced(
        &self,
        theta: &[f64],
        rec: &Recording,
        initial: &[f64],
        columns: &[usize],
    ) -> Result<(Simulation, Sensitivities)> {
        let scale = theta[..6].iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let step = |j: usize| 1e-5 * (theta[j].abs() + 1e-3 * scale);
        let step0 = |i: usize| 1e-5 * (initial[i].abs() + 1e-3);
        let moved = |j: Option<usize>, i: Option<usize>| -> Result<Simulation> {
            let mut th = theta.to_vec();
            let mut x0 = initial.to_vec();
            if let Some(j) = j {
                th[j] += step(j);
            }
            if let Some(i) = i {
                x0[i] += step0(i);
            }
            self.simulate(&th, rec, &x0)
        };
        let jobs: Vec<(Option<usize>, Option<usize>)> = std::iter::once((None, None))
            .chain(columns.iter().map(|&j| (Some(j), None)))
            .chain((0..initial.len()).map(|i| (None, Some(i))))
            .collect();
        // On the pool's threads (no thread of its own per column: an excerpt's windows are
        // short, and already shared out), collected in order; a simulation that panics (inside
        // a model) is an error.
        use rayon::prelude::*;
        let mut sims = jobs
            .par_iter()
            .map(|&(j, i)| guarded(|| moved(j, i)))
            .collect::<Result<Vec<_>>>()?
            .into_iter();
        let y = sims
            .next()
            .ok_or_else(|| Error::InvalidSetting("no simulation".into()))?;
        let n = rec.len();
        let mut diff = |h: f64| -> Result<[Vec<f64>; 2]> {
            let up = sims
                .next()
                .ok_or_else(|| Error::InvalidSetting("missing difference".into()))?;
            Ok([0, 1].map(|c| (0..n).map(|k| (up[c][k] - y[c][k]) / h).collect()))
        };
        let mut theta_cols = [
            nalgebra::DMatrix::zeros(n, columns.len()),
            nalgebra::DMatrix::zeros(n, columns.len()),
        ];
        for (a, &j) in columns.iter().enumerate() {
            let d = diff(step(j))?;
            for c in 0..2 {
                theta_cols[c].set_column(a, &nalgebra::DVector::from_column_slice(&d[c]));
            }
        }
        let mut initial_cols = [
            nalgebra::DMatrix::zeros(n, initial.len()),
            nalgebra::DMatrix::zeros(n, initial.len()),
        ];
        for i in 0..initial.len() {
            let d = diff(step0(i))?;
            for c in 0..2 {
                initial_cols[c].set_column(i, &nalgebra::DVector::from_column_slice(&d[c]));
            }
        }
        let [tv, tw] = theta_cols;
        let [iv, iw] = initial_cols;
        Ok((
            y,
            Sensitivities {
                theta: vec![tv, tw],
                initial: vec![iv, iw],
            },
        ))
    }
}
