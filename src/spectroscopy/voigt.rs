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
    // One division: 1/|z|² times x and −y (within an ulp of dividing each, far below the
    // series' truncation error; the division was a third of a line wing's cost).
    let inv = 1.0 / r2;
    let (zr, zi) = (x * inv, -y * inv);
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

/// `acc[i] += scale · re_w(xᵢ, y)` for the wavenumbers `nu_cm1[i]` (sorted; else evaluated one
/// by one) of one line, xᵢ = (νᵢ − `centre_cm1`)·`cx`: bit for bit what [`re_w`] gives one by one (the same
/// operations in the same order), evaluated over runs of arguments that take the same branch
/// and number of terms, in fixed-width blocks the compiler vectorises. A line's wing, most of
/// a line-by-line sum's work, is such a run over every wavenumber of a channel cluster.
pub fn add_re_w(nu_cm1: &[f64], centre_cm1: f64, cx: f64, y: f64, scale: f64, acc: &mut [f64]) {
    if !nu_cm1.is_sorted() {
        // Unsorted (not a line-by-line caller's): one at a time.
        for (a, nu) in acc.iter_mut().zip(nu_cm1) {
            *a += scale * re_w((nu - centre_cm1) * cx, y);
        }
        return;
    }
    add_re_w_sorted(nu_cm1, centre_cm1, cx, y, scale, acc);
}

/// [`add_re_w`] of wavenumbers the caller knows to be sorted.
pub(crate) fn add_re_w_sorted(
    nu_cm1: &[f64],
    centre_cm1: f64,
    cx: f64,
    y: f64,
    scale: f64,
    acc: &mut [f64],
) {
    debug_assert_eq!(nu_cm1.len(), acc.len());
    debug_assert!(nu_cm1.is_sorted());
    let x = |nu: f64| (nu - centre_cm1) * cx;
    // 0: the exact function; else the expansion's number of terms (re_w's rule). Rounding is
    // monotone, so |x| and r² grow away from the centre: on each side the branch changes at a
    // few indices, found by bisection (the wavenumbers are sorted).
    let branch = |nu: f64| {
        let x = x(nu);
        let r2 = x * x + y * y;
        if r2 < EXACT_RADIUS_SQUARED {
            0
        } else {
            asymptotic_terms(r2)
        }
    };
    let Some(last) = nu_cm1.last() else {
        return;
    };
    // The sides of the centre; most lines lie beyond every wavenumber on one side.
    let centre = if *last < centre_cm1 {
        nu_cm1.len()
    } else if !(nu_cm1[0] < centre_cm1) {
        0
    } else {
        nu_cm1.partition_point(|&nu| nu < centre_cm1)
    };
    let mut i = 0;
    while i < nu_cm1.len() {
        let terms = branch(nu_cm1[i]);
        let side_end = if i < centre { centre } else { nu_cm1.len() };
        // Most often (a line far from every wavenumber) the whole side is one run.
        let j = if branch(nu_cm1[side_end - 1]) == terms {
            side_end
        } else {
            i + nu_cm1[i..side_end].partition_point(|&nu| branch(nu) == terms)
        };
        let (nus, out) = (&nu_cm1[i..j], &mut acc[i..j]);
        if terms == 0 {
            for (a, nu) in out.iter_mut().zip(nus) {
                *a += scale * re_w_exact(x(*nu), y);
            }
        } else {
            // The number of terms as a constant: the Horner loop unrolled.
            let run = match terms {
                1 => add_asymptotic_run::<1>,
                2 => add_asymptotic_run::<2>,
                3 => add_asymptotic_run::<3>,
                4 => add_asymptotic_run::<4>,
                _ => add_asymptotic_run::<7>,
            };
            debug_assert!([1, 2, 3, 4, 7].contains(&terms));
            run(nus, centre_cm1, cx, y, scale, out);
        }
        i = j;
    }
}

