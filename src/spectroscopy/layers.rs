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
//! Between profile levels the state is the one hydrostatic integration of
//! [`crate::atmosphere::hydrostatic::HydrostaticProfile`]: T linear in altitude, the pressure
//! from the hydrostatic equation with the virtual temperature (so that the air column between
//! two altitudes is their pressure difference over m g, the weighting function's Δp being that
//! same difference), n = p/(kT), each gas's mixing ratio log-linear (linear where a level has
//! none). The integrals use 8-point Gauss-Legendre quadrature on each piece between levels inside
//! the layer (exact to rounding for these smooth integrands), so layers thinner than the level
//! spacing work. Edges outside the profile are an error.
//!
//! Optical depths are vertical. In plane-parallel geometry the slant optical depth along a line
//! of sight with zenith angle θ is τ_vertical/|cos θ| ([`LineOfSight`]).

use super::SpectroscopyError;
use super::isotopologues::molecule_name;
use super::lines::LineList;
use super::xsec::GasState;
use crate::atmosphere::Profile;
use crate::atmosphere::hydrostatic::HydrostaticProfile;

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

pub(crate) fn check_profile(profile: &Profile) -> Result<(), SpectroscopyError> {
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

/// Curtis-Godson layers between consecutive `edges_m` (strictly increasing, inside the
/// profile), module docs.
pub fn curtis_godson_layers(
    profile: &Profile,
    edges_m: &[f64],
) -> Result<Vec<CgLayer>, SpectroscopyError> {
    check_profile(profile)?;
    check_edges(profile, edges_m)?;
    let hydro = HydrostaticProfile::new(profile);
    let mut layers = Vec::with_capacity(edges_m.len() - 1);
    for e in edges_m.windows(2) {
        let (zb, zt) = (e[0], e[1]);
        let c = hydro.integrate(zb, zt);
        let (u_air, u_p, u_t, u_gas) = (
            c.air_per_m2,
            c.pressure_weighted,
            c.temperature_weighted,
            c.gas_per_m2,
        );
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

    /// ∫_0^z γ dz' for normal gravity's height factor γ = g(z)/g(0) (at 45°, as the
    /// hydrostatic integration takes it): the geopotential over surface gravity, in closed form.
    fn gamma_integral(z: f64) -> f64 {
        use crate::atmosphere::hydrostatic::{
            geopotential_m2_per_s2, normal_gravity_surface_m_per_s2,
        };
        geopotential_m2_per_s2(45.0, z) / normal_gravity_surface_m_per_s2(45.0)
    }

    /// Composite Simpson's rule with `n` (even) intervals.
    fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
        let h = (b - a) / n as f64;
        let inner: f64 = (1..n)
            .map(|k| f(a + k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 })
            .sum();
        (f(a) + inner + f(b)) * h / 3.0
    }

    /// An isothermal atmosphere in hydrostatic balance with normal gravity:
    /// p = p0 e^{−Γ(z)/H}, Γ = ∫γ dz, constant T and vmr.
    fn isothermal() -> Profile {
        let h = 8000.0;
        let z: Vec<f64> = (0..=10).map(|i| i as f64 * 2000.0).collect();
        Profile {
            name: "isothermal".into(),
            pressure_pa: z
                .iter()
                .map(|z| 1e5 * (-gamma_integral(*z) / h).exp())
                .collect(),
            temperature_k: vec![250.0; z.len()],
            gases: vec![GasProfile {
                name: "CO2".into(),
                vmr: vec![4e-4; z.len()],
            }],
            altitude_m: z,
        }
    }

    /// The isothermal atmosphere's layer against its closed-form state, p(z) = p0 e^{−Γ(z)/H},
    /// integrated by Simpson's rule (20 000 intervals): columns and p̄ to 1e-12.
    #[test]
    fn columns_and_cg_pressure_match_the_isothermal_hydrostatic_atmosphere() {
        let prof = isothermal();
        let (h, n0) = (8000.0, 1e5 / (crate::constants::BOLTZMANN_J_PER_K * 250.0));
        let n = |z: f64| n0 * (-gamma_integral(z) / h).exp();
        // A layer thinner than the level spacing, straddling a level.
        let (zb, zt) = (1500.0, 2700.0);
        let l = &curtis_godson_layers(&prof, &[zb, zt]).unwrap()[0];
        let u = simpson(n, zb, zt, 20_000) * 1e-4;
        assert!((l.air_column_per_cm2 / u - 1.0).abs() < 1e-12);
        assert!((l.gas_columns_per_cm2[0] / (4e-4 * u) - 1.0).abs() < 1e-12);
        let p_n = simpson(
            |z| n(z) * 1e5 * (-gamma_integral(z) / h).exp(),
            zb,
            zt,
            20_000,
        );
        assert!((l.pressure_pa / (p_n * 1e-4 / u) - 1.0).abs() < 1e-12);
        assert!((l.temperature_k - 250.0).abs() < 1e-9);
    }

    /// A dry atmosphere with a constant lapse rate Γ_T in hydrostatic balance with normal
    /// gravity: T = T0 − Γ_T z and ln p = ln p0 − (g0 M_d/R) ∫ γ/T dz, with levels on it. The
    /// Curtis-Godson layer against that state integrated by Simpson's rule (the inner integral
    /// by 2000 intervals, the outer by 4000): columns, p̄ and T̄ to 1e-10.
    #[test]
    fn cg_layers_match_the_hydrostatic_state_under_a_constant_lapse_rate() {
        use crate::atmosphere::hydrostatic::{
            dry_air_gas_constant_j_per_kg_k, normal_gravity_surface_m_per_s2,
        };
        let (p0, t0, lapse) = (101_325.0_f64, 288.15, 6.5e-3);
        let k = crate::constants::BOLTZMANN_J_PER_K;
        let c = normal_gravity_surface_m_per_s2(45.0) / dry_air_gas_constant_j_per_kg_k();
        let temperature = |z: f64| t0 - lapse * z;
        let gamma = |z: f64| {
            use crate::atmosphere::hydrostatic::normal_gravity_m_per_s2;
            normal_gravity_m_per_s2(45.0, z) / normal_gravity_surface_m_per_s2(45.0)
        };
        let pressure =
            |z: f64| p0 * (-c * simpson(|y| gamma(y) / temperature(y), 0.0, z, 2000)).exp();
        let mut prof = isothermal();
        prof.temperature_k = prof.altitude_m.iter().map(|z| temperature(*z)).collect();
        prof.pressure_pa = prof.altitude_m.iter().map(|z| pressure(*z)).collect();
        for (a, b) in [(1500.0, 2700.0), (0.0, 20_000.0), (9100.0, 9900.0)] {
            let l = &curtis_godson_layers(&prof, &[a, b]).unwrap()[0];
            let n = |z: f64| pressure(z) / (k * temperature(z));
            let col = simpson(n, a, b, 4000);
            let t_n = simpson(|z| n(z) * temperature(z), a, b, 4000);
            let p_n = simpson(|z| n(z) * pressure(z), a, b, 4000);
            assert!(
                (l.air_column_per_cm2 / (col * 1e-4) - 1.0).abs() < 1e-10,
                "[{a}, {b}]: column {} vs {}",
                l.air_column_per_cm2,
                col * 1e-4
            );
            assert!(
                (l.temperature_k / (t_n / col) - 1.0).abs() < 1e-10,
                "[{a}, {b}]"
            );
            assert!(
                (l.pressure_pa / (p_n / col) - 1.0).abs() < 1e-10,
                "[{a}, {b}]"
            );
        }
    }

    /// vmr 0 at 2 km and 4e-4 at 4 km (and the reverse): ln x is undefined at the empty level,
    /// so x is linear between the two; the column over [2 km, 3 km] is ∫ x(z) n(z) dz with the
    /// isothermal atmosphere's n, by Simpson's rule, to 1e-12.
    #[test]
    fn a_gas_absent_at_one_level_is_linear_in_mixing_ratio_there() {
        let mut prof = isothermal();
        let (h, n0) = (
            8000.0_f64,
            1e5 / (crate::constants::BOLTZMANN_J_PER_K * 250.0),
        );
        let n = |z: f64| n0 * (-gamma_integral(z) / h).exp();
        let (a, b, c) = (2000.0_f64, 3000.0_f64, 4000.0_f64);
        for (empty, x) in [
            (
                1,
                Box::new(|z: f64| 4e-4 * (z - a) / (c - a)) as Box<dyn Fn(f64) -> f64>,
            ),
            (2, Box::new(|z: f64| 4e-4 * (c - z) / (c - a))),
        ] {
            prof.gases[0].vmr = vec![4e-4; prof.len()];
            prof.gases[0].vmr[empty] = 0.0;
            let l = &curtis_godson_layers(&prof, &[a, b]).unwrap()[0];
            let want = simpson(|z| x(z) * n(z), a, b, 20_000) * 1e-4;
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
