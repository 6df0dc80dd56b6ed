//! Scattering matrices for polarised transport (`docs/particles.md`, "Scattering matrices (polarisation)").
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
//!
//! # Which matrices are physical
//!
//! A scattering matrix of such a medium is a sum of pure (single-particle, Jones-derived)
//! Mueller matrices. For the six-element form this holds if and only if (Hovenier, van de Hulst
//! & van der Mee 1986, A&A 157, 301; Hovenier & van der Mee 1996, JQSRT 55, 649, "Testing
//! scattering matrices: a compendium of recipes"; Hovenier, van der Mee & Domke 2004, §2.7)
//!
//! ```text
//! (M1) |F_ij| ≤ F11 for every element, in particular F22 ≤ F11
//! (M2) |F22 − F12| ≤ F11 − F12,   |F22 + F12| ≤ F11 + F12
//! (M3) |F33 − F44| ≤ F11 − F22
//! (M4) (F33 + F44)² + 4 F34² ≤ (F11 + F22)² − 4 F12²
//! ```
//!
//! We could not read those texts through the sources available to us; the set is checked
//! here against its derivation instead ([`MatrixElements::mueller_violation`], unit tests): in
//! the Pauli basis the coherency matrix of Cloude (1986, Optik 75, 26) of a mirror-symmetric,
//! reciprocal ensemble of Jones matrices [[S2, S3], [S4, S1]] is block diagonal,
//! `[[A, C], [C*, B]] ⊕ diag(D, E)` with
//!
//! ```text
//! A = (F11 + F22) + (F33 + F44),   B = (F11 + F22) − (F33 + F44),   C = 2 F12 − 2i F34,
//! D = (F11 − F22) + (F33 − F44),   E = (F11 − F22) − (F33 − F44),
//! ```
//!
//! and the matrix is a sum of pure Mueller matrices exactly when it is positive semi-definite:
//! D, E ≥ 0 is (M3), A B ≥ |C|² is (M4), and (M1), (M2) follow from these with
//! F11 + F22 ≥ 0. A single sphere is on the boundary: F22 = F11, F44 = F33 and
//! F12² + F33² + F34² = F11² (equality in M3 and M4).

use std::sync::Arc;

use super::phase::{PhaseFunction, SegmentGuide};

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

/// Relative tolerance of the checks of tabulated matrices against the inequalities (M1)–(M4)
/// of the module documentation, in units of F11: a table printed to 6 significant digits
/// (rounding ≤ 5e-6 F11 per element, at most four elements in one inequality: ≤ 2e-5 F11)
/// never fails by rounding alone, and a row broken by more than 1e-4 F11 is refused.
pub const MUELLER_TOLERANCE: f64 = 1e-4;

/// One inequality of (M1)–(M4) (module documentation) that a matrix breaks.
#[derive(Debug, Clone, PartialEq)]
pub struct MuellerViolation {
    /// The element (column) the inequality bounds: `F11` … `F34`.
    pub element: &'static str,
    /// The inequality, as text with its label.
    pub inequality: &'static str,
    /// Left-hand side minus right-hand side, in units of F11 (> the tolerance).
    pub excess: f64,
}

impl std::fmt::Display for MuellerViolation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "breaks {} by {:.3e} × F11 (no sum of pure Mueller matrices has these elements)",
            self.inequality, self.excess
        )
    }
}