/// `acc[i] += scale · re_w_asymptotic(xᵢ, y, N)` over a run ([`add_re_w`]), with the widest
/// vector instructions the processor has ([`crate::simd`]).
fn add_asymptotic_run<const N: u32>(
    nu_cm1: &[f64],
    centre_cm1: f64,
    cx: f64,
    y: f64,
    scale: f64,
    acc: &mut [f64],
) {
    struct Run<'a, const N: u32> {
        nu_cm1: &'a [f64],
        centre_cm1: f64,
        cx: f64,
        y: f64,
        scale: f64,
        acc: &'a mut [f64],
    }
    impl<const N: u32> crate::simd::WithSimd for Run<'_, N> {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: crate::simd::Simd>(self, _: S) {
            asymptotic_run::<N>(
                self.nu_cm1,
                self.centre_cm1,
                self.cx,
                self.y,
                self.scale,
                self.acc,
            );
        }
    }
    crate::simd::dispatch(Run::<N> {
        nu_cm1,
        centre_cm1,
        cx,
        y,
        scale,
        acc,
    });
}

/// The loop of [`add_asymptotic_run`].
#[inline(always)]
fn asymptotic_run<const N: u32>(
    nu_cm1: &[f64],
    centre_cm1: f64,
    cx: f64,
    y: f64,
    scale: f64,
    acc: &mut [f64],
) {
    let x = |nu: f64| (nu - centre_cm1) * cx;
    let whole = nu_cm1.len() / LANES * LANES;
    for (nus, out) in nu_cm1.chunks_exact(LANES).zip(acc.chunks_exact_mut(LANES)) {
        let v = re_w_asymptotic_lanes::<N>(std::array::from_fn(|k| x(nus[k])), y);
        for k in 0..LANES {
            out[k] += scale * v[k];
        }
    }
    for (a, nu) in acc[whole..].iter_mut().zip(&nu_cm1[whole..]) {
        *a += scale * re_w_asymptotic(x(*nu), y, N);
    }
}

/// Width of the blocks of [`add_re_w`].
const LANES: usize = 4;

