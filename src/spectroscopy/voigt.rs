//! The Voigt profile through the Faddeeva function w(z) = e^{−z²} erfc(−iz).
//!
//! With Doppler HWHM γ_D, Lorentz HWHM γ_L and detuning Δ = ν − ν_c (all cm⁻¹), the
//! area-normalised Voigt profile is (Armstrong 1967, JQSRT 7, 61, eq. 2; as HAPI)
//!
//! ```text
//! g_V(Δ) = sqrt(ln2/π)/γ_D · Re w(x + i y),   x = sqrt(ln2) Δ/γ_D,   y = sqrt(ln2) γ_L/γ_D     [1/cm⁻¹]
//! ```
//!
//! Two evaluations of Re w for y ≥ 0:
//! * [`re_w_exact`]: the `errorfunctions` crate (a port of S. G. Johnson's Faddeeva package,
//!   identical to scipy's `wofz`), the truth everywhere.
//! * [`re_w`]: the same exact function where |z| < 8, and outside it the asymptotic (Laplace)
//!   expansion w(z) = i/(√π z) Σₙ (2n−1)!!/(2z²)ⁿ (Abramowitz & Stegun 7.1.23) truncated after
//!   N terms, N chosen by |z| so that the truncation error (2N−1)!!/(2|z|²)^N ≲ 3e-10. The
//!   expansion is what the line wings need (|z| ≫ 1 on almost every grid point of a line), and
//!   costs one complex reciprocal and N complex multiply-adds. Its error against the exact
//!   function over the plane lidarsim uses is measured by the unit test
//!   `fast_re_w_matches_exact_over_the_plane` (max relative error of Re w < 1e-8, far below the
//!   1e-5 budget of the summed cross-section).

use num_complex::Complex64;

/// 1/√π.
const FRAC_1_SQRT_PI: f64 = 0.564_189_583_547_756_3;
/// sqrt(ln 2).
pub const SQRT_LN2: f64 = 0.832_554_611_157_697_8;
/// sqrt(ln2/π).
pub const SQRT_LN2_OVER_PI: f64 = 0.469_718_639_349_825_66;

/// |z|² below which [`re_w`] calls the exact Faddeeva function.
pub const EXACT_RADIUS_SQUARED: f64 = 64.0;

/// Re w(x + iy) by the exact Faddeeva function (errorfunctions; ~1e-13 relative), y ≥ 0.
pub fn re_w_exact(x: f64, y: f64) -> f64 {
    errorfunctions::w_with_relerror(Complex64::new(x, y), 0.0).re
}

/// Re w(x + iy), y ≥ 0: exact for |z| < 8, asymptotic expansion outside (see module docs).
#[inline]
pub fn re_w(x: f64, y: f64) -> f64 {
    let r2 = x * x + y * y;
    if r2 < EXACT_RADIUS_SQUARED {
        return re_w_exact(x, y);
    }
    re_w_asymptotic(x, y, asymptotic_terms(r2))
}

/// Terms of the asymptotic expansion for |z|² = `r2` ≥ 64: truncation after N terms errs by
/// ≈ (2N−1)!!/(2|z|²)^N ≤ 3e-10 of |w| in every branch (the real part's relative error is
/// ≤ (2N+1) times that, < 5e-9).
#[inline]
fn asymptotic_terms(r2: f64) -> u32 {
    if r2 >= 1.0e9 {
        1
    } else if r2 >= 1.0e5 {
        2
    } else if r2 >= 4.0e3 {
        3
    } else if r2 >= 400.0 {
        4
    } else {
        7
    }
}

/// 1/z and the series S = 1 + Σ (2n−1)!!/(2z²)ⁿ with `n` terms (Horner from the innermost),
/// as ((Re 1/z, Im 1/z), (Re S, Im S)); w ≈ (i/√π)·S/z.
#[inline]
fn asymptotic_series(x: f64, y: f64, n: u32) -> ((f64, f64), (f64, f64)) {
    let r2 = x * x + y * y;
    let (zr, zi) = (x / r2, -y / r2);
    let ur = 0.5 * (zr * zr - zi * zi);
    let ui = zr * zi;
    let (mut sr, mut si) = (1.0, 0.0);
    for k in (1..=n).rev() {
        let c = (2 * k - 1) as f64;
        let (pr, pi) = (ur * sr - ui * si, ur * si + ui * sr);
        sr = 1.0 + c * pr;
        si = c * pi;
    }
    ((zr, zi), (sr, si))
}

/// The asymptotic expansion of Re w with `n` correction terms (A&S 7.1.23); accurate for
/// |z| ≫ 1 only.
#[inline]
pub fn re_w_asymptotic(x: f64, y: f64, n: u32) -> f64 {
    let ((zr, zi), (sr, si)) = asymptotic_series(x, y, n);
    // w = (i/√π)·S/z  →  Re w = −Im(S/z)/√π
    -(sr * zi + si * zr) * FRAC_1_SQRT_PI
}

