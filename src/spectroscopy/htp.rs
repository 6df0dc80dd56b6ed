//! Beyond Voigt: the partially-correlated quadratic-speed-dependent hard-collision profile
//! (pCqSDHC, the Hartmann-Tran profile) and its limits, with first-order line mixing.
//!
//! The profile of Tran, Ngo & Hartmann (2013, JQSRT 129, 199; erratum JQSRT 134, 104), as
//! recommended by Tennyson et al. (2014, Pure Appl. Chem. 86, 1931) and evaluated by HAPI, is
//! the complex function
//!
//! ```text
//! I(ν) = (1/π) · A / (1 − (ν_VC − η (C₀ − 3C₂/2)) A + η C₂ B)
//! C₀ = Γ₀ + iΔ₀,  C₂ = Γ₂ + iΔ₂,  C̃₀ = (1 − η)(C₀ − 3C₂/2) + ν_VC,  C̃₂ = (1 − η) C₂
//! X = (i(ν₀ − ν) + C̃₀)/C̃₂,  Y = 1/(2 c C̃₂)²,  c = √ln2/γ_D
//! Z₁ = √(X + Y) − √Y,  Z₂ = √(X + Y) + √Y
//! A = √π c (w(iZ₁) − w(iZ₂)),
//! B = (−1 + √π/(2√Y) (1 − Z₁²) w(iZ₁) − √π/(2√Y) (1 − Z₂²) w(iZ₂)) / C̃₂
//! ```
//!
//! with γ_D the Doppler HWHM and w the Faddeeva function. Its Lorentz limit is
//! (1/π)/(Γ₀ − i(ν − ν₀ − Δ₀)): Re I is the normalised line shape (unit area) and Im I is
//! positive on the high-wavenumber side. **Line mixing** (first order, Rosenkranz 1975) is
//! then absorption ∝ Re I + Y·Im I, so Y > 0 raises the high-wavenumber side (the convention of
//! the NIST/HITRAN parameters, `../shared/data/nist_30012/PROVENANCE.md`).
//!
//! Limits: η = 0 gives the speed-dependent Nelkin-Ghatak (hard-collision) profile, η = ν_VC = 0
//! the speed-dependent Voigt, and C₂ = 0 with η = ν_VC = 0 the Voigt: that case takes the
//! Voigt's own formula, Z₁ = c (i(ν₀ − ν) + C₀), A = √π c w(iZ₁).
//!
//! **Numerics.** As Γ₂/Γ₀ → 0 (some lines have 1e-4), Y grows as 1/C̃₂² and
//! Z₁ = √(X + Y) − √Y cancels catastrophically; it is evaluated as X/(√(X + Y) + √Y), the same
//! number without the cancellation (HAPI switches instead to a first-order expansion when
//! |X| ≤ 3e-8 |Y|). B multiplies η C₂, whose factor C₂/C̃₂ = 1/(1 − η) keeps that product's
//! absolute error at rounding level even though B itself cancels. Where |Y| ≪ |X| the two w
//! terms of A cancel by √(Y/X); HAPI switches to an asymptotic form below |Y/X| = 1e-15, which
//! would need a detuning of ~10¹² cm⁻¹ for these lines (|Y/X| ≈ 1/(4c²C̃₂|ν − ν₀|)), so the
//! general form is kept (at a 25 cm⁻¹ wing and 1 atm √(Y/X) ≈ 0.01: two digits lost of 16).

use num_complex::Complex64;

use super::voigt::SQRT_LN2;

const SQRT_PI: f64 = 1.772_453_850_905_516;

/// The Faddeeva function w(z) (errorfunctions: S. G. Johnson's package, as scipy's `wofz`).
#[inline]
fn w_exact(z: Complex64) -> Complex64 {
    errorfunctions::w_with_relerror(z, 0.0)
}

/// The principal square root, algebraically (no trigonometric functions: this is the hot path):
/// √(a + ib) = (t, b/(2t)) for a ≥ 0 and (|b|/(2t), ±t) otherwise, t = √((|z| + |a|)/2).
#[inline]
fn principal_sqrt(z: Complex64) -> Complex64 {
    let (a, b) = (z.re, z.im);
    if a == 0.0 && b == 0.0 {
        return Complex64::new(0.0, 0.0);
    }
    let r = (a * a + b * b).sqrt();
    let t = (0.5 * (r + a.abs())).sqrt();
    if a >= 0.0 {
        Complex64::new(t, b / (2.0 * t))
    } else {
        Complex64::new(b.abs() / (2.0 * t), t.copysign(b))
    }
}