/// [`re_w_asymptotic`] at `LANES` arguments with one y and `N` terms: the operations of
/// [`asymptotic_series`] lane by lane.
#[inline(always)]
fn re_w_asymptotic_lanes<const N: u32>(x: [f64; LANES], y: f64) -> [f64; LANES] {
    let mut zr = [0.0; LANES];
    let mut zi = [0.0; LANES];
    let mut ur = [0.0; LANES];
    let mut ui = [0.0; LANES];
    for k in 0..LANES {
        let r2 = x[k] * x[k] + y * y;
        let inv = 1.0 / r2;
        zr[k] = x[k] * inv;
        zi[k] = -y * inv;
        ur[k] = 0.5 * (zr[k] * zr[k] - zi[k] * zi[k]);
        ui[k] = zr[k] * zi[k];
    }
    let mut sr = [1.0; LANES];
    let mut si = [0.0; LANES];
    for t in (1..=N).rev() {
        let c = (2 * t - 1) as f64;
        for k in 0..LANES {
            let (pr, pi) = (ur[k] * sr[k] - ui[k] * si[k], ur[k] * si[k] + ui[k] * sr[k]);
            sr[k] = 1.0 + c * pr;
            si[k] = c * pi;
        }
    }
    let mut out = [0.0; LANES];
    for k in 0..LANES {
        out[k] = -(sr[k] * zi[k] + si[k] * zr[k]) * FRAC_1_SQRT_PI;
    }
    out
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

/// Weideman's rational series for w (Weideman 1994, SIAM J. Numer. Anal. 31, 1497, eq. 38-39):
/// w(z) = 2 P(Q)/(L − iz)² + 1/(√π (L − iz)),  Q = (L + iz)/(L − iz),  L = √(N/√2), with P the
/// polynomial of the N = 24 coefficients below (highest power first). Its relative error over
/// Im z ≥ 0, |z| < 8 is 4e-10 (`weideman_matches_exact_inside_the_radius`); it is HAPI's w there
/// too. One Horner chain of 24 complex multiply-adds, latency-bound: two arguments evaluated
/// together ([`w_pair_fast`]) cost about a fifth of two exact evaluations.
const WEIDEMAN_L: f64 = 4.119_534_287_814_235;
/// The coefficients a₂₄ … a₁ of Weideman's series (his Matlab code: the FFT of
/// e^{−t²}(L² + t²) at t = L tan(θ/2)); recomputed by the unit test `weideman_coefficients`.
const WEIDEMAN_A: [f64; 24] = [
    -1.513_736_281_330_423e-10,
    4.904_818_766_415_797e-9,
    1.331_044_066_632_536_3e-9,
    -3.008_282_496_719_25e-8,
    -1.912_226_181_103_686e-8,
    1.873_834_332_514_571_5e-7,
    2.568_264_138_672_986e-7,
    -1.085_647_582_092_323_3e-6,
    -3.038_893_182_187_122_6e-6,
    4.139_461_719_806_133e-6,
    3.047_106_608_235_668_6e-5,
    2.433_141_546_309_691_7e-5,
    -2.074_843_151_171_531_2e-4,
    -7.816_642_995_626_492e-4,
    -4.936_426_901_289_703e-4,
    6.215_006_362_947_51e-3,
    3.372_336_685_531_513e-2,
    0.108_387_234_845_664_94,
    0.265_496_395_988_075_2,
    0.536_113_953_572_911_1,
    0.925_708_713_858_866_3,
    1.394_819_673_379_117_8,
    1.856_286_499_205_54,
    2.197_858_936_531_541_7,
];

/// Weideman's w(z) for Im z ≥ 0 (the N = 24 series above).
#[inline]
pub fn w_weideman(z: Complex64) -> Complex64 {
    w_weideman_lanes([z])[0]
}

/// Weideman's w at N arguments in one interleaved Horner loop: the N chains of dependent
/// multiply-adds run side by side in the processor, so N values cost little more than one.
#[inline]
fn w_weideman_lanes<const N: usize>(z: [Complex64; N]) -> [Complex64; N] {
    // L − iz and L + iz for z = x + iy: (L + y) − ix and (L − y) + ix.
    let r = z.map(|z| 1.0 / Complex64::new(WEIDEMAN_L + z.im, -z.re));
    let mut q = [Complex64::new(0.0, 0.0); N];
    for n in 0..N {
        q[n] = Complex64::new(WEIDEMAN_L - z[n].im, z[n].re) * r[n];
    }
    let mut p = [Complex64::new(0.0, 0.0); N];
    for &a in &WEIDEMAN_A {
        for n in 0..N {
            p[n] = p[n] * q[n] + a;
        }
    }
    let mut w = [Complex64::new(0.0, 0.0); N];
    for n in 0..N {
        w[n] = (2.0 * p[n] * r[n] + FRAC_1_SQRT_PI) * r[n];
    }
    w
}

/// w in the upper half-plane for the beyond-Voigt fast path: Weideman's series where |z| < 8,
/// the asymptotic expansion outside ([`w_fast`]).
#[inline]
pub fn w_weideman_or_fast(z: Complex64) -> Complex64 {
    if z.norm_sqr() < EXACT_RADIUS_SQUARED {
        w_weideman(z)
    } else {
        w_fast(z)
    }
}

/// w at two arguments in the upper half-plane for the beyond-Voigt fast path: the asymptotic
/// expansion where |z| ≥ 8 (as [`w_fast`]), Weideman's series inside (relative error ≤ 4e-10
/// of |w| everywhere, against 3e-10 for `w_fast` outside the radius).
#[inline]
pub fn w_pair_fast(z1: Complex64, z2: Complex64) -> (Complex64, Complex64) {
    let near = |z: Complex64| z.norm_sqr() < EXACT_RADIUS_SQUARED;
    if near(z1) && near(z2) {
        let [a, b] = w_weideman_lanes([z1, z2]);
        (a, b)
    } else {
        (w_weideman_or_fast(z1), w_weideman_or_fast(z2))
    }
}

/// [`w_pair_fast`] at four arguments (two wavenumbers' pairs), interleaved four ways where all
/// four lie inside the radius.
#[inline]
pub fn w_quad_fast(z: [Complex64; 4]) -> [Complex64; 4] {
    if z.iter().all(|z| z.norm_sqr() < EXACT_RADIUS_SQUARED) {
        w_weideman_lanes(z)
    } else {
        let (a, b) = w_pair_fast(z[0], z[1]);
        let (c, d) = w_pair_fast(z[2], z[3]);
        [a, b, c, d]
    }
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

    /// A wing run vectorised with the processor's widest instructions ([`crate::simd`]; AVX2
    /// on the machines the tests run on) adds, bit for bit, what the expansion gives point by
    /// point ([`re_w_asymptotic`]) and what the same loop compiled for the baseline adds: the
    /// same operations in the same order, whatever the instruction set. Runs of every length
    /// from 0 to 11 (whole blocks of lanes and a remainder), every number of terms, on both
    /// sides of the line.
    #[test]
    fn a_vectorised_wing_run_is_the_pointwise_expansion_bit_for_bit() {
        let (centre, cx, y, scale) = (6360.0, 97.3, 0.61, 3.7e-21);
        for len in 0..12 {
            for side in [-1.0, 1.0] {
                let nu: Vec<f64> = (0..len)
                    .map(|i| centre + side * (0.4 + 0.173 * i as f64 + 1e-3 * (i * i) as f64))
                    .map(|v| if side < 0.0 { 2.0 * centre - v } else { v })
                    .collect();
                let mut nu = nu;
                nu.sort_by(f64::total_cmp);
                let start: Vec<f64> = (0..len).map(|i| 1e-22 * (i + 1) as f64).collect();
                let check = |n: u32, run: fn(&[f64], f64, f64, f64, f64, &mut [f64])| {
                    let mut got = start.clone();
                    run(&nu, centre, cx, y, scale, &mut got);
                    let mut baseline = start.clone();
                    asymptotic_run_baseline(n, &nu, centre, cx, y, scale, &mut baseline);
                    for i in 0..len {
                        let want = start[i] + scale * re_w_asymptotic((nu[i] - centre) * cx, y, n);
                        assert_eq!(got[i].to_bits(), want.to_bits(), "N {n}, {len} points");
                        assert_eq!(got[i].to_bits(), baseline[i].to_bits(), "N {n}");
                    }
                };
                check(1, add_asymptotic_run::<1>);
                check(2, add_asymptotic_run::<2>);
                check(3, add_asymptotic_run::<3>);
                check(4, add_asymptotic_run::<4>);
                check(7, add_asymptotic_run::<7>);
            }
        }
    }

    /// The loop of [`add_asymptotic_run`] compiled for the baseline target, not dispatched.
    fn asymptotic_run_baseline(
        n: u32,
        nu: &[f64],
        centre: f64,
        cx: f64,
        y: f64,
        scale: f64,
        acc: &mut [f64],
    ) {
        match n {
            1 => asymptotic_run::<1>(nu, centre, cx, y, scale, acc),
            2 => asymptotic_run::<2>(nu, centre, cx, y, scale, acc),
            3 => asymptotic_run::<3>(nu, centre, cx, y, scale, acc),
            4 => asymptotic_run::<4>(nu, centre, cx, y, scale, acc),
            _ => asymptotic_run::<7>(nu, centre, cx, y, scale, acc),
        }
    }

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

    /// Below the real axis the asymptotic expansion misses the term 2e^{−z²} of the
    /// reflection formula w(z) = 2e^{−z²} − w(−z) (A&S 7.1.11), which grows without bound
    /// there; `w_fast` must take the exact function for every Im z < 0, however far out.
    #[test]
    fn fast_w_below_the_real_axis_obeys_the_reflection_formula() {
        for (x, y) in [
            (1.0, -9.0),
            (10.0, -1.0),
            (-30.0, -0.5),
            (300.0, -1e-3),
            (0.0, -20.0),
        ] {
            let z = Complex64::new(x, y);
            let reflected = 2.0 * (-z * z).exp() - errorfunctions::w_with_relerror(-z, 0.0);
            let f = w_fast(z);
            assert!(
                (f - reflected).norm() <= 1e-10 * reflected.norm(),
                "w({z}): {f} vs 2e^(−z²) − w(−z) = {reflected}"
            );
        }
    }

    /// The embedded coefficients are Weideman's recipe (his eq. 38 and Matlab listing),
    /// recomputed here by a direct DFT of f(t) = e^{−t²}(L² + t²) at t = L tan(θ/2).
    #[test]
    fn weideman_coefficients() {
        let n = WEIDEMAN_A.len();
        let m = 2 * n;
        let l = (n as f64 / std::f64::consts::SQRT_2).sqrt();
        assert!((l - WEIDEMAN_L).abs() < 1e-15);
        // f at k = −M .. M−1 (f(−M) = 0: t = ∞), fftshifted, real part of its 2M-point DFT.
        let f = |k: i64| -> f64 {
            if k == -(m as i64) {
                return 0.0;
            }
            let t = l * (k as f64 * std::f64::consts::PI / m as f64 / 2.0).tan();
            (-t * t).exp() * (l * l + t * t)
        };
        for (idx, &a) in WEIDEMAN_A.iter().enumerate() {
            let j = n - idx; // a₂₄ first
            let mut sum = 0.0;
            for i in 0..2 * m {
                // fftshift of f(−M .. M−1): element i is f at k = i (i < M), else i − 2M.
                let k = if i < m {
                    i as i64
                } else {
                    i as i64 - 2 * m as i64
                };
                let phase = 2.0 * std::f64::consts::PI * (j * i) as f64 / (2 * m) as f64;
                sum += f(k) * phase.cos();
            }
            let recomputed = sum / (2 * m) as f64;
            assert!(
                (recomputed - a).abs() <= 1e-14 * (1.0 + a.abs()),
                "a{j}: {recomputed:e} vs {a:e}"
            );
        }
    }

    /// Weideman's series and the pair evaluator against the exact w over the half-disc where
    /// the fast path uses them, dense near the real axis and the origin.
    #[test]
    fn weideman_matches_exact_inside_the_radius() {
        let mut worst = 0.0f64;
        for i in 0..=160 {
            let x = -8.0 + 0.1 * i as f64;
            for j in 0..=120 {
                let y = if j == 0 {
                    0.0
                } else {
                    8.0 * 1.07f64.powi(j - 120)
                };
                let z = Complex64::new(x, y);
                if z.norm_sqr() >= EXACT_RADIUS_SQUARED {
                    continue;
                }
                let e = errorfunctions::w_with_relerror(z, 0.0);
                let (a, b) = w_pair_fast(z, Complex64::new(y, x.abs()));
                let q = w_quad_fast([z, Complex64::new(y, x.abs()), z, z]);
                assert_eq!((q[0], q[1]), (a, b));
                let e2 = errorfunctions::w_with_relerror(Complex64::new(y, x.abs()), 0.0);
                worst = worst
                    .max((a - e).norm() / e.norm())
                    .max((b - e2).norm() / e2.norm());
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

    /// `add_re_w` adds exactly what `re_w` gives one argument at a time: sorted wavenumbers on
    /// both sides of a line, through every branch (the exact function near the centre, each
    /// number of terms farther out, the run boundaries between them) and block remainders.
    #[test]
    fn batched_re_w_is_re_w_bit_for_bit() {
        let centre = 6360.0;
        for (gamma_d, y) in [(0.0054, 1e-4), (0.0054, 0.5), (0.0054, 7.99), (0.004, 30.0)] {
            let cx = SQRT_LN2 / gamma_d;
            for n in [1, 3, 4, 5, 9, 400] {
                // Log-spaced detunings from 1e-5 to 30 cm⁻¹ each side, and the centre itself.
                let mut nu: Vec<f64> = (0..n)
                    .flat_map(|i| {
                        let d = 1e-5 * 3e6f64.powf(i as f64 / n.max(2) as f64);
                        [centre - d, centre + d]
                    })
                    .chain([centre])
                    .collect();
                nu.sort_by(f64::total_cmp);
                let start: Vec<f64> = (0..nu.len()).map(|i| 1e-3 * i as f64).collect();
                // Sorted in runs; reversed, one by one.
                for _ in 0..2 {
                    let mut acc = start.clone();
                    add_re_w(&nu, centre, cx, y, 2.5, &mut acc);
                    for (i, v) in nu.iter().enumerate() {
                        let want = start[i] + 2.5 * re_w((v - centre) * cx, y);
                        assert_eq!(
                            acc[i].to_bits(),
                            want.to_bits(),
                            "ν {v}, y {y}: {} vs {want}",
                            acc[i]
                        );
                    }
                    nu.reverse();
                }
            }
        }
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
