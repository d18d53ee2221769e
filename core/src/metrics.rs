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
}
