//! Goodness-of-fit measures.
//!
//! * fit % (MATLAB `compare`, Ljung): 100 · (1 − ‖y − ŷ‖ / ‖y − ȳ‖) = 100 · (1 − NRMSE).
//! * R² (coefficient of determination): 1 − ‖y − ŷ‖² / ‖y − ȳ‖².

fn norms(y: &[f64], yhat: &[f64]) -> (f64, f64) {
    let n = y.len().min(yhat.len());
    let mean = y[..n].iter().sum::<f64>() / n.max(1) as f64;
    let err: f64 = y[..n].iter().zip(yhat).map(|(a, b)| (a - b).powi(2)).sum();
    let tot: f64 = y[..n].iter().map(|a| (a - mean).powi(2)).sum();
    (err, tot)
}

/// Fit % = 100·(1 − ‖y − ŷ‖/‖y − mean(y)‖); 100 is perfect, 0 is no better than the mean, and it
/// can be negative. NaN if y is constant.
pub fn fit_percent(y: &[f64], yhat: &[f64]) -> f64 {
    let (err, tot) = norms(y, yhat);
    if tot == 0.0 {
        return f64::NAN;
    }
    100.0 * (1.0 - (err / tot).sqrt())
}

/// [`fit_percent`] of the series end to end, without joining them: `parts` are (y, ŷ) pairs
/// (each pair's common length counts), summed in the order a joined series would be (so one
/// part gives [`fit_percent`] bit for bit).
pub fn fit_percent_parts(parts: &[(&[f64], &[f64])]) -> f64 {
    let lens = || parts.iter().map(|(y, yhat)| y.len().min(yhat.len()));
    let n: usize = lens().sum();
    let sum = parts.iter().zip(lens()).fold(0.0, |acc, ((y, _), m)| {
        y[..m].iter().fold(acc, |a, v| a + v)
    });
    let mean = sum / n.max(1) as f64;
    let (mut err, mut tot) = (0.0, 0.0);
    for ((y, yhat), m) in parts.iter().zip(lens()) {
        err = y[..m]
            .iter()
            .zip(*yhat)
            .fold(err, |a, (y, f)| a + (y - f).powi(2));
        tot = y[..m].iter().fold(tot, |a, y| a + (y - mean).powi(2));
    }
    if tot == 0.0 {
        return f64::NAN;
    }
    100.0 * (1.0 - (err / tot).sqrt())
}

/// R² = 1 − ‖y − ŷ‖²/‖y − mean(y)‖². NaN if y is constant.
pub fn r_squared(y: &[f64], yhat: &[f64]) -> f64 {
    let (err, tot) = norms(y, yhat);
    if tot == 0.0 {
        return f64::NAN;
    }
    1.0 - err / tot
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_form_values() {
        let y = [1.0, 2.0, 3.0];
        assert_eq!(fit_percent(&y, &y), 100.0);
        assert_eq!(fit_percent(&y, &[2.0, 2.0, 2.0]), 0.0);
        // error norm 1, total norm √2
        approx::assert_relative_eq!(
            fit_percent(&y, &[1.0, 2.0, 4.0]),
            100.0 * (1.0 - 1.0 / 2f64.sqrt()),
            max_relative = 1e-12
        );
        approx::assert_relative_eq!(r_squared(&y, &[1.0, 2.0, 4.0]), 0.5);
        assert!(fit_percent(&[1.0, 1.0], &[1.0, 2.0]).is_nan());
    }

    #[test]
    fn fit_over_parts_is_the_fit_of_the_joined_series() {
        let (y1, f1) = ([1.0, 2.0, 3.0], [1.1, 1.9, 3.3]);
        let (y2, f2) = ([0.5, -1.0], [0.4, -0.7]);
        let joined = fit_percent(&[1.0, 2.0, 3.0, 0.5, -1.0], &[1.1, 1.9, 3.3, 0.4, -0.7]);
        assert_eq!(fit_percent_parts(&[(&y1, &f1), (&y2, &f2)]), joined);
        assert_eq!(fit_percent_parts(&[(&y1, &f1)]), fit_percent(&y1, &f1));
        assert!(fit_percent_parts(&[(&[2.0], &[1.0]), (&[2.0], &[3.0])]).is_nan());
    }
}
