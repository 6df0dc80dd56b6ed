//! Stokes vectors for polarised transport (`docs/transport.md`, "Polarisation"): one place for
//! the frame convention, the rotation into the scattering plane and the analyser.
//!
//! **Convention.** A beam travelling along the unit vector d carries a reference axis e₁ ⊥ d
//! (a unit vector, carried with the photon) and e₂ = d × e₁, so that (e₁, e₂, d) is right-handed.
//! With the electric field E = E₁ e₁ + E₂ e₂ the Stokes vector is I = |E₁|² + |E₂|²,
//! Q = |E₁|² − |E₂|², U = 2 Re(E₁E₂*), V = −2 Im(E₁E₂*) (van de Hulst 1957, §5.12, with
//! (e₁, e₂) the parallel and perpendicular directions): Q > 0 is light polarised along e₁,
//! U > 0 along (e₁ + e₂)/√2. Turning the reference axis by ψ toward e₂, e₁' = cos ψ e₁ +
//! sin ψ e₂, gives Q' = Q cos 2ψ + U sin 2ψ, U' = −Q sin 2ψ + U cos 2ψ, V' = V (from the field
//! components in the new axes).
//!
//! **Scattering.** From direction d to d', the scattering plane has the normal n = d × d'/|d × d'|;
//! the incident beam is first referred to e₁ = n × d (in the plane, so e₂ = n), the scattering
//! matrix F of `particles::matrix` (Bohren & Huffman 1983, §3.3: parallel and perpendicular to
//! the plane) applied, and the scattered beam is referred to e₁' = n × d' (again e₂' = n). This
//! "frame carried as a vector" avoids the meridian plane and its poles (Hovenier & van der Mee
//! 1983 refer to it; the scattering matrix is the same in either right-handed frame, since U
//! and V change sign together). In a forward or backward scattering (|d × d'| ≈ 0) the plane
//! is taken through e₂ of the incident frame, with no rotation.
//!
//! **Weights.** Directions are sampled from F₁₁ exactly as in scalar transport (the phase
//! function, with a uniform azimuth); the photon's intensity weight then takes the factor
//! (F₁₁ + F₁₂ q)/F₁₁ of its reduced Stokes vector (q, u, v) = (Q, U, V)/I in the scattering
//! plane, and its reduced vector becomes the scattered one over its intensity. The mean over the
//! azimuth of that factor is 1 (q varies as cos 2φ), so the scalar intensity is unchanged in
//! expectation and the matrix acts as a weight, unbiased.

use glam::DVec3;

use crate::particles::matrix::MatrixElements;

/// Reduced Stokes vector (Q, U, V)/I.
pub(crate) type Reduced = [f64; 3];

/// The geometry of one scattering: the rotation of the incident Stokes vector into the
/// scattering plane (cos 2ψ, sin 2ψ) and the reference axis of the scattered beam.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Turn {
    c2: f64,
    s2: f64,
    /// Reference axis of the scattered beam (unit, ⊥ d').
    pub e1: DVec3,
}

/// Below this |d × d'|² the scattering plane is taken as that of e₂ (no rotation).
const PARALLEL: f64 = 1e-24;

impl Turn {
    /// From the incident direction `d` with reference axis `e1` to the direction `d2`.
    #[inline]
    pub fn new(d: DVec3, e1: DVec3, d2: DVec3) -> Self {
        let e2 = d.cross(e1);
        let n = d.cross(d2);
        let n2 = n.length_squared();
        if !(n2 > PARALLEL) {
            // Forward or backward: the plane through e₂ (e₁ = e₂ × d is the current axis).
            return Turn {
                c2: 1.0,
                s2: 0.0,
                e1: e2.cross(d2).normalize(),
            };
        }
        let n = n / n2.sqrt();
        // The plane's parallel axis for the incident beam, e₁ₛ = n × d = cos ψ e₁ + sin ψ e₂.
        let es = n.cross(d);
        let (c, s) = (es.dot(e1), es.dot(e2));
        // Renormalised against rounding: cos²ψ + sin²ψ = 1.
        let r2 = c * c + s * s;
        Turn {
            c2: (c * c - s * s) / r2,
            s2: 2.0 * c * s / r2,
            e1: n.cross(d2),
        }
    }

