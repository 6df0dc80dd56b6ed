//! Interpolation of a [`Profile`] to other altitudes or pressures, and the hybrid
//! pressure-level shift used for surface-pressure changes and class means.
//!
//! Within a layer, ln p is linear in altitude (exact for an isothermal layer); temperature is
//! linear in altitude; the log of each mixing ratio is linear in ln p (a power law in p; linear
//! where one of the two values is zero). Since ln p is linear in z inside a layer, all use the
//! same weight, and interpolating to altitudes and to pressures are inverses of each other.
//! Log interpolation of mixing ratios makes partial densities log-linear between levels, the
//! assumption of the column integrals ([`super::column`]): a fine grid keeps the columns (a
//! linear interpolation of H2O on the 1-km AFGL grid adds 1.3 % to the tropical water column).
//! A constant mixing ratio stays constant. No extrapolation: a target outside the profile is an
//! error.

use super::{AtmosphereError, GasProfile, Profile};

/// Pressure \[Pa\] above which levels follow the surface in [`hybrid_shift_pa`]; above this
/// pressure level (lower pressures) levels stay at fixed pressure. 100 hPa: levels above the
/// tropopause region do not move (as in ECMWF's hybrid η levels, pure pressure aloft).
pub const HYBRID_TOP_PA: f64 = 10_000.0;

/// Move a pressure level when the surface pressure changes from `old_surface_pa` to
/// `new_surface_pa`: `p' = p + b(p) (p_s' − p_s)` with `b = clamp((p − p_t)/(p_s − p_t), 0, 1)`,
/// p_t = [`HYBRID_TOP_PA`]. Sigma-like near the surface (the surface maps to the surface),
/// pure pressure above p_t, monotonic whenever both surface pressures exceed p_t.
pub fn hybrid_shift_pa(p: f64, old_surface_pa: f64, new_surface_pa: f64) -> f64 {
    let b = ((p - HYBRID_TOP_PA) / (old_surface_pa - HYBRID_TOP_PA)).clamp(0.0, 1.0);
    p + b * (new_surface_pa - old_surface_pa)
}

/// Segment index k and weight w such that the coordinate c lies in [c_k, c_{k+1}] with
/// c = (1 − w) c_k + w c_{k+1}; `coords` strictly increasing.
fn locate(coords: &[f64], c: f64) -> (usize, f64) {
    let n = coords.len();
    let k = coords.partition_point(|&x| x <= c).clamp(1, n - 1) - 1;
    let w = (c - coords[k]) / (coords[k + 1] - coords[k]);
    (k, w.clamp(0.0, 1.0))
}

impl Profile {
    /// The profile at the given altitudes \[m\] (strictly increasing, within the profile's
    /// range): ln p and T linear in z, ln(mixing ratio) linear in ln p (see the module docs).
    pub fn interpolate_to_altitudes(&self, altitude_m: &[f64]) -> Result<Profile, AtmosphereError> {
        self.validate()?;
        check_targets(altitude_m, true, "altitude_m")?;
        let (lo, hi) = (self.altitude_m[0], self.altitude_m[self.len() - 1]);
        let ln_p: Vec<f64> = self.pressure_pa.iter().map(|p| p.ln()).collect();
        let mut at = Vec::with_capacity(altitude_m.len());
        for &z in altitude_m {
            let tol = 1e-9 * (hi - lo);
            if !(lo - tol..=hi + tol).contains(&z) {
                return Err(self.out_of_range("altitude_m", z, lo, hi));
            }
            let (k, w) = locate(&self.altitude_m, z);
            // ln p is linear in z; the mixing-ratio weight in ln p is then the same w.
            let p = match w {
                0.0 => self.pressure_pa[k],
                1.0 => self.pressure_pa[k + 1],
                _ => (ln_p[k] + w * (ln_p[k + 1] - ln_p[k])).exp(),
            };
            at.push((k, w, w, z, p));
        }
        Ok(self.build(&at))
    }

    /// The profile at the given pressures \[Pa\] (strictly decreasing, within the profile's
    /// range): z, T and ln(mixing ratio) linear in ln p (the inverse of
    /// [`Self::interpolate_to_altitudes`]).
    pub fn interpolate_to_pressures(
        &self,
        pressure_pa: &[f64],
    ) -> Result<Profile, AtmosphereError> {
        self.validate()?;
        check_targets(pressure_pa, false, "pressure_pa")?;
        let n = self.len();
        let (lo, hi) = (self.pressure_pa[n - 1], self.pressure_pa[0]);
        // Increasing coordinate: −ln p.
        let s: Vec<f64> = self.pressure_pa.iter().map(|p| -p.ln()).collect();
        let mut at = Vec::with_capacity(pressure_pa.len());
        for &p in pressure_pa {
            if !(lo * (1.0 - 1e-12)..=hi * (1.0 + 1e-12)).contains(&p) {
                return Err(self.out_of_range("pressure_pa", p, lo, hi));
            }
            let (k, w) = locate(&s, -p.ln());
            let z = self.altitude_m[k] + w * (self.altitude_m[k + 1] - self.altitude_m[k]);
            at.push((k, w, w, z, p));
        }
        Ok(self.build(&at))
    }

    fn out_of_range(
        &self,
        coordinate: &'static str,
        value: f64,
        min: f64,
        max: f64,
    ) -> AtmosphereError {
        AtmosphereError::OutOfRange {
            profile: self.name.clone(),
            coordinate,
            value,
            min,
            max,
        }
    }