/// Parameters of one line at one state (all cm⁻¹ except η).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HtParameters {
    /// Unshifted line centre ν₀.
    pub nu0: f64,
    /// Doppler HWHM γ_D.
    pub gamma_d: f64,
    /// Speed-averaged collisional half width Γ₀.
    pub gamma0: f64,
    /// Its quadratic speed dependence Γ₂.
    pub gamma2: f64,
    /// Speed-averaged pressure shift Δ₀.
    pub delta0: f64,
    /// Its quadratic speed dependence Δ₂.
    pub delta2: f64,
    /// Velocity-changing collision frequency ν_VC (Dicke narrowing).
    pub nu_vc: f64,
    /// Correlation parameter η (dimensionless, 0 ≤ η < 1).
    pub eta: f64,
}

/// The complex normalised Hartmann-Tran profile I(ν) \[1/cm⁻¹\] (module docs): Re I is the line
/// shape, Im I the dispersion that first-order line mixing adds. Exact Faddeeva function.
pub fn hartmann_tran(p: &HtParameters, nu: f64) -> Complex64 {
    HtProfile::new(p).eval(nu)
}

/// The profile of one line at one state with everything that does not depend on ν worked out
/// once: the line-by-line loops evaluate it at hundreds of wavenumbers per line.
#[derive(Debug, Clone, Copy)]
pub struct HtProfile {
    nu0: f64,
    /// c = √ln2/γ_D and √π c.
    c: f64,
    sqrt_pi_c: f64,
    /// C̃₀.
    c0t: Complex64,
    /// 1/C̃₂, √Y and Y; `None` without speed dependence (the Voigt's own argument, module docs).
    speed: Option<Speed>,
    /// The denominator's terms; `None` when they vanish (the speed-dependent Voigt: the
    /// denominator is 1).
    narrowing: Option<Narrowing>,
}

/// 1 − (ν_VC − η (C₀ − 3C₂/2)) A + η C₂ B = 1 − `vc` A + `eta_c2` B.
#[derive(Debug, Clone, Copy)]
struct Narrowing {
    vc: Complex64,
    /// `None` for η = 0 (the Nelkin-Ghatak limit): B is then not needed at all.
    eta_c2: Option<Complex64>,
}

#[derive(Debug, Clone, Copy)]
struct Speed {
    inv_c2t: Complex64,
    sqrt_y: Complex64,
    y: Complex64,
    /// √π/(2√Y), the factor of B's w terms.
    k: Complex64,
}

impl HtProfile {
    /// The ν-independent constants of the profile of `p`.
    pub fn new(p: &HtParameters) -> HtProfile {
        let c = SQRT_LN2 / p.gamma_d;
        let c0 = Complex64::new(p.gamma0, p.delta0);
        let c2 = Complex64::new(p.gamma2, p.delta2);
        let c0t = (1.0 - p.eta) * (c0 - 1.5 * c2) + p.nu_vc;
        let c2t = (1.0 - p.eta) * c2;
        let speed = (c2t.re != 0.0 || c2t.im != 0.0).then(|| {
            let sqrt_y = 1.0 / (2.0 * c * c2t);
            Speed {
                inv_c2t: 1.0 / c2t,
                sqrt_y,
                y: sqrt_y * sqrt_y,
                k: SQRT_PI / (2.0 * sqrt_y),
            }
        });
        let vc = p.nu_vc - p.eta * (c0 - 1.5 * c2);
        let eta_c2 = p.eta * c2;
        let nonzero = |z: Complex64| z.re != 0.0 || z.im != 0.0;
        HtProfile {
            nu0: p.nu0,
            c,
            sqrt_pi_c: SQRT_PI * c,
            c0t,
            speed,
            narrowing: (nonzero(vc) || nonzero(eta_c2)).then_some(Narrowing {
                vc,
                eta_c2: nonzero(eta_c2).then_some(eta_c2),
            }),
        }
    }

    /// I(ν), exact Faddeeva function.
    pub fn eval(&self, nu: f64) -> Complex64 {
        self.eval_with(nu, w_exact, w_pair_exact)
    }

    /// I(ν) with fast Faddeeva functions ([`super::voigt::w_pair_fast`]: Weideman's series near
    /// the origin, the asymptotic expansion far from it, both within 4e-10 of |w|): the
    /// line-by-line fast path.
    pub fn eval_fast(&self, nu: f64) -> Complex64 {
        self.eval_with(
            nu,
            super::voigt::w_weideman_or_fast,
            super::voigt::w_pair_fast,
        )
    }

