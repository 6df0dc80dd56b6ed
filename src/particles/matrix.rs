//! Scattering matrices for polarised transport (issue 16).
//!
//! For a macroscopically isotropic, mirror-symmetric medium (spheres, randomly oriented
//! particles with their mirror images) the 4 × 4 scattering matrix has six independent
//! elements (van de Hulst 1957, §5.22; Hovenier, van der Mee & Domke 2004, §2.7):
//!
//! ```text
//!        | F11  F12   0    0  |
//!   F =  | F12  F22   0    0  |
//!        |  0    0   F33  F34 |
//!        |  0    0  −F34  F44 |
//! ```
//!
//! acting on Stokes vectors (I, Q, U, V) whose reference plane is the scattering plane (Q > 0:
//! the electric field parallel to it), the convention of Bohren & Huffman (1983, §3.3) and
//! Hansen & Travis (1974, Space Sci. Rev. 16, 527). F11 is the phase function, normalised here
//! as everywhere in lidarsim so that its integral over the sphere is 4π; the other elements
//! carry the same normalisation. The transport samples directions from F11 (the scalar
//! [`super::phase::PhaseFunction`] of the same scatterer) and applies the ratios F_ij/F11.

use std::sync::Arc;

use super::phase::PhaseFunction;

/// The six elements at one scattering angle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatrixElements {
    /// Phase function (per 4π).
    pub f11: f64,
    /// Linear-polarisation elements.
    pub f22: f64,
    /// Elements of U and V.
    pub f33: f64,
    /// Circular-polarisation element.
    pub f44: f64,
    /// Coupling of I and Q (negative where scattering polarises perpendicular to the plane).
    pub f12: f64,
    /// Coupling of U and V.
    pub f34: f64,
}

impl MatrixElements {
    /// The matrix of a scatterer that does not change the state of polarisation:
    /// F22 = F33 = F44 = F11, F12 = F34 = 0.
    #[inline]
    pub fn non_depolarising(f11: f64) -> Self {
        MatrixElements {
            f11,
            f22: f11,
            f33: f11,
            f44: f11,
            f12: 0.0,
            f34: 0.0,
        }
    }
}

/// A scatterer's matrix, evaluated at μ = cos Θ.
#[derive(Debug, Clone)]
pub enum ScatteringMatrix {
    /// A scalar phase function used as if it did not depolarise (Henyey-Greenstein and other
    /// scalar phase functions in a polarised run).
    NonDepolarising(Arc<PhaseFunction>),
    /// Molecules with depolarisation factor ρ (Hansen & Travis 1974, eqs. 2.15–2.16):
    /// Δ = (1 − ρ)/(1 + ρ/2), Δ' = (1 − 2ρ)/(1 − ρ);
    /// F11 = ¾Δ(1 + μ²) + 1 − Δ, F22 = ¾Δ(1 + μ²), F12 = −¾Δ(1 − μ²),
    /// F33 = (3/2)Δ μ, F44 = (3/2)ΔΔ' μ, F34 = 0. F11 equals the scalar Rayleigh phase function
    /// of Bucholtz (1995, eq. 12) with γ = ρ/(2 − ρ).
    Rayleigh {
        /// Δ.
        delta: f64,
        /// Δ'.
        delta_prime: f64,
    },
    /// A table on nodes in μ, linear in μ between them (as the scalar table of its F11).
    Tabulated(Arc<TabulatedMatrix>),
}

impl ScatteringMatrix {
    /// The molecular matrix for depolarisation factor ρ ∈ [0, 0.5).
    pub fn rayleigh(rho: f64) -> Self {
        ScatteringMatrix::Rayleigh {
            delta: (1.0 - rho) / (1.0 + 0.5 * rho),
            delta_prime: (1.0 - 2.0 * rho) / (1.0 - rho),
        }
    }

