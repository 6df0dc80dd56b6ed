//! Monte Carlo statistics from batch values: means, standard errors, figure of merit.
//!
//! Tallies keep, for every bin, the running mean and the running sum of squared deviations M2
//! of the batch values, updated batch by batch in batch order (Welford 1962, Technometrics 4,
//! 419; Knuth TAOCP 2, 4.2.2). Unlike raw sums Σx and Σx², this does not lose the variance of a
//! nearly deterministic tally (a hard-target return) to cancellation. With n batch values (each
//! an estimate of the quantity) the standard error of the mean is √(M2/(n(n − 1))); with n < 2
//! there is no error bar (NaN).

/// Fold batch value `x` into a running mean and M2; `n` is the count including `x`.
#[inline]
pub fn welford_add(mean: &mut f64, m2: &mut f64, n: usize, x: f64) {
    let delta = x - *mean;
    *mean += delta / n as f64;
    *m2 += delta * (x - *mean);
}

/// Standard error of the mean of n batch values from their M2.
pub fn std_error(m2: f64, n: usize) -> f64 {
    if n < 2 {
        return f64::NAN;
    }
    let nf = n as f64;
    (m2.max(0.0) / (nf * (nf - 1.0))).sqrt()
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

    fn fold(xs: &[f64]) -> (f64, f64) {
        let (mut m, mut m2) = (0.0, 0.0);
        for (i, x) in xs.iter().enumerate() {
            welford_add(&mut m, &mut m2, i + 1, *x);
        }
        (m, m2)
    }

    #[test]
    fn standard_error_of_known_sample() {
        // x = 1, 2, 3, 4: mean 2.5, sample variance 5/3, SE = sqrt(5/12).
        let (m, m2) = fold(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(m, 2.5);
        assert!((std_error(m2, 4) - (5.0f64 / 12.0).sqrt()).abs() < 1e-15);
        assert!(std_error(0.0, 1).is_nan());
        // A nearly constant tally keeps its tiny variance (raw sums would give exactly 0):
        // 1 + {0, 2e-12, 0, 2e-12}: sample variance 4/3 e-24.
        let (_, m2) = fold(&[1.0, 1.0 + 2e-12, 1.0, 1.0 + 2e-12]);
        let expect = (4.0 / 3.0e24 / 4.0f64).sqrt();
        assert!(
            (std_error(m2, 4) / expect - 1.0).abs() < 1e-3,
            "{}",
            std_error(m2, 4)
        );
        assert!((figure_of_merit(0.1, 2.0) - 50.0).abs() < 1e-12);
        assert_eq!(figure_of_merit(rel_err(0.0, 1.0), 1.0), 0.0);
    }
}