    /// [`HtProfile::eval_fast`] at two wavenumbers, their four Faddeeva functions evaluated
    /// together ([`super::voigt::w_quad_fast`]): the same numbers, faster where the profile is
    /// evaluated node after node.
    pub fn eval_fast_pair(&self, nu_a: f64, nu_b: f64) -> (Complex64, Complex64) {
        match self.speed {
            None => (self.eval_fast(nu_a), self.eval_fast(nu_b)),
            Some(ref s) => {
                let (z1a, z2a) = self.arguments(s, nu_a);
                let (z1b, z2b) = self.arguments(s, nu_b);
                let i = Complex64::new(0.0, 1.0);
                let [w1a, w2a, w1b, w2b] =
                    super::voigt::w_quad_fast([i * z1a, i * z2a, i * z1b, i * z2b]);
                (
                    self.combine(s, z1a, z2a, w1a, w2a),
                    self.combine(s, z1b, z2b, w1b, w2b),
                )
            }
        }
    }

    /// The profile with given Faddeeva functions: `w` at one argument (the Voigt limit), `w2`
    /// at the two, w(iZ₁) and w(iZ₂), together.
    #[inline]
    fn eval_with(
        &self,
        nu: f64,
        w: fn(Complex64) -> Complex64,
        w2: fn(Complex64, Complex64) -> (Complex64, Complex64),
    ) -> Complex64 {
        match self.speed {
            // No speed dependence: the Voigt's own argument, z = c (i(ν₀ − ν) + C̃₀); B is
            // multiplied by C₂ = 0.
            None => {
                let shifted = Complex64::new(self.c0t.re, self.c0t.im + (self.nu0 - nu));
                let i = Complex64::new(0.0, 1.0);
                self.finish(self.sqrt_pi_c * w(i * (shifted * self.c)), None)
            }
            Some(ref s) => {
                let (z1, z2) = self.arguments(s, nu);
                let i = Complex64::new(0.0, 1.0);
                let (w1, w2) = w2(i * z1, i * z2);
                self.combine(s, z1, z2, w1, w2)
            }
        }
    }

    /// Z₁ and Z₂ at ν (speed dependence).
    #[inline]
    fn arguments(&self, s: &Speed, nu: f64) -> (Complex64, Complex64) {
        // X = (i(ν₀ − ν) + C̃₀)/C̃₂
        let x = Complex64::new(self.c0t.re, self.c0t.im + (self.nu0 - nu)) * s.inv_c2t;
        // Principal √(X + Y), as published. Z₁ = √(X+Y) − √Y = X/(√(X+Y) + √Y): the second
        // form where the first would cancel (always, as Re √Y ≥ 0 and Re √(X+Y) ≥ 0 when
        // Γ₂ > 0).
        let root = principal_sqrt(x + s.y);
        let sum = root + s.sqrt_y;
        let diff = root - s.sqrt_y;
        let z1 = if sum.norm_sqr() >= diff.norm_sqr() {
            x / sum
        } else {
            diff
        };
        (z1, sum)
    }

    /// I from Z₁, Z₂ and w(iZ₁), w(iZ₂) (speed dependence).
    #[inline]
    fn combine(
        &self,
        s: &Speed,
        z1: Complex64,
        z2: Complex64,
        w1: Complex64,
        w2: Complex64,
    ) -> Complex64 {
        let a = self.sqrt_pi_c * (w1 - w2);
        // η C₂ B, only where η ≠ 0.
        let eta_c2_b = self.narrowing.and_then(|n| n.eta_c2).map(|eta_c2| {
            let b = (-1.0 + s.k * (1.0 - z1 * z1) * w1 - s.k * (1.0 - z2 * z2) * w2) * s.inv_c2t;
            eta_c2 * b
        });
        self.finish(a, eta_c2_b)
    }

    /// I = (1/π) A/(1 − (ν_VC − η (C₀ − 3C₂/2)) A + η C₂ B).
    #[inline]
    fn finish(&self, a: Complex64, eta_c2_b: Option<Complex64>) -> Complex64 {
        let i = match self.narrowing {
            None => a,
            Some(n) => a / (1.0 - n.vc * a + eta_c2_b.unwrap_or_default()),
        };
        i * std::f64::consts::FRAC_1_PI
    }
}

