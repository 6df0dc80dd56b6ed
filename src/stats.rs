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

/// The greatest power of two ≤ |x|, at least the smallest normal number (so that dividing by
/// it is exact and never overflows); 0 for 0.
#[inline]
fn power_of_two_scale(x: f64) -> f64 {
    let a = x.abs();
    if a == 0.0 || !a.is_finite() {
        return a;
    }
    // The exponent bits alone: a power of two, no rounding.
    f64::from_bits(a.to_bits() & 0x7ff0_0000_0000_0000).max(f64::MIN_POSITIVE)
}

/// [`welford_add`] with M2 kept in units of `scale`², a power of two within a factor 2 of the
/// largest |x| seen (raised, and M2 rescaled exactly, when a larger value comes): the variance
/// of tallies far below 1e-154 (returns from deep in an optically thick cloud) would otherwise
/// underflow to a standard error of exactly 0 while the values still scatter. Where nothing
/// underflows the result equals [`welford_add`]'s bit for bit (the scalings are exact).
#[inline]
pub fn welford_add_scaled(mean: &mut f64, m2: &mut f64, scale: &mut f64, n: usize, x: f64) {
    // A zero into moments that are all zero changes nothing (the common case of a tally bin
    // no batch has reached yet: a Jacobian's layers beyond a gate's range, rare orders).
    if x == 0.0 && *mean == 0.0 {
        return;
    }
    let new = power_of_two_scale(x);
    if new > *scale {
        // M2 is 0 while the scale is (every value so far was 0), so r = 0 then is harmless.
        let r = *scale / new;
        *m2 *= r * r;
        *scale = new;
    }
    let delta = x - *mean;
    *mean += delta / n as f64;
    if *scale > 0.0 {
        // A power of two: multiplying by its reciprocal is the division, exactly.
        let inv = 1.0 / *scale;
        *m2 += (delta * inv) * ((x - *mean) * inv);
    }
}

/// [`welford_add_scaled`] of `k` zero values at once to moments of `c` values: the pairwise
/// update of Chan, Golub & LeVeque (1979, "Updating formulae and a pairwise algorithm for
/// computing sample variances") with a group of k zeros, whose mean and M2 are 0:
/// x̄ ← x̄ c/(c + k), M2 ← M2 + x̄² c k/(c + k). Equal to k sequential updates within rounding;
/// a tally that folds only the bins a batch touched ([`crate::transport`]) catches up the others
/// with it. The scale does not change (zeros never raise it).
#[inline]
pub fn welford_add_zeros_scaled(mean: &mut f64, m2: &mut f64, scale: f64, c: usize, k: usize) {
    if k == 0 || c == 0 {
        // No zeros, or zeros after nothing but zeros: the moments stay 0.
        return;
    }
    let n = (c + k) as f64;
    let m = *mean;
    *mean = m * (c as f64 / n);
    if scale > 0.0 {
        let ms = m / scale;
        *m2 += ms * ms * (c as f64 * k as f64 / n);
    }
}

/// Standard error of the mean of n batch values from a scaled M2 ([`welford_add_scaled`]).
pub fn std_error_scaled(m2: f64, scale: f64, n: usize) -> f64 {
    std_error(m2, n) * scale
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
/// wall-clock at a stated thread count). Zero where it has no meaning: a relative error that is
/// infinite (no score), NaN (one batch) or zero (no scatter), or a time that is not positive.
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
        // Two values, 1 and 3: sample variance 2, SE = 1 (the smallest n with an error bar).
        let (_, m2) = fold(&[1.0, 3.0]);
        assert_eq!(std_error(m2, 2), 1.0);
        assert!((figure_of_merit(0.1, 2.0) - 50.0).abs() < 1e-12);
        assert!((figure_of_merit(0.5, 0.25) - 16.0).abs() < 1e-12);
        for (r, t) in [(0.0, 1.0), (f64::NAN, 1.0), (0.1, 0.0), (0.1, -1.0)] {
            assert_eq!(figure_of_merit(r, t), 0.0, "{r} {t}");
        }
        assert!((rel_err(-2.0, 0.5) - 0.25).abs() < 1e-15);
        assert_eq!(rel_err(0.0, 1.0), f64::INFINITY);
        assert_eq!(figure_of_merit(rel_err(0.0, 1.0), 1.0), 0.0);
    }

    fn fold_scaled(xs: &[f64]) -> (f64, f64, f64) {
        let (mut m, mut m2, mut sc) = (0.0, 0.0, 0.0);
        for (i, x) in xs.iter().enumerate() {
            welford_add_scaled(&mut m, &mut m2, &mut sc, i + 1, *x);
        }
        (m, m2, sc)
    }

    /// The scaled fold is the plain one where nothing underflows, and keeps the standard error
    /// of values near 1e-200, whose squares underflow: 1e-200 × {1, 2, 3, 4} has standard
    /// error √(5/12) 1e-200, where the plain fold gives 0.
    #[test]
    fn scaled_standard_error_survives_tiny_values() {
        let xs = [0.0, 3.0, 1.5, 7.25, 0.125, 2.0];
        let (m, m2) = fold(&xs);
        let (ms, m2s, sc) = fold_scaled(&xs);
        assert_eq!(m, ms);
        assert_eq!(std_error(m2, xs.len()), std_error_scaled(m2s, sc, xs.len()));
        assert_eq!(sc, 4.0);
        let tiny: Vec<f64> = [1.0, 2.0, 3.0, 4.0].iter().map(|x| x * 1e-200).collect();
        let (_, m2) = fold(&tiny);
        assert_eq!(std_error(m2, 4), 0.0, "the plain fold underflows");
        let (m, m2s, sc) = fold_scaled(&tiny);
        let se = std_error_scaled(m2s, sc, 4);
        assert!((m / 2.5e-200 - 1.0).abs() < 1e-15);
        assert!(
            (se / ((5.0f64 / 12.0).sqrt() * 1e-200) - 1.0).abs() < 1e-14,
            "{se:e}"
        );
        // A tiny value first, then large ones: the rescaling keeps the large ones' variance.
        let (_, m2s, sc) = fold_scaled(&[1e-300, 1.0, 2.0, 3.0]);
        let (_, m2) = fold(&[1e-300, 1.0, 2.0, 3.0]);
        assert!((std_error_scaled(m2s, sc, 4) / std_error(m2, 4) - 1.0).abs() < 1e-15);
        // Subnormal values (below 2.2e-308) keep an error bar too.
        let (_, m2s, sc) = fold_scaled(&[3e-316, 1e-316, 0.0, 2e-316]);
        let se = std_error_scaled(m2s, sc, 4);
        assert!(
            (se / ((5.0f64 / 12.0).sqrt() * 1e-316) - 1.0).abs() < 1e-7,
            "{se:e}"
        );
        // All zero: zero error, no NaN.
        let (_, m2s, sc) = fold_scaled(&[0.0, 0.0, 0.0]);
        assert_eq!(std_error_scaled(m2s, sc, 3), 0.0);
    }
}