impl MatrixElements {
    /// The first inequality of (M1)–(M4) (module documentation) broken by more than
    /// `rel_tol` × F11, or `None`; F11 ≤ 0 (or NaN) is reported first. (M4) is tested in the equivalent form
    /// √((F33 + F44)² + 4F34² + 4F12²) ≤ F11 + F22 (equivalent once F11 + F22 ≥ 0, which (M1)
    /// checks first), linear in the elements so that the tolerance means the same everywhere.
    pub fn mueller_violation(&self, rel_tol: f64) -> Option<MuellerViolation> {
        let MatrixElements {
            f11,
            f22,
            f33,
            f44,
            f12,
            f34,
        } = *self;
        let m1 = [
            ("F22", "(M1) |F22| ≤ F11", f22.abs() - f11),
            ("F33", "(M1) |F33| ≤ F11", f33.abs() - f11),
            ("F44", "(M1) |F44| ≤ F11", f44.abs() - f11),
            ("F12", "(M1) |F12| ≤ F11", f12.abs() - f11),
            ("F34", "(M1) |F34| ≤ F11", f34.abs() - f11),
        ];
        let m34 = [
            (
                "F44",
                "(M3) |F33 − F44| ≤ F11 − F22",
                (f33 - f44).abs() - (f11 - f22),
            ),
            (
                "F34",
                "(M4) (F33 + F44)² + 4F34² ≤ (F11 + F22)² − 4F12²",
                (f33 + f44).hypot(2.0 * f34).hypot(2.0 * f12) - (f11 + f22),
            ),
        ];
        first_violation(self, &m1, &m34, rel_tol)
    }

    /// The check of [`Self::mueller_violation`] for a table without F44 and F34 (linear
    /// polarisation only): F11, F22, F33, F12 pass when some F44 and F34 complete them to a
    /// matrix that passes. (M1) and (M2) do not involve them; F34 = 0 is best for (M4), and over
    /// the F44 that (M3) allows, [F33 − (F11 − F22), F33 + (F11 − F22)], the smallest
    /// |F33 + F44| is max(0, 2|F33| − (F11 − F22)), so (M3)–(M4) become
    ///
    /// ```text
    /// (M34) max(0, 2|F33| − (F11 − F22))² + 4F12² ≤ (F11 + F22)²
    /// ```
    ///
    /// (with F22 ≤ F11 from (M1)). `f44` and `f34` are ignored.
    pub fn linear_mueller_violation(&self, rel_tol: f64) -> Option<MuellerViolation> {
        let MatrixElements {
            f11, f22, f33, f12, ..
        } = *self;
        let m1 = [
            ("F22", "(M1) |F22| ≤ F11", f22.abs() - f11),
            ("F33", "(M1) |F33| ≤ F11", f33.abs() - f11),
            ("F12", "(M1) |F12| ≤ F11", f12.abs() - f11),
        ];
        let m34 = [(
            "F33",
            "(M3–M4 without F44, F34) max(0, 2|F33| − (F11 − F22))² + 4F12² ≤ (F11 + F22)²",
            (2.0 * f33.abs() - (f11 - f22)).max(0.0).hypot(2.0 * f12) - (f11 + f22),
        )];
        first_violation(self, &m1, &m34, rel_tol)
    }

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
#[derive(Debug, Clone, PartialEq)]
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

/// (element, inequality, left side minus right side) of one Mueller inequality.
type Check = (&'static str, &'static str, f64);

/// The first inequality `m` breaks by more than `rel_tol`·F11, or None.
///
/// Both checks share F11 > 0 (first, so that the excesses below are relative to a positive
/// F11) and the two (M2) inequalities, which involve only F11, F22 and F12; they come after
/// the element-wise (M1) bounds, so a violation is reported by the simplest rule it breaks.
fn first_violation(
    m: &MatrixElements,
    m1: &[Check],
    rest: &[Check],
    rel_tol: f64,
) -> Option<MuellerViolation> {
    let MatrixElements { f11, f22, f12, .. } = *m;
    if !(f11 > 0.0) {
        return Some(MuellerViolation {
            element: "F11",
            inequality: "F11 > 0",
            excess: f64::INFINITY,
        });
    }
    let m2 = [
        (
            "F12",
            "(M2) |F22 − F12| ≤ F11 − F12",
            (f22 - f12).abs() - (f11 - f12),
        ),
        (
            "F12",
            "(M2) |F22 + F12| ≤ F11 + F12",
            (f22 + f12).abs() - (f11 + f12),
        ),
    ];
    m1.iter()
        .chain(&m2)
        .chain(rest)
        .find_map(|&(element, inequality, diff)| {
            // `!(… <= …)` also catches NaN.
            (!(diff <= rel_tol * f11)).then_some(MuellerViolation {
                element,
                inequality,
                excess: diff / f11,
            })
        })
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
    /// Segment lookup (the scalar table's: O(1) at the forward peak and the glory alike).
    guide: SegmentGuide,
}

impl TabulatedMatrix {
    /// From nodes in μ (strictly increasing, −1 to 1) and the elements at each, already
    /// normalised and checked.
    pub fn from_nodes(mu: Vec<f64>, values: Vec<[f64; 6]>, circular: bool) -> Self {
        TabulatedMatrix {
            guide: SegmentGuide::new(&mu),
            mu,
            values,
            circular,
        }
    }