/// The complex Faddeeva function w(z) for Im z ≥ 0 by the rule of [`re_w`]: exact for
/// |z| < 8 (and in the lower half-plane), the asymptotic expansion with the same number of
/// terms outside (relative error ≲ 3e-10 of |w|; both parts: `fast_w_matches_exact_over_the_plane`).
#[inline]
pub fn w_fast(z: Complex64) -> Complex64 {
    let (x, y) = (z.re, z.im);
    let r2 = x * x + y * y;
    if r2 < EXACT_RADIUS_SQUARED || y < 0.0 {
        return errorfunctions::w_with_relerror(z, 0.0);
    }
    let ((zr, zi), (sr, si)) = asymptotic_series(x, y, asymptotic_terms(r2));
    // w = (i/√π)·S/z
    Complex64::new(
        -(sr * zi + si * zr) * FRAC_1_SQRT_PI,
        (sr * zr - si * zi) * FRAC_1_SQRT_PI,
    )
}

/// The area-normalised Voigt profile g_V(Δ) [1/cm⁻¹] (module docs), exact Faddeeva.
pub fn voigt_profile_exact(delta_cm1: f64, gamma_d_cm1: f64, gamma_l_cm1: f64) -> f64 {
    let c = SQRT_LN2 / gamma_d_cm1;
    SQRT_LN2_OVER_PI / gamma_d_cm1 * re_w_exact(delta_cm1 * c, gamma_l_cm1 * c)
}

/// The area-normalised Voigt profile g_V(Δ) [1/cm⁻¹] (module docs), with [`re_w`].
pub fn voigt_profile(delta_cm1: f64, gamma_d_cm1: f64, gamma_l_cm1: f64) -> f64 {
    let c = SQRT_LN2 / gamma_d_cm1;
    SQRT_LN2_OVER_PI / gamma_d_cm1 * re_w(delta_cm1 * c, gamma_l_cm1 * c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_w_matches_exact_over_the_plane() {
        let mut worst = 0.0f64;
        for i in 0..400 {
            for j in 0..200 {
                let x = -4000.0 + 20.0 * i as f64 * (1.0 + 0.37 * (j % 3) as f64);
                let y = 1e-3 * 1.09f64.powi(j);
                let z = Complex64::new(x, y);
                let e = errorfunctions::w_with_relerror(z, 0.0);
                let f = w_fast(z);
                worst = worst.max((f - e).norm() / e.norm());
            }
        }
        assert!(worst < 1e-9, "max relative error of w {worst:e}");
    }

    #[test]
    fn fast_re_w_matches_exact_over_the_plane() {
        // x from 0 to 1e5 (25 cm⁻¹ wings of lines with γ_D ≥ 2e-4 cm⁻¹), y from 1e-6 (top of
        // the atmosphere) to 1e3 (pressure-broadened far beyond any lidar case).
        let mut worst = (0.0f64, 0.0, 0.0);
        for i in 0..=400 {
            let x = if i == 0 {
                0.0
            } else {
                10f64.powf(-2.0 + 7.0 * i as f64 / 400.0)
            };
            for j in 0..=200 {
                let y = 10f64.powf(-6.0 + 9.0 * j as f64 / 200.0);
                let (a, b) = (re_w(x, y), re_w_exact(x, y));
                let rel = ((a - b) / b).abs();
                if rel > worst.0 {
                    worst = (rel, x, y);
                }
            }
        }
        assert!(worst.0 < 1e-8, "max relative error {worst:?}");
    }

    #[test]
    fn limits_are_gauss_and_lorentz() {
        // y → 0: Re w(x) = exp(−x²); far wing: Re w → y/(√π (x²+y²)).
        for x in [0.0, 0.5, 1.0, 2.0] {
            assert!((re_w(x, 0.0) - (-x * x).exp()).abs() < 1e-14);
        }
        let (x, y) = (3.0e3, 0.7);
        let lorentz = y / (std::f64::consts::PI.sqrt() * (x * x + y * y));
        assert!((re_w(x, y) / lorentz - 1.0).abs() < 1e-6);
    }

    #[test]
    fn voigt_profile_has_unit_area() {
        // Trapezoid over ±2000 HWHM, plus the analytic Lorentz tails beyond (2γ_L/(π·2000γ)).
        let (gd, gl) = (0.006, 0.07);
        let h = 2e-4;
        let lim = 2000.0 * gl;
        let n = (2.0 * lim / h) as usize;
        let mut s = 0.0;
        for i in 0..=n {
            let d = -lim + i as f64 * h;
            let w = if i == 0 || i == n { 0.5 } else { 1.0 };
            s += w * voigt_profile(d, gd, gl);
        }
        s *= h;
        s += 2.0 * gl / (std::f64::consts::PI * lim);
        assert!((s - 1.0).abs() < 1e-6, "{s}");
    }
}
