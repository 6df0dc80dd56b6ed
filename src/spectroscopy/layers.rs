//! Curtis-Godson layers and the line of sight.
//!
//! A layer [z_b, z_t] of a [`Profile`] is replaced by one homogeneous path with the column
//! amounts of the real one and absorber-weighted mean pressure and temperature (Curtis 1952,
//! QJRMS 78, 638; Godson 1953, QJRMS 79, 367; as LBLRTM's PAVE/TAVE, weighted by the air
//! column):
//!
//! ```text
//! U_air = ∫ n_air dz,   U_g = ∫ n_g dz,   p̄ = ∫ p n_air dz / U_air,   T̄ = ∫ T n_air dz / U_air
//! ```
//!
//! Between profile levels, ln p and ln n (air and each gas) are linear in altitude and T is
//! linear (a gas with a zero mixing ratio at either level is interpolated linearly in n). The
//! integrals use 8-point Gauss-Legendre quadrature on each piece between levels inside the layer
//! (exact to rounding for these smooth integrands), so layers thinner than the level spacing
//! work. Edges outside the profile are an error.
//!
//! Optical depths are vertical. In plane-parallel geometry the slant optical depth along a line
//! of sight with zenith angle θ is τ_vertical/|cos θ| ([`LineOfSight`]).

use super::SpectroscopyError;
use super::hitran::LineList;
use super::isotopologues::molecule_name;
use super::xsec::GasState;
use crate::atmosphere::Profile;

/// One Curtis-Godson layer.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CgLayer {
    /// Bottom altitude \[m\].
    pub bottom_m: f64,
    /// Top altitude \[m\].
    pub top_m: f64,
    /// Curtis-Godson pressure p̄ \[Pa\].
    pub pressure_pa: f64,
    /// Curtis-Godson temperature T̄ \[K\].
    pub temperature_k: f64,
    /// Vertical air column [molecules/cm²].
    pub air_column_per_cm2: f64,
    /// Names of the gases, as in the profile.
    pub gas_names: Vec<String>,
    /// Vertical column of each gas [molecules/cm²], same order as `gas_names`.
    pub gas_columns_per_cm2: Vec<f64>,
}