    /// The elements at μ, linear between nodes.
    #[inline]
    pub fn eval(&self, mu: f64) -> MatrixElements {
        let mu = mu.clamp(-1.0, 1.0);
        let i = self.guide.segment(&self.mu, mu);
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
    use num_complex::Complex64 as C;
    use rand::{RngExt, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// The Mueller matrix of a Jones matrix J = [[S2, S3], [S4, S1]] acting on (E∥, E⊥)
    /// (Bohren & Huffman 1983, eq. 3.12), from its definition: the coherencies
    /// c = (E∥E∥*, E∥E⊥*, E⊥E∥*, E⊥E⊥*) go to (J ⊗ J*) c, and the Stokes vector is A c with
    /// I = |E∥|² + |E⊥|², Q = |E∥|² − |E⊥|², U = 2 Re E∥E⊥*, V = −2 Im E∥E⊥* (BH eq. 2.84),
    /// so M = A (J ⊗ J*) A⁻¹. Written without any of the element formulas under test.
    fn mueller_of_jones(j: [[C; 2]; 2]) -> [[f64; 4]; 4] {
        let i = C::new(0.0, 1.0);
        let (o, z) = (C::new(1.0, 0.0), C::new(0.0, 0.0));
        let a = [[o, z, z, o], [o, z, z, -o], [z, o, o, z], [z, i, -i, z]];
        let a_inv = [
            [o * 0.5, o * 0.5, z, z],
            [z, z, o * 0.5, -i * 0.5],
            [z, z, o * 0.5, i * 0.5],
            [o * 0.5, -o * 0.5, z, z],
        ];
        // (J ⊗ J*)[(p,q),(r,s)] = J[p][r] J[q][s]*, index (p,q) → 2p + q.
        let mut k = [[z; 4]; 4];
        for p in 0..2 {
            for q in 0..2 {
                for r in 0..2 {
                    for t in 0..2 {
                        k[2 * p + q][2 * r + t] = j[p][r] * j[q][t].conj();
                    }
                }
            }
        }
        let mul = |x: &[[C; 4]; 4], y: &[[C; 4]; 4]| {
            let mut out = [[z; 4]; 4];
            for r in 0..4 {
                for c in 0..4 {
                    out[r][c] = (0..4).map(|m| x[r][m] * y[m][c]).sum();
                }
            }
            out
        };
        let m = mul(&mul(&a, &k), &a_inv);
        let mut out = [[0.0; 4]; 4];
        for r in 0..4 {
            for c in 0..4 {
                assert!(m[r][c].im.abs() < 1e-12, "Mueller matrix not real");
                out[r][c] = m[r][c].re;
            }
        }
        out
    }

    fn random_c(rng: &mut Xoshiro256PlusPlus) -> C {
        C::new(
            rng.random::<f64>() * 2.0 - 1.0,
            rng.random::<f64>() * 2.0 - 1.0,
        )
    }

    /// Sums of pure Mueller matrices of random particles, each with its mirror image and its
    /// reciprocal partner (the ensemble of a macroscopically isotropic, mirror-symmetric
    /// medium), pass the checks to rounding (the inequalities are necessary); the ensemble
    /// has the six-element form (the construction is right). Single spheres (diagonal J) lie on
    /// the boundary: a 1e-3 push outward is refused.
    #[test]
    fn sums_of_pure_mueller_matrices_pass_and_spheres_are_on_the_boundary() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(16);
        let six = |m: &[[f64; 4]; 4]| MatrixElements {
            f11: m[0][0],
            f22: m[1][1],
            f33: m[2][2],
            f44: m[3][3],
            f12: m[0][1],
            f34: m[2][3],
        };
        for trial in 0..2000 {
            let mut sum = [[0.0; 4]; 4];
            let particles = 1 + trial % 4;
            for _ in 0..particles {
                let (s1, s2) = (random_c(&mut rng), random_c(&mut rng));
                // A third of the particles are spheres (S3 = S4 = 0).
                let (s3, s4) = if rng.random::<f64>() < 0.33 {
                    (C::new(0.0, 0.0), C::new(0.0, 0.0))
                } else {
                    (random_c(&mut rng), random_c(&mut rng))
                };
                let w: f64 = rng.random();
                for j in [
                    [[s2, s3], [s4, s1]],
                    [[s2, -s3], [-s4, s1]],
                    [[s2, -s4], [-s3, s1]],
                    [[s2, s4], [s3, s1]],
                ] {
                    let m = mueller_of_jones(j);
                    for r in 0..4 {
                        for c in 0..4 {
                            sum[r][c] += w * m[r][c];
                        }
                    }
                }
            }
            let scale = sum[0][0];
            for (r, c) in [
                (0, 2),
                (0, 3),
                (1, 2),
                (1, 3),
                (2, 0),
                (2, 1),
                (3, 0),
                (3, 1),
            ] {
                assert!(
                    sum[r][c].abs() < 1e-12 * scale,
                    "[{r}][{c}] = {}",
                    sum[r][c]
                );
            }
            assert!((sum[1][0] - sum[0][1]).abs() < 1e-12 * scale);
            assert!((sum[3][2] + sum[2][3]).abs() < 1e-12 * scale);
            let e = six(&sum);
            assert_eq!(e.mueller_violation(1e-12), None, "{e:?}");
            assert_eq!(e.linear_mueller_violation(1e-12), None, "{e:?}");
        }
        for _ in 0..200 {
            let (s1, s2) = (random_c(&mut rng), random_c(&mut rng));
            let z = C::new(0.0, 0.0);
            let e = six(&mueller_of_jones([[s2, z], [z, s1]]));
            assert_eq!(e.f22, e.f11);
            assert!((e.f44 - e.f33).abs() < 1e-14 * e.f11);
            // On (M4)'s boundary: F12² + F33² + F34² = F11².
            let r = (e.f12.powi(2) + e.f33.powi(2) + e.f34.powi(2)) / e.f11.powi(2);
            assert!((r - 1.0).abs() < 1e-12, "{r}");
            let mut out = e;
            out.f34 = e.f34 + 1e-3 * e.f11 * e.f34.signum();
            if e.f34.abs() > 0.1 * e.f11 {
                assert_eq!(out.mueller_violation(1e-4).map(|v| v.element), Some("F34"));
            }
        }
    }

    /// The checks accept exactly the matrices whose coherency matrix (module documentation) is
    /// positive semi-definite: random elements in [−1, 1] with F11 = 1, against the eigenvalues
    /// of [[A, C], [C*, B]] and D, E (cases within 1e-9 of the boundary left out). The
    /// linear-only check accepts exactly the rows some F44 (searched on a grid) and F34 = 0
    /// complete to an accepted matrix.
    #[test]
    fn checks_agree_with_the_coherency_matrix() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(649);
        let (mut accepted, mut refused) = (0, 0);
        for _ in 0..200_000 {
            let mut r = || 2.0 * rng.random::<f64>() - 1.0;
            let e = MatrixElements {
                f11: 1.0,
                f22: r(),
                f33: r(),
                f44: r(),
                f12: 0.5 * r(),
                f34: 0.5 * r(),
            };
            let a = (e.f11 + e.f22) + (e.f33 + e.f44);
            let b = (e.f11 + e.f22) - (e.f33 + e.f44);
            let c2 = 4.0 * e.f12 * e.f12 + 4.0 * e.f34 * e.f34;
            let d = (e.f11 - e.f22) + (e.f33 - e.f44);
            let ee = (e.f11 - e.f22) - (e.f33 - e.f44);
            let lo = 0.5 * (a + b) - (0.25 * (a - b) * (a - b) + c2).sqrt();
            let min_eig = lo.min(d).min(ee);
            if min_eig.abs() < 1e-9 {
                continue;
            }
            let ok = e.mueller_violation(0.0).is_none();
            assert_eq!(ok, min_eig > 0.0, "{e:?}: smallest eigenvalue {min_eig}");
            if ok {
                accepted += 1;
            } else {
                refused += 1;
            }
        }
        assert!(accepted > 1000 && refused > 1000, "{accepted} {refused}");

        let mut rng = Xoshiro256PlusPlus::seed_from_u64(650);
        for _ in 0..3000 {
            let mut r = || 2.0 * rng.random::<f64>() - 1.0;
            let e = MatrixElements {
                f11: 1.0,
                f22: r(),
                f33: r(),
                f44: 0.0,
                f12: 0.5 * r(),
                f34: 0.0,
            };
            let lin = e.linear_mueller_violation(0.0);
            if lin.as_ref().is_some_and(|v| v.excess < 1e-3) {
                continue; // too near the boundary for the grid
            }
            if lin.is_none() {
                // Accepted rows are completed by the F44 the derivation names.
                let d = e.f11 - e.f22;
                let f44 = (-e.f33).clamp(e.f33 - d, e.f33 + d);
                assert_eq!(MatrixElements { f44, ..e }.mueller_violation(1e-12), None);
            } else {
                let completed = (0..=20_000).any(|i| {
                    let f44 = -1.0 + i as f64 * 1e-4;
                    MatrixElements { f44, ..e }.mueller_violation(0.0).is_none()
                });
                assert!(!completed, "{e:?} refused but completed");
            }
        }
    }