    /// The matrix a scalar phase function stands for: molecules' from their depolarisation
    /// factor (ρ = 2γ/(1 + γ) of the scalar form's γ = ρ/(2 − ρ)); any other scatters without
    /// depolarising.
    pub fn of_phase(p: &Arc<PhaseFunction>) -> Self {
        match &**p {
            PhaseFunction::Rayleigh(r) => {
                let g = r.gamma();
                ScatteringMatrix::rayleigh(2.0 * g / (1.0 + g))
            }
            _ => ScatteringMatrix::NonDepolarising(p.clone()),
        }
    }

    /// The six elements at μ = cos Θ.
    #[inline]
    pub fn eval(&self, mu: f64) -> MatrixElements {
        match self {
            ScatteringMatrix::NonDepolarising(p) => MatrixElements::non_depolarising(p.eval(mu)),
            ScatteringMatrix::Rayleigh { delta, delta_prime } => {
                let (d, dp) = (*delta, *delta_prime);
                let f22 = 0.75 * d * (1.0 + mu * mu);
                MatrixElements {
                    f11: f22 + 1.0 - d,
                    f22,
                    f33: 1.5 * d * mu,
                    f44: 1.5 * d * dp * mu,
                    f12: -0.75 * d * (1.0 - mu * mu),
                    f34: 0.0,
                }
            }
            ScatteringMatrix::Tabulated(t) => t.eval(mu),
        }
    }

    /// True for a scalar phase function standing in for a matrix.
    pub fn is_stand_in(&self) -> bool {
        matches!(self, ScatteringMatrix::NonDepolarising(_))
    }
}

/// Six elements tabulated on nodes μ_i (strictly increasing from −1 to 1), linear in μ between
/// them. `f11` must be the same function as the scalar phase function the transport samples.
#[derive(Debug, Clone, PartialEq)]
pub struct TabulatedMatrix {
    mu: Vec<f64>,
    /// Per node: F11, F22, F33, F44, F12, F34.
    values: Vec<[f64; 6]>,
    /// False for a table without F44 and F34, which only linear polarisation may use.
    pub circular: bool,
}

impl TabulatedMatrix {
    /// From nodes in μ (strictly increasing, −1 to 1) and the elements at each, already
    /// normalised and checked.
    pub fn from_nodes(mu: Vec<f64>, values: Vec<[f64; 6]>, circular: bool) -> Self {
        TabulatedMatrix {
            mu,
            values,
            circular,
        }
    }

    /// The elements at μ, linear between nodes.
    #[inline]
    pub fn eval(&self, mu: f64) -> MatrixElements {
        let mu = mu.clamp(-1.0, 1.0);
        let n = self.mu.len();
        let i = self
            .mu
            .partition_point(|m| *m <= mu)
            .saturating_sub(1)
            .min(n - 2);
        let t = (mu - self.mu[i]) / (self.mu[i + 1] - self.mu[i]);
        let (a, b) = (&self.values[i], &self.values[i + 1]);
        let v = |j: usize| a[j] + t * (b[j] - a[j]);
        MatrixElements {
            f11: v(0),
            f22: v(1),
            f33: v(2),
            f44: v(3),
            f12: v(4),
            f34: v(5),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::particles::phase::RayleighPhase;

    /// The molecular F11 is the scalar Rayleigh phase function, and single backscatter by air
    /// has the linear depolarisation ratio (F11 − F22)/(F11 + F22) = ρ/(2 − ρ) (Behrendt &
    /// Nakamura 2002, Opt. Express 10, 805).
    #[test]
    fn rayleigh_matrix_matches_the_scalar_phase_and_the_backscatter_depolarisation() {
        for rho in [0.0, 0.0284, 0.0365, 0.1] {
            let m = ScatteringMatrix::rayleigh(rho);
            let p = RayleighPhase::from_depolarisation(rho).unwrap();
            for i in 0..=20 {
                let mu = -1.0 + 0.1 * i as f64;
                assert!(
                    (m.eval(mu).f11 - p.eval(mu)).abs() < 1e-14,
                    "ρ {rho} μ {mu}"
                );
            }
            let e = m.eval(-1.0);
            let delta = (e.f11 - e.f22) / (e.f11 + e.f22);
            assert!((delta - rho / (2.0 - rho)).abs() < 1e-15, "ρ {rho}");
        }
    }
}