/// w at both arguments: the exact function, twice.
#[inline]
fn w_pair_exact(z1: Complex64, z2: Complex64) -> (Complex64, Complex64) {
    (w_exact(z1), w_exact(z2))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spectroscopy::voigt::voigt_profile_exact;

    fn r16(p_atm: f64) -> HtParameters {
        // R(16)e of the NIST list at 296 K: Γ₀ = 0.0739 p, Γ₂/Γ₀ = 0.0772, ν_VC = 0.0054 p.
        HtParameters {
            nu0: 6359.967248,
            gamma_d: 0.005_8,
            gamma0: 0.073_949_633 * p_atm,
            gamma2: 0.077_240_676 * 0.073_949_633 * p_atm,
            delta0: -0.005_407_741 * p_atm,
            delta2: 0.0,
            nu_vc: 0.005_439_081 * p_atm,
            eta: 0.0,
        }
    }

    /// Without speed dependence, Dicke narrowing and correlation the profile is the Voigt
    /// (real part, exact Faddeeva) and its dispersion the Faddeeva function's imaginary part.
    #[test]
    fn without_beyond_voigt_terms_it_is_the_voigt() {
        let p = HtParameters {
            gamma2: 0.0,
            nu_vc: 0.0,
            ..r16(0.5)
        };
        for k in -200..=200 {
            let nu = p.nu0 + k as f64 * 0.01;
            let i = hartmann_tran(&p, nu);
            let v = voigt_profile_exact(nu - p.nu0 - p.delta0, p.gamma_d, p.gamma0);
            assert!((i.re - v).abs() <= 1e-14 * v, "ν {nu}: {} vs {v}", i.re);
        }
    }

    /// Unit area: ∫ Re I dν = 1, the far wings (Lorentzian, Γ₀/(π Δ²)) added analytically.
    #[test]
    fn the_profile_has_unit_area() {
        for p_atm in [1.0, 0.1, 0.01] {
            let p = HtParameters {
                eta: 0.3,
                ..r16(p_atm)
            };
            let half = 30.0;
            let n = 600_000;
            let h = 2.0 * half / n as f64;
            let mut sum = 0.0;
            for k in 0..=n {
                let nu = p.nu0 + p.delta0 - half + k as f64 * h;
                let w = if k == 0 || k == n { 0.5 } else { 1.0 };
                sum += w * hartmann_tran(&p, nu).re * h;
            }
            let wings = 2.0 * p.gamma0 / (std::f64::consts::PI * half);
            assert!(
                (sum + wings - 1.0).abs() < 2e-5,
                "p {p_atm} atm: area {}",
                sum + wings
            );
        }
    }

    /// As Γ₂ → 0 the profile tends to the Γ₂ = 0 one linearly, without cancellation noise:
    /// I(2ε) − I(0) = 2 (I(ε) − I(0)) up to second order (measured: the residual is ~240 ε of
    /// the first-order term; the floor is the rounding of I), over ±2 cm⁻¹, down to
    /// Γ₂/Γ₀ = 1e-12, where √(X + Y) − √Y computed as written would lose 7 digits of I.
    #[test]
    fn small_speed_dependence_is_accurate() {
        let base = HtParameters {
            gamma2: 0.0,
            ..r16(1.0)
        };
        for ratio in [1e-6, 1e-9, 1e-12] {
            let at = |r: f64, nu: f64| {
                hartmann_tran(
                    &HtParameters {
                        gamma2: r * base.gamma0,
                        ..base
                    },
                    nu,
                )
            };
            let (mut worst, mut scale, mut peak) = (0.0f64, 0.0f64, 0.0f64);
            for k in -2000..=2000 {
                let nu = base.nu0 + k as f64 * 0.001;
                let i0 = at(0.0, nu);
                let d1 = at(ratio, nu) - i0;
                let d2 = at(2.0 * ratio, nu) - i0;
                worst = worst.max((d2 - 2.0 * d1).norm());
                scale = scale.max(d1.norm());
                peak = peak.max(i0.norm());
            }
            assert!(
                // Rounding of I itself (1e-16 relative) is the floor.
                worst <= 300.0 * ratio * scale + 1e-14 * peak,
                "Γ₂/Γ₀ = {ratio}: second-order residual {worst:e} against first-order {scale:e}"
            );
        }
    }

    /// The algebraic square root is num_complex's (polar) principal root to rounding.
    #[test]
    fn principal_sqrt_is_the_principal_root() {
        for (a, b) in [
            (4.0, 0.0),
            (-4.0, 0.0),
            (0.0, 4.0),
            (0.0, -4.0),
            (-4.0, -0.0),
            (3.0, -4.0),
            (-3.0, 4.0),
            (-3.0, -4.0),
            (1e21, 3e7),
            (-2e-9, 5e-12),
        ] {
            let z = Complex64::new(a, b);
            let (p, q) = (principal_sqrt(z), z.sqrt());
            assert!(
                (p - q).norm() <= 1e-15 * q.norm(),
                "√({a} + {b}i): {p} vs {q}"
            );
        }
    }

    /// Speed dependence narrows the line: a higher peak and weaker near wings than the Voigt
    /// of the same Γ₀, by about 1 % at R(16)e's 1 atm parameters (the NIST fits' size).
    #[test]
    fn speed_dependence_raises_the_peak() {
        let sd = HtParameters {
            nu_vc: 0.0,
            ..r16(1.0)
        };
        let v = HtParameters { gamma2: 0.0, ..sd };
        let centre = sd.nu0 + sd.delta0;
        let ratio = hartmann_tran(&sd, centre).re / hartmann_tran(&v, centre).re;
        assert!(ratio > 1.003 && ratio < 1.03, "peak ratio {ratio}");
    }
}