    /// F₁₁ must be positive (the documented first check, by both checks): a row with F₁₁ = 0
    /// exactly, and every other element 0, passes every inequality relative to F₁₁ but is
    /// refused; so are F₁₁ < 0 and NaN.
    #[test]
    fn f11_must_be_positive() {
        for f11 in [0.0, -0.0, -1e-300, -1.0, f64::NAN] {
            let m = MatrixElements::non_depolarising(f11);
            for v in [m.mueller_violation(1e-4), m.linear_mueller_violation(1e-4)] {
                let v = v.unwrap_or_else(|| panic!("F11 = {f11} accepted"));
                assert_eq!((v.element, v.inequality), ("F11", "F11 > 0"), "F11 = {f11}");
            }
        }
        let tiny = MatrixElements::non_depolarising(1e-300);
        assert_eq!(tiny.mueller_violation(1e-4), None);
    }

    /// The molecular matrix of Hansen & Travis (1974) is physical for every depolarisation
    /// factor of air and beyond, ρ ∈ [0, 0.1]; at μ = ±1 it lies on (M3)'s boundary.
    #[test]
    fn rayleigh_matrix_satisfies_the_mueller_inequalities() {
        for i in 0..=100 {
            let rho = 1e-3 * i as f64;
            let m = ScatteringMatrix::rayleigh(rho);
            for j in 0..=2000 {
                let mu = -1.0 + 1e-3 * j as f64;
                let e = m.eval(mu);
                assert_eq!(e.mueller_violation(1e-14), None, "ρ {rho} μ {mu}: {e:?}");
            }
            let e = m.eval(1.0);
            let slack = (e.f11 - e.f22) - (e.f33 - e.f44).abs();
            assert!(slack.abs() < 1e-14, "ρ {rho}: {slack}");
        }
    }

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