    /// Assemble a profile from (segment, weight for T, weight for mixing ratios, z, p).
    fn build(&self, at: &[(usize, f64, f64, f64, f64)]) -> Profile {
        let lerp = |v: &[f64], k: usize, w: f64| v[k] + w * (v[k + 1] - v[k]);
        Profile {
            name: self.name.clone(),
            altitude_m: at.iter().map(|a| a.3).collect(),
            pressure_pa: at.iter().map(|a| a.4).collect(),
            temperature_k: at
                .iter()
                .map(|&(k, w, _, _, _)| lerp(&self.temperature_k, k, w))
                .collect(),
            gases: self
                .gases
                .iter()
                .map(|g| GasProfile {
                    name: g.name.clone(),
                    vmr: at
                        .iter()
                        .map(|&(k, _, wp, _, _)| {
                            let (a, b) = (g.vmr[k], g.vmr[k + 1]);
                            if a > 0.0 && b > 0.0 {
                                // ln x linear in ln p: a power law in p between levels.
                                (a.ln() + wp * (b.ln() - a.ln())).exp()
                            } else {
                                lerp(&g.vmr, k, wp)
                            }
                        })
                        .collect(),
                })
                .collect(),
        }
    }

    /// Altitudes from the lowest level to the top in steps of `step_m` (the top level is
    /// included even where it is not a multiple of the step): a fine grid for
    /// [`Self::interpolate_to_altitudes`].
    pub fn uniform_altitudes(&self, step_m: f64) -> Result<Vec<f64>, AtmosphereError> {
        if !(step_m.is_finite() && step_m > 0.0) || self.len() < 2 {
            return Err(AtmosphereError::InvalidArgument(format!(
                "altitude step {step_m} m must be positive (profile `{}` with {} levels)",
                self.name,
                self.len()
            )));
        }
        let (lo, hi) = (self.altitude_m[0], self.altitude_m[self.len() - 1]);
        let n = ((hi - lo) / step_m).floor() as usize;
        let mut z: Vec<f64> = (0..=n).map(|i| lo + i as f64 * step_m).collect();
        if hi - z[n] > 1e-6 * step_m {
            z.push(hi);
        } else {
            z[n] = hi;
        }
        Ok(z)
    }
}

fn check_targets(v: &[f64], increasing: bool, name: &str) -> Result<(), AtmosphereError> {
    if v.len() < 2 {
        return Err(AtmosphereError::InvalidArgument(format!(
            "{name}: at least 2 target levels are needed, got {}",
            v.len()
        )));
    }
    let ok = v.iter().all(|x| x.is_finite())
        && v.windows(2)
            .all(|w| if increasing { w[1] > w[0] } else { w[1] < w[0] });
    if !ok {
        return Err(AtmosphereError::InvalidArgument(format!(
            "{name}: targets must be finite and strictly {}",
            if increasing {
                "increasing"
            } else {
                "decreasing"
            }
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atmosphere::StandardAtmosphere;

    #[test]
    fn interpolation_reproduces_levels_and_inverts() {
        let p = StandardAtmosphere::Tropical.profile();
        let same = p.interpolate_to_altitudes(&p.altitude_m).unwrap();
        for k in 0..p.len() {
            assert!((same.pressure_pa[k] / p.pressure_pa[k] - 1.0).abs() < 1e-12);
            assert!((same.temperature_k[k] - p.temperature_k[k]).abs() < 1e-9);
        }
        let fine = p
            .interpolate_to_altitudes(&p.uniform_altitudes(250.0).unwrap())
            .unwrap();
        fine.validate().unwrap();
        let back = fine.interpolate_to_pressures(&p.pressure_pa).unwrap();
        for k in 0..p.len() {
            assert!((back.altitude_m[k] - p.altitude_m[k]).abs() < 1e-6);
            assert!((back.temperature_k[k] - p.temperature_k[k]).abs() < 1e-9);
        }
        // Midway in altitude between two levels, p is the geometric mean.
        let z = 0.5 * (p.altitude_m[3] + p.altitude_m[4]);
        let mid = p.interpolate_to_altitudes(&[p.altitude_m[3], z]).unwrap();
        let gm = (p.pressure_pa[3] * p.pressure_pa[4]).sqrt();
        assert!((mid.pressure_pa[1] / gm - 1.0).abs() < 1e-12);
    }

    #[test]
    fn no_extrapolation() {
        let p = StandardAtmosphere::Tropical.profile();
        let e = p.interpolate_to_altitudes(&[-10.0, 0.0]).unwrap_err();
        assert!(matches!(e, AtmosphereError::OutOfRange { .. }), "{e}");
        assert!(p.interpolate_to_pressures(&[2e5, 1e5]).is_err());
        assert!(p.interpolate_to_altitudes(&[10.0, 5.0]).is_err());
    }

    #[test]
    fn hybrid_shift_moves_surface_keeps_top() {
        assert_eq!(hybrid_shift_pa(101_300.0, 101_300.0, 100_000.0), 100_000.0);
        assert_eq!(hybrid_shift_pa(5_000.0, 101_300.0, 100_000.0), 5_000.0);
        let a = hybrid_shift_pa(50_000.0, 101_300.0, 100_000.0);
        assert!(a < 50_000.0 && a > 49_000.0);
    }
}