    /// The scattered Stokes vector (I, Q, U, V) per unit incident intensity, for the reduced
    /// incident vector `p` and the matrix elements `m` at this angle.
    #[inline]
    pub fn apply(&self, p: Reduced, m: &MatrixElements) -> [f64; 4] {
        let q = p[0] * self.c2 + p[1] * self.s2;
        let u = -p[0] * self.s2 + p[1] * self.c2;
        let v = p[2];
        [
            m.f11 + m.f12 * q,
            m.f12 + m.f22 * q,
            m.f33 * u + m.f34 * v,
            -m.f34 * u + m.f44 * v,
        ]
    }
}

/// The scattered beam as a weight factor and a reduced vector: `s` from [`Turn::apply`], `f11`
/// the phase function the direction was sampled with.
#[inline]
pub(crate) fn reduce(s: [f64; 4], f11: f64) -> (f64, Reduced) {
    if !(s[0] > 0.0) {
        return (0.0, [0.0; 3]);
    }
    let inv = 1.0 / s[0];
    (s[0] / f11, [s[1] * inv, s[2] * inv, s[3] * inv])
}

/// What the receiver separates: the co- and cross-polarised parts of a returning beam. `co` is
/// what a sphere's single backscatter returns: light polarised along the emitted axis for a
/// linear source, the opposite helicity (V < 0 about the returning direction) for a circular one.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Analyser {
    /// The emitted polarisation axis (unit, ⊥ the pointing).
    Linear(DVec3),
    Circular,
}

/// The analyser's rotation for one returning beam.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Analysis {
    c2: f64,
    s2: f64,
    circular: bool,
}

impl Analyser {
    /// For a beam travelling along `omega` with reference axis `e1`.
    #[inline]
    pub fn toward(&self, omega: DVec3, e1: DVec3) -> Analysis {
        match self {
            Analyser::Circular => Analysis {
                c2: 1.0,
                s2: 0.0,
                circular: true,
            },
            Analyser::Linear(axis) => {
                // The emitted axis seen across the returning beam.
                let ea = *axis - omega * axis.dot(omega);
                let (c, s) = (ea.dot(e1), ea.dot(omega.cross(e1)));
                let r2 = c * c + s * s;
                if !(r2 > 0.0) {
                    // The beam travels along the emitted axis: no preferred direction.
                    return Analysis {
                        c2: 0.0,
                        s2: 0.0,
                        circular: false,
                    };
                }
                Analysis {
                    c2: (c * c - s * s) / r2,
                    s2: 2.0 * c * s / r2,
                    circular: false,
                }
            }
        }
    }
}

impl Analysis {
    /// (co, cross) of the Stokes vector `s` = (I, Q, U, V).
    #[inline]
    pub fn split(&self, s: [f64; 4]) -> (f64, f64) {
        let x = if self.circular {
            -s[3]
        } else {
            s[1] * self.c2 + s[2] * self.s2
        };
        (0.5 * (s[0] + x), 0.5 * (s[0] - x))
    }
}

