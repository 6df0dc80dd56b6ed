//! Monte Carlo statistics from batch moments: means, standard errors, figure of merit.
//!
//! Tallies keep, for every bin, the sum and the sum of squares of the batch values (OpenMC's
//! raw moments). With n batches of equal size and batch values x_i (each already an estimate of
//! the quantity), mean = Σx/n and the standard error of the mean is
//! √[(Σx²/n − mean²)/(n − 1)]. Rows with n < 2 get no error bar (reported as NaN); a negative
//! variance from rounding is clamped to zero.

/// Mean of n batch values from their sum.
pub fn mean(sum: f64, n: usize) -> f64 {
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// Standard error of the mean from the batch sum and sum of squares.
pub fn std_error(sum: f64, sum_sq: f64, n: usize) -> f64 {
    if n < 2 {
        return f64::NAN;
    }
    let nf = n as f64;
    let m = sum / nf;
    let var = (sum_sq / nf - m * m).max(0.0) * nf / (nf - 1.0);
    (var / nf).sqrt()
}

/// Relative error σ_mean/|mean|; infinite where the mean is zero (no score).
pub fn rel_err(mean: f64, std_error: f64) -> f64 {
    if mean == 0.0 {
        f64::INFINITY
    } else {
        std_error / mean.abs()
    }
}

/// Figure of merit 1/(rel_err² · wall_s), wall-clock seconds (MCNP uses CPU time; we report
/// wall-clock at a stated thread count). Zero where the relative error is infinite.
pub fn figure_of_merit(rel_err: f64, wall_s: f64) -> f64 {
    if rel_err.is_finite() && rel_err > 0.0 && wall_s > 0.0 {
        1.0 / (rel_err * rel_err * wall_s)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standard_error_of_known_sample() {
        // x = 1, 2, 3, 4: mean 2.5, sample variance 5/3, SE = sqrt(5/12).
        let xs = [1.0, 2.0, 3.0, 4.0];
        let s: f64 = xs.iter().sum();
        let s2: f64 = xs.iter().map(|x| x * x).sum();
        assert_eq!(mean(s, 4), 2.5);
        assert!((std_error(s, s2, 4) - (5.0f64 / 12.0).sqrt()).abs() < 1e-15);
        assert!(std_error(1.0, 1.0, 1).is_nan());
        assert!((figure_of_merit(0.1, 2.0) - 50.0).abs() < 1e-12);
        assert_eq!(figure_of_merit(rel_err(0.0, 1.0), 1.0), 0.0);
    }
}