impl CgLayer {
    /// The gas state of gas `gas_index` in this layer (self vmr = U_g/U_air).
    pub fn state_for(&self, gas_index: usize) -> GasState {
        let vmr = if self.air_column_per_cm2 > 0.0 {
            (self.gas_columns_per_cm2[gas_index] / self.air_column_per_cm2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        GasState {
            pressure_pa: self.pressure_pa,
            temperature_k: self.temperature_k,
            self_vmr: vmr,
        }
    }
}

/// Gauss-Legendre nodes and weights on [−1, 1], 8 points.
const GL8: [(f64, f64); 8] = [
    (-0.960_289_856_497_536_2, 0.101_228_536_290_376_26),
    (-0.796_666_477_413_626_7, 0.222_381_034_453_374_48),
    (-0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (-0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_48),
    (0.960_289_856_497_536_2, 0.101_228_536_290_376_26),
];

fn check_profile(profile: &Profile) -> Result<(), SpectroscopyError> {
    let n = profile.len();
    let bad = |what: String| {
        Err(SpectroscopyError::Gas(format!(
            "profile `{}`: {what}",
            profile.name
        )))
    };
    if n < 2 {
        return bad("needs at least two levels".into());
    }
    if profile.pressure_pa.len() != n
        || profile.temperature_k.len() != n
        || profile.gases.iter().any(|g| g.vmr.len() != n)
    {
        return bad("per-level vectors differ in length".into());
    }
    if !profile.altitude_m.windows(2).all(|w| w[1] > w[0]) {
        return bad("altitudes must increase strictly".into());
    }
    if profile
        .pressure_pa
        .iter()
        .any(|&p| !(p > 0.0 && p.is_finite()))
        || profile
            .temperature_k
            .iter()
            .any(|&t| !(t > 0.0 && t.is_finite()))
    {
        return bad("pressures and temperatures must be positive".into());
    }
    if profile
        .gases
        .iter()
        .any(|g| g.vmr.iter().any(|&v| !(0.0..=1.0).contains(&v)))
    {
        return bad("mixing ratios must be within [0, 1]".into());
    }
    Ok(())
}

/// State at altitude z inside level interval i: (p, T, n_air, n_gas…).
fn state_at(
    profile: &Profile,
    n_air: &[f64],
    i: usize,
    z: f64,
    gas_out: &mut [f64],
) -> (f64, f64, f64) {
    let (z0, z1) = (profile.altitude_m[i], profile.altitude_m[i + 1]);
    let t = (z - z0) / (z1 - z0);
    let loglin = |a: f64, b: f64| {
        if a > 0.0 && b > 0.0 {
            a * (b / a).powf(t)
        } else {
            a + (b - a) * t
        }
    };
    let p = loglin(profile.pressure_pa[i], profile.pressure_pa[i + 1]);
    let temp =
        profile.temperature_k[i] + (profile.temperature_k[i + 1] - profile.temperature_k[i]) * t;
    let n = loglin(n_air[i], n_air[i + 1]);
    for (g, out) in profile.gases.iter().zip(gas_out.iter_mut()) {
        *out = loglin(g.vmr[i] * n_air[i], g.vmr[i + 1] * n_air[i + 1]);
    }
    (p, temp, n)
}

/// Curtis-Godson layers between consecutive `edges_m` (strictly increasing, inside the
/// profile), module docs.
pub fn curtis_godson_layers(
    profile: &Profile,
    edges_m: &[f64],
) -> Result<Vec<CgLayer>, SpectroscopyError> {
    check_profile(profile)?;
    check_edges(profile, edges_m)?;
    let n_air = profile.air_number_density_per_m3();
    let ng = profile.gases.len();
    let mut gas_n = vec![0.0; ng];
    let z = &profile.altitude_m;
    let mut layers = Vec::with_capacity(edges_m.len() - 1);
    for e in edges_m.windows(2) {
        let (zb, zt) = (e[0], e[1]);
        let (mut u_air, mut u_p, mut u_t) = (0.0, 0.0, 0.0);
        let mut u_gas = vec![0.0; ng];
        // Pieces between profile levels.
        let first = z
            .partition_point(|&zi| zi <= zb)
            .saturating_sub(1)
            .min(z.len() - 2);
        let mut i = first;
        let mut a = zb;
        while a < zt {
            // i ≤ len − 2 here, and zt ≤ the top level (check_edges).
            let b = z[i + 1].min(zt);
            let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
            for (x, wq) in GL8 {
                let zz = mid + half * x;
                let (p, t, n) = state_at(profile, &n_air, i, zz, &mut gas_n);
                let wn = wq * half * n;
                u_air += wn;
                u_p += wn * p;
                u_t += wn * t;
                for (u, g) in u_gas.iter_mut().zip(&gas_n) {
                    *u += wq * half * g;
                }
            }
            a = b;
            i += 1;
            if i > z.len() - 2 {
                break;
            }
        }
        // per m² → per cm²
        layers.push(CgLayer {
            bottom_m: zb,
            top_m: zt,
            pressure_pa: u_p / u_air,
            temperature_k: u_t / u_air,
            air_column_per_cm2: u_air * 1e-4,
            gas_names: profile.gases.iter().map(|g| g.name.clone()).collect(),
            gas_columns_per_cm2: u_gas.iter().map(|u| u * 1e-4).collect(),
        });
    }
    Ok(layers)
}

fn check_edges(profile: &Profile, edges_m: &[f64]) -> Result<(), SpectroscopyError> {
    if edges_m.len() < 2 {
        return Err(SpectroscopyError::InvalidArgument {
            name: "edges_m (count)",
            value: edges_m.len() as f64,
            reason: "at least two layer edges are needed".into(),
        });
    }
    let (bottom, top) = (profile.altitude_m[0], profile.altitude_m[profile.len() - 1]);
    for (i, &e) in edges_m.iter().enumerate() {
        if !e.is_finite() || e < bottom || e > top {
            return Err(SpectroscopyError::OutsideProfile {
                altitude_m: e,
                profile: profile.name.clone(),
                bottom_m: bottom,
                top_m: top,
            });
        }
        if i > 0 && e <= edges_m[i - 1] {
            return Err(SpectroscopyError::InvalidArgument {
                name: "edges_m",
                value: e,
                reason: format!(
                    "layer edges must increase strictly (edge {i} ≤ edge {})",
                    i - 1
                ),
            });
        }
    }
    Ok(())
}

/// For each molecule of the line list, its HITRAN number and its index in the profile's gases.
/// A molecule the profile does not carry is an error.
pub fn line_gases(
    profile: &Profile,
    lines: &LineList,
) -> Result<Vec<(u8, usize)>, SpectroscopyError> {
    lines
        .molecules()
        .into_iter()
        .map(|m| {
            let name = molecule_name(m).unwrap_or("?");
            profile
                .gases
                .iter()
                .position(|g| g.name == name)
                .map(|gi| (m, gi))
                .ok_or_else(|| {
                    SpectroscopyError::Gas(format!(
                        "{name} has lines in `{}` but the profile `{}` has no {name} mixing ratio",
                        lines.source, profile.name
                    ))
                })
        })
        .collect()
}

/// A lidar's line of sight in plane-parallel geometry.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LineOfSight {
    /// Sensor altitude \[m\].
    pub sensor_altitude_m: f64,
    /// Zenith angle of the pointing \[deg\]: 0 looks straight up, 180 straight down (nadir);
    /// 90 (horizontal) is not plane-parallel and is rejected.
    pub zenith_angle_deg: f64,
    /// Surface altitude \[m\] (where a downward path ends).
    pub surface_altitude_m: f64,
}

impl LineOfSight {
    /// |cos θ|, the factor that turns a vertical optical depth into a slant one (τ/|cos θ|).
    pub fn mu(&self) -> Result<f64, SpectroscopyError> {
        let mu = self.zenith_angle_deg.to_radians().cos().abs();
        if !(self.zenith_angle_deg.is_finite() && (0.0..=180.0).contains(&self.zenith_angle_deg))
            || mu < 1e-3
        {
            return Err(SpectroscopyError::InvalidArgument {
                name: "zenith_angle_deg",
                value: self.zenith_angle_deg,
                reason: "must be within [0, 180] and at least 0.06° away from horizontal".into(),
            });
        }
        Ok(mu)
    }

    /// Bottom and top altitude of the path through `profile` \[m\]: sensor to profile top when
    /// looking up, surface to sensor when looking down.
    pub fn vertical_extent(&self, profile: &Profile) -> Result<(f64, f64), SpectroscopyError> {
        self.mu()?;
        let top = *profile.altitude_m.last().unwrap_or(&0.0);
        let up = self.zenith_angle_deg < 90.0;
        let (lo, hi) = if up {
            (self.sensor_altitude_m, top)
        } else {
            (self.surface_altitude_m, self.sensor_altitude_m)
        };
        for z in [lo, hi] {
            if !(z >= profile.altitude_m[0] && z <= top) {
                return Err(SpectroscopyError::OutsideProfile {
                    altitude_m: z,
                    profile: profile.name.clone(),
                    bottom_m: profile.altitude_m[0],
                    top_m: top,
                });
            }
        }
        if hi <= lo {
            return Err(SpectroscopyError::InvalidArgument {
                name: "sensor_altitude_m",
                value: self.sensor_altitude_m,
                reason:
                    "the path is empty (a downward-looking sensor must be above the surface; an \
                         upward-looking one below the top of the profile)"
                        .into(),
            });
        }
        Ok((lo, hi))
    }

    /// Layer edges along the path, about `thickness_m` thick (the last one thinner).
    pub fn layer_edges(
        &self,
        profile: &Profile,
        thickness_m: f64,
    ) -> Result<Vec<f64>, SpectroscopyError> {
        if !(thickness_m.is_finite() && thickness_m > 0.0) {
            return Err(SpectroscopyError::InvalidArgument {
                name: "thickness_m",
                value: thickness_m,
                reason: "must be positive".into(),
            });
        }
        let (lo, hi) = self.vertical_extent(profile)?;
        let n = ((hi - lo) / thickness_m - 1e-9).ceil().max(1.0);
        if n > crate::limits::MAX_PATH_LAYERS as f64 {
            return Err(SpectroscopyError::InvalidArgument {
                name: "thickness_m",
                value: thickness_m,
                reason: format!(
                    "makes {n:.0} layers along the path, more than the limit of {}",
                    crate::limits::MAX_PATH_LAYERS
                ),
            });
        }
        let n = n as usize;
        let mut e: Vec<f64> = (0..n).map(|i| lo + i as f64 * thickness_m).collect();
        e.push(hi);
        Ok(e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atmosphere::{GasProfile, StandardAtmosphere};

    /// An isothermal exponential atmosphere: p = p0 e^{−z/H}, constant T and vmr.
    fn isothermal() -> Profile {
        let h = 8000.0;
        let z: Vec<f64> = (0..=10).map(|i| i as f64 * 2000.0).collect();
        Profile {
            name: "isothermal".into(),
            pressure_pa: z.iter().map(|z| 1e5 * (-z / h).exp()).collect(),
            temperature_k: vec![250.0; z.len()],
            gases: vec![GasProfile {
                name: "CO2".into(),
                vmr: vec![4e-4; z.len()],
            }],
            altitude_m: z,
        }
    }

    #[test]
    fn columns_and_cg_pressure_match_the_analytic_exponential_atmosphere() {
        let prof = isothermal();
        let (h, n0) = (8000.0, 1e5 / (crate::constants::BOLTZMANN_J_PER_K * 250.0));
        // A layer thinner than the level spacing, straddling a level.
        let (zb, zt) = (1500.0, 2700.0);
        let l = &curtis_godson_layers(&prof, &[zb, zt]).unwrap()[0];
        let u = n0 * h * ((-zb / h).exp() - (-zt / h).exp()) * 1e-4;
        assert!((l.air_column_per_cm2 / u - 1.0).abs() < 1e-12);
        assert!((l.gas_columns_per_cm2[0] / (4e-4 * u) - 1.0).abs() < 1e-12);
        // p̄ = ∫p n dz/∫n dz = p0 (e^{−2zb/H} − e^{−2zt/H}) / (2 (e^{−zb/H} − e^{−zt/H}))
        let pbar = 1e5 * ((-2.0 * zb / h).exp() - (-2.0 * zt / h).exp())
            / (2.0 * ((-zb / h).exp() - (-zt / h).exp()));
        assert!((l.pressure_pa / pbar - 1.0).abs() < 1e-12);
        assert!((l.temperature_k - 250.0).abs() < 1e-9);
    }

    #[test]
    fn cg_temperature_matches_the_closed_form_under_a_constant_lapse_rate() {
        // T = T0 − Γz and n = n0 e^{−z/H} at the levels (p = n k T there), so between levels T is
        // exactly linear and n exactly log-linear: T̄ = T0 − Γ z̄ with the column-weighted mean
        // height z̄ = [(a + H)e^{−a/H} − (b + H)e^{−b/H}] / (e^{−a/H} − e^{−b/H}).
        let (h, n0, t0, lapse) = (8000.0_f64, 2.5e25, 288.15, 6.5e-3);
        let mut prof = isothermal();
        prof.temperature_k = prof.altitude_m.iter().map(|z| t0 - lapse * z).collect();
        prof.pressure_pa = prof
            .altitude_m
            .iter()
            .zip(&prof.temperature_k)
            .map(|(z, t)| n0 * (-z / h).exp() * crate::constants::BOLTZMANN_J_PER_K * t)
            .collect();
        for (a, b) in [(1500.0, 2700.0), (0.0, 20_000.0), (9100.0, 9900.0)] {
            let l = &curtis_godson_layers(&prof, &[a, b]).unwrap()[0];
            let (ea, eb) = ((-a / h).exp(), (-b / h).exp());
            let zbar = ((a + h) * ea - (b + h) * eb) / (ea - eb);
            assert!(
                (l.temperature_k - (t0 - lapse * zbar)).abs() < 1e-9,
                "[{a}, {b}]: {} vs {}",
                l.temperature_k,
                t0 - lapse * zbar
            );
            assert!((l.air_column_per_cm2 / (n0 * h * (ea - eb) * 1e-4) - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn a_gas_absent_at_one_level_is_linear_in_number_density_there() {
        // vmr 0 at 2 km and 4e-4 at 4 km (and the reverse): ln n_g is undefined at the empty
        // level, so n_g is linear between the two and its column over [2 km, 3 km] is the
        // trapezoid ∫ n₄ (z − 2 km)/(2 km) dz = n₄ · 250 m (n₄ · 750 m when the empty level is
        // at 4 km).
        let mut prof = isothermal();
        let n_air = prof.air_number_density_per_m3();
        for (empty, full, share_m) in [(1, 2, 250.0), (2, 1, 750.0)] {
            prof.gases[0].vmr = vec![4e-4; prof.len()];
            prof.gases[0].vmr[empty] = 0.0;
            let l = &curtis_godson_layers(&prof, &[2000.0, 3000.0]).unwrap()[0];
            let want = 4e-4 * n_air[full] * share_m * 1e-4;
            assert!(
                (l.gas_columns_per_cm2[0] / want - 1.0).abs() < 1e-12,
                "empty level {empty}: {} vs {want}",
                l.gas_columns_per_cm2[0]
            );
        }
    }

    #[test]
    fn a_level_without_pressure_is_refused() {
        let mut prof = isothermal();
        *prof.pressure_pa.last_mut().unwrap() = 0.0;
        let e = curtis_godson_layers(&prof, &[0.0, 1000.0]).unwrap_err();
        assert!(e.to_string().contains("must be positive"), "{e}");
    }

    #[test]
    fn layers_add_up_and_edges_outside_are_errors() {
        let prof = StandardAtmosphere::UsStandard.profile();
        let whole = curtis_godson_layers(&prof, &[0.0, 10_000.0]).unwrap();
        let split = curtis_godson_layers(&prof, &[0.0, 333.0, 5000.0, 10_000.0]).unwrap();
        let s: f64 = split.iter().map(|l| l.gas_columns_per_cm2[1]).sum();
        assert!((s / whole[0].gas_columns_per_cm2[1] - 1.0).abs() < 1e-12);
        assert!(matches!(
            curtis_godson_layers(&prof, &[-10.0, 100.0]),
            Err(SpectroscopyError::OutsideProfile { .. })
        ));
        assert!(curtis_godson_layers(&prof, &[100.0, 100.0]).is_err());
    }

    #[test]
    fn line_of_sight_extent_and_mu() {
        let prof = StandardAtmosphere::UsStandard.profile();
        let down = LineOfSight {
            sensor_altitude_m: 10_000.0,
            zenith_angle_deg: 180.0,
            surface_altitude_m: 200.0,
        };
        assert_eq!(down.vertical_extent(&prof).unwrap(), (200.0, 10_000.0));
        assert!((down.mu().unwrap() - 1.0).abs() < 1e-15);
        let e = down.layer_edges(&prof, 1000.0).unwrap();
        assert_eq!(e.len(), 11);
        assert_eq!(*e.last().unwrap(), 10_000.0);
        let flat = LineOfSight {
            zenith_angle_deg: 90.0,
            ..down
        };
        assert!(flat.mu().is_err());
        // Beyond [0°, 180°] is refused even where |cos θ| is fine.
        for zenith_angle_deg in [-10.0, 190.0, f64::NAN] {
            let los = LineOfSight {
                zenith_angle_deg,
                ..down
            };
            assert!(los.mu().is_err(), "{zenith_angle_deg}");
        }
        // 9 800 m in 0.05 m layers is 196 000 layers, beyond the limit of 100 000; 0.1 m is
        // 98 000, within it.
        assert!(down.layer_edges(&prof, 0.05).is_err());
        assert_eq!(down.layer_edges(&prof, 0.1).unwrap().len(), 98_001);
    }
}