/// The reference axis and reduced Stokes vector of light emitted along `dir`: linear along the
/// emitted axis `axis_e1` (⊥ the pointing) projected across `dir`, or circular (V = +1).
pub(crate) fn emitted(dir: DVec3, axis_e1: DVec3, circular: bool) -> (DVec3, Reduced) {
    let e = axis_e1 - dir * axis_e1.dot(dir);
    let e1 = if e.length_squared() > 1e-24 {
        e.normalize()
    } else {
        dir.any_orthonormal_vector()
    };
    (
        e1,
        if circular {
            [0.0, 0.0, 1.0]
        } else {
            [1.0, 0.0, 0.0]
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere_backscatter() -> MatrixElements {
        MatrixElements {
            f11: 1.0,
            f22: 1.0,
            f33: -1.0,
            f44: -1.0,
            f12: 0.0,
            f34: 0.0,
        }
    }

    /// A sphere's exact backscatter returns the emitted state: linear along the emitted axis
    /// (co = I, cross = 0), and for circular light the opposite helicity about the returning
    /// direction (co = I). Whatever the incident reference axis was turned to.
    #[test]
    fn sphere_backscatter_is_all_co_polarised() {
        let d = DVec3::Z;
        let ex = DVec3::X;
        for circular in [false, true] {
            let (e1, p) = emitted(d, ex, circular);
            let back = -d;
            let t = Turn::new(d, e1, back);
            let s = t.apply(p, &sphere_backscatter());
            let an = if circular {
                Analyser::Circular
            } else {
                Analyser::Linear(ex)
            };
            let (co, cross) = an.toward(back, t.e1).split(s);
            assert!(
                (co - 1.0).abs() < 1e-15 && cross.abs() < 1e-15,
                "{circular}: {co} {cross}"
            );
        }
    }

    /// Rotating the reference axis does not change the light: two turns through an oblique
    /// scattering with a non-depolarising matrix keep |Q + iU| and V, and the analyser gives
    /// the same co and cross whatever reference axis the beam carries.
    #[test]
    fn reference_axis_does_not_matter() {
        let d = DVec3::new(0.2, -0.1, 1.0).normalize();
        let d2 = DVec3::new(-0.5, 0.3, -0.8).normalize();
        let m = MatrixElements::non_depolarising(2.0);
        let p: Reduced = [0.6, -0.3, 0.2];
        let e1a = d.any_orthonormal_vector();
        let ang: f64 = 0.7;
        let e1b = e1a * ang.cos() + d.cross(e1a) * ang.sin();
        // The same light referred to e1b: rotate p by ang.
        let (c2, s2) = ((2.0 * ang).cos(), (2.0 * ang).sin());
        let pb: Reduced = [p[0] * c2 + p[1] * s2, -p[0] * s2 + p[1] * c2, p[2]];
        let (ta, tb) = (Turn::new(d, e1a, d2), Turn::new(d, e1b, d2));
        let (sa, sb) = (ta.apply(p, &m), tb.apply(pb, &m));
        let an = Analyser::Linear(DVec3::X);
        let (ca, xa) = an.toward(d2, ta.e1).split(sa);
        let (cb, xb) = an.toward(d2, tb.e1).split(sb);
        assert!((ca - cb).abs() < 1e-13 && (xa - xb).abs() < 1e-13);
        let pol = |s: [f64; 4]| (s[1] * s[1] + s[2] * s[2]).sqrt();
        assert!((pol(sa) - 2.0 * (0.6f64.powi(2) + 0.3f64.powi(2)).sqrt()).abs() < 1e-13);
        assert!((sa[3] - 0.4).abs() < 1e-13);
    }

    /// Second-order backscatter by non-depolarising dipoles (Rayleigh, ρ = 0) over path pairs
    /// in a field of view, made axially symmetric by eight rotations: δ_C = 2δ_L/(1 − δ_L)
    /// (Mishchenko & Hovenier 1995), which needs every path's Jones matrix to be symmetric in
    /// backscattering. (With depolarising molecules, ρ = 0.03, the same sum gives δ_C 0.0629
    /// against 0.0646: the relation holds for their single backscatter only;
    /// `docs/transport.md`, "Polarisation".)
    #[test]
    fn second_order_backscatter_obeys_mishchenko_hovenier() {
        let m = crate::particles::matrix::ScatteringMatrix::rayleigh(0.0);
        let ex = DVec3::X;
        let (mut co, mut cross) = ([0.0; 2], [0.0; 2]);
        let mut seed = 12345u64;
        let mut u = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..2000 {
            let mut disc = |z: f64| {
                let (r, f) = (10.0 * u().sqrt(), 2.0 * std::f64::consts::PI * u());
                DVec3::new(r * f.cos(), r * f.sin(), z)
            };
            let (q1, q2) = (disc(1000.0), disc(1050.0));
            for rot in 0..8 {
                let (sa, ca) = (rot as f64 * std::f64::consts::FRAC_PI_4).sin_cos();
                let rz = |v: DVec3| DVec3::new(v.x * ca - v.y * sa, v.x * sa + v.y * ca, v.z);
                let (p1, p2) = (rz(q1), rz(q2));
                for (a, b) in [(p1, p2), (p2, p1)] {
                    for (c, circular) in [(0, false), (1, true)] {
                        let d0 = a.normalize();
                        let (e1, p) = emitted(d0, ex, circular);
                        let d1 = (b - a).normalize();
                        let t1 = Turn::new(d0, e1, d1);
                        let (i1, r1) = reduce(t1.apply(p, &m.eval(d0.dot(d1))), 1.0);
                        let d2 = -b.normalize();
                        let t2 = Turn::new(d1, t1.e1, d2);
                        let s2 = t2.apply(r1, &m.eval(d1.dot(d2)));
                        let an = if circular {
                            Analyser::Circular
                        } else {
                            Analyser::Linear(ex)
                        };
                        let (x, y) = an.toward(d2, t2.e1).split(s2);
                        co[c] += i1 * x;
                        cross[c] += i1 * y;
                    }
                }
            }
        }
        let (dl, dc) = (cross[0] / co[0], cross[1] / co[1]);
        let predicted = 2.0 * dl / (1.0 - dl);
        assert!(dl > 1e-4, "δ_L {dl}");
        assert!(
            (dc - predicted).abs() < 1e-5 * predicted,
            "δ_C {dc} against {predicted}"
        );
    }

    /// A beam of zero intensity carries no weight and no polarisation: a zero, finite reduced
    /// vector, not 0/0. Light polarised along the scattering plane (q = 1 in its frame: e₁ = x
    /// for z → x), scattered by dipoles at 90°, where F₁₂ = −F₁₁, has I = F₁₁ + F₁₂ q = 0.
    #[test]
    fn a_beam_of_zero_intensity_has_no_polarisation() {
        let m = crate::particles::matrix::ScatteringMatrix::rayleigh(0.0).eval(0.0);
        let s = Turn::new(DVec3::Z, DVec3::X, DVec3::X).apply([1.0, 0.0, 0.0], &m);
        assert_eq!(s[0], 0.0);
        assert_eq!(reduce(s, m.f11), (0.0, [0.0; 3]));
        assert_eq!(reduce([-1e-300, 0.5, 0.0, 0.0], 1.0), (0.0, [0.0; 3]));
    }

    /// Emitted light's reference axis is a unit vector across its direction (the frame
    /// convention), in the plane of the direction and the emitted axis, on the axis's side,
    /// for a beam far off the pointing as well; along the axis, any axis across it.
    #[test]
    fn emitted_reference_axis_is_the_axis_across_the_beam() {
        let axis = DVec3::X;
        for dir in [
            DVec3::Z,
            DVec3::new(0.6, 0.0, 0.8),
            DVec3::new(-0.3, 0.5, 0.7).normalize(),
            DVec3::X,
        ] {
            for circular in [false, true] {
                let (e1, p) = emitted(dir, axis, circular);
                assert!((e1.length() - 1.0).abs() < 1e-15, "{dir}");
                assert!(e1.dot(dir).abs() < 1e-15, "{dir}: e1 {e1}");
                if dir != DVec3::X {
                    assert!(e1.dot(axis) > 0.0 && e1.cross(axis).dot(dir).abs() < 1e-15);
                }
                let expected = if circular {
                    [0.0, 0.0, 1.0]
                } else {
                    [1.0, 0.0, 0.0]
                };
                assert_eq!(p, expected);
            }
        }
    }

    /// A linear analyser whose axis lies along the returning beam sees no direction across it:
    /// co and cross are half the intensity each, whatever the beam's polarisation.
    #[test]
    fn a_beam_along_the_analyser_axis_splits_evenly() {
        let an = Analyser::Linear(DVec3::X);
        for (omega, e1) in [(DVec3::X, DVec3::Y), (-DVec3::X, DVec3::Z)] {
            let (co, cross) = an.toward(omega, e1).split([2.0, 1.5, -0.5, 0.3]);
            assert_eq!((co, cross), (1.0, 1.0), "{omega}");
        }
    }

    /// Rayleigh scattering at 90° of unpolarised light polarises it fully perpendicular to the
    /// scattering plane: Q/I = −1 in the plane's frame (F₁₂ = −F₁₁ there for ρ = 0).
    #[test]
    fn rayleigh_at_ninety_degrees_polarises_perpendicular_to_the_plane() {
        let m = crate::particles::matrix::ScatteringMatrix::rayleigh(0.0).eval(0.0);
        let d = DVec3::Z;
        let d2 = DVec3::X;
        let t = Turn::new(d, DVec3::Y, d2);
        let s = t.apply([0.0; 3], &m);
        assert!((s[1] / s[0] + 1.0).abs() < 1e-15);
        // Perpendicular to the plane (x, z) is ±y: along the new e₂ = d2 × e1.
        assert!(t.e1.dot(DVec3::Z).abs() > 1.0 - 1e-15);
    }
}
