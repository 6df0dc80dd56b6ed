//! Perturbed ensembles: `x = x̄ + L z`, `S = L Lᵀ`, `z ~ N(0, I)`.
//!
//! The state is (T, ln H2O, CO2 ppmv, p_s hPa) on the mean profile's levels (see
//! [`super::covariance`]). Each member:
//! 1. draws z (Xoshiro256++ seeded from the user's seed, standard normals from
//!    `rand_distr::StandardNormal`, element by element, member after member: the same seed gives
//!    the same members, and the first k members do not depend on how many are drawn);
//! 2. moves the levels to the new surface pressure p_s' = p̄_s + δp_s with
//!    [`super::interp::hybrid_shift_pa`] (sigma-like near the surface, fixed
//!    pressure above 100 hPa), so perturbations are level-following;
//! 3. sets T' = T̄ + δT, x_H2O' = exp(ln x̄_H2O + δ) (always positive), CO2' = CO2̄ + δ; other
//!    gases keep their mixing ratios;
//! 4. caps water vapour at a relative humidity limit (default 100 % over liquid water, Murphy and
//!    Koop 2005), counting the capped values;
//! 5. recomputes altitudes hydrostatically from the mean's surface altitude.
//!
//! Perturbations are unbiased in ln H2O, so the ensemble's arithmetic-mean H2O exceeds the mean
//! profile's by exp(σ²/2) before capping (4 % for σ = 0.28).

use nalgebra::DVector;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use super::covariance::{Covariance, Factor, RepairReport};
use super::humidity::{SaturationOver, saturation_vapour_pressure_pa};
use super::hydrostatic::hydrostatic_altitudes_m;
use super::interp::{HYBRID_TOP_PA, hybrid_shift_pa};
use super::set::{ProfileMeta, ProfileSet, SetMember};
use super::{AtmosphereError, Profile};

/// Settings of [`generate_ensemble`].
#[derive(Debug, Clone, PartialEq)]
pub struct EnsembleConfig {
    /// Number of members.
    pub n: usize,
    /// Seed of the Xoshiro256++ generator.
    pub seed: u64,
    /// Largest relative humidity allowed (fraction: 1.0 = 100 %).
    pub max_relative_humidity: f64,
    /// Phase the relative humidity refers to.
    pub saturation: SaturationOver,
    /// Member ids are `{id_prefix}{i:04}`, i from 1.
    pub id_prefix: String,
    /// Repair a covariance that is not positive semi-definite beyond rounding (else an error).
    pub allow_repair: bool,
}

impl EnsembleConfig {
    /// `n` members from `seed`, RH ≤ 100 % over water, ids `m0001...`, no repair beyond rounding.
    pub fn new(n: usize, seed: u64) -> EnsembleConfig {
        EnsembleConfig {
            n,
            seed,
            max_relative_humidity: 1.0,
            saturation: SaturationOver::Water,
            id_prefix: "m".into(),
            allow_repair: false,
        }
    }
}

/// What happened while generating an ensemble.
#[derive(Debug, Clone, PartialEq)]
pub struct EnsembleReport {
    /// Water vapour values capped at the relative-humidity limit.
    pub capped_values: usize,
    /// Members with at least one capped value.
    pub capped_members: usize,
    /// Water vapour values in all members.
    pub total_values: usize,
    /// Set when the covariance had to be repaired.
    pub repair: Option<RepairReport>,
    /// Levels at which the mean profile itself exceeds the relative-humidity limit (a mean of
    /// profiles from different climates can: mean q with a colder mean T). Every member is
    /// capped there.
    pub mean_levels_above_limit: usize,
}

/// Draw `n` perturbation vectors δ = L z (columns of the result), as [`generate_ensemble`]
/// draws them for the same seed.
pub fn draw_perturbations(factor: &Factor, n: usize, seed: u64) -> nalgebra::DMatrix<f64> {
    let dim = factor.l.nrows();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut out = nalgebra::DMatrix::<f64>::zeros(dim, n);
    for j in 0..n {
        let z = DVector::<f64>::from_fn(dim, |_, _| StandardNormal.sample(&mut rng));
        out.set_column(j, &(&factor.l * z));
    }
    out
}

/// Generate `cfg.n` perturbed profiles around `mean` with covariance `cov` (which must be on the
/// mean profile's state elements: [`Covariance::fits`]). See the module documentation.
///
/// Errors: a covariance that does not fit or is not positive semi-definite (unless
/// `cfg.allow_repair`), a mean profile without H2O or CO2 where these are perturbed, a
/// perturbation that makes a temperature, a CO2 mixing ratio or the surface pressure
/// unphysical.
pub fn generate_ensemble(
    mean: &SetMember,
    cov: &Covariance,
    cfg: &EnsembleConfig,
) -> Result<(ProfileSet, EnsembleReport), AtmosphereError> {
    let prof = &mean.profile;
    prof.validate()?;
    crate::limits::check_product(
        "the ensemble",
        &[("profiles", cfg.n as u64), ("levels", prof.len() as u64)],
        crate::limits::MAX_ENSEMBLE_LEVELS,
    )
    .map_err(AtmosphereError::InvalidArgument)?;
    if !cov.fits(prof) {
        return Err(AtmosphereError::Covariance(format!(
            "its {} elements are not those of profile `{}` ({} levels): project it with on_profile",
            cov.dimension(),
            prof.name,
            prof.len()
        )));
    }
    if !(cfg.max_relative_humidity.is_finite() && cfg.max_relative_humidity > 0.0) {
        return Err(AtmosphereError::InvalidArgument(format!(
            "relative humidity limit {} must be positive",
            cfg.max_relative_humidity
        )));
    }
    let factor = cov.factor(cfg.allow_repair)?;
    let deltas = draw_perturbations(&factor, cfg.n, cfg.seed);
    let mut set = ProfileSet {
        name: format!("ensemble around {}", prof.name),
        members: Vec::with_capacity(cfg.n),
        notes: Vec::new(),
    };
    let mean_levels_above_limit = match prof.gas("H2O") {
        Some(x) => (0..prof.len())
            .filter(|&k| {
                x[k] * prof.pressure_pa[k]
                    > cfg.max_relative_humidity
                        * saturation_vapour_pressure_pa(prof.temperature_k[k], cfg.saturation)
            })
            .count(),
        None => 0,
    };
    let mut report = EnsembleReport {
        capped_values: 0,
        capped_members: 0,
        total_values: 0,
        repair: factor.repair,
        mean_levels_above_limit,
    };
    for j in 0..cfg.n {
        let delta: Vec<f64> = deltas.column(j).iter().copied().collect();
        let id = format!("{}{:04}", cfg.id_prefix, j + 1);
        let (member, capped) = perturb_member(mean, &delta, &id, cfg)?;
        report.capped_values += capped;
        report.capped_members += usize::from(capped > 0);
        report.total_values += member.profile.len();
        set.members.push(member);
    }
    Ok((set, report))
}

/// One member: the mean perturbed by the state vector `delta` (T K, ln H2O, CO2 ppmv per level,
/// then p_s hPa), with the relative-humidity cap of `cfg`. Returns the member and the number of
/// capped water vapour values.
pub fn perturb_member(
    mean: &SetMember,
    delta: &[f64],
    id: &str,
    cfg: &EnsembleConfig,
) -> Result<(SetMember, usize), AtmosphereError> {
    let prof = &mean.profile;
    let n = prof.len();
    if delta.len() != 3 * n + 1 {
        return Err(AtmosphereError::Covariance(format!(
            "perturbation has {} elements, profile `{}` needs {}",
            delta.len(),
            prof.name,
            3 * n + 1
        )));
    }
    let bad = |message: String| AtmosphereError::InvalidProfile {
        profile: format!("{} member {id}", prof.name),
        message,
    };
    let (dt, dq, dc, dps) = (
        &delta[..n],
        &delta[n..2 * n],
        &delta[2 * n..3 * n],
        delta[3 * n],
    );
    let ps = prof.surface_pressure_pa();
    let ps_new = ps + dps * 100.0;
    if !(ps_new > HYBRID_TOP_PA) {
        return Err(bad(format!(
            "perturbed surface pressure {ps_new} Pa is not above {HYBRID_TOP_PA} Pa"
        )));
    }
    let pressure_pa: Vec<f64> = prof
        .pressure_pa
        .iter()
        .map(|&p| hybrid_shift_pa(p, ps, ps_new))
        .collect();
    let temperature_k: Vec<f64> = prof
        .temperature_k
        .iter()
        .zip(dt)
        .map(|(t, d)| t + d)
        .collect();
    if let Some((k, t)) = temperature_k.iter().enumerate().find(|(_, t)| !(**t > 0.0)) {
        return Err(bad(format!(
            "perturbed temperature {t} K at level {k}: the covariance is too large for this profile"
        )));
    }
    let mut out = Profile {
        name: format!("{} {id}", prof.name),
        altitude_m: Vec::new(),
        pressure_pa,
        temperature_k,
        gases: prof.gases.clone(),
    };
    let mut capped = 0;
    let perturbs_h2o = dq.iter().any(|d| *d != 0.0);
    let perturbs_co2 = dc.iter().any(|d| *d != 0.0);
    if perturbs_h2o && prof.gas("H2O").is_none() {
        prof.require_gas("H2O")?;
    }
    if perturbs_co2 && prof.gas("CO2").is_none() {
        prof.require_gas("CO2")?;
    }
    for g in &mut out.gases {
        match g.name.as_str() {
            "H2O" => {
                for k in 0..n {
                    let x = if g.vmr[k] > 0.0 {
                        (g.vmr[k].ln() + dq[k]).exp()
                    } else {
                        0.0
                    };
                    let e_s = saturation_vapour_pressure_pa(out.temperature_k[k], cfg.saturation);
                    let x_max = (cfg.max_relative_humidity * e_s / out.pressure_pa[k]).min(1.0);
                    g.vmr[k] = if x > x_max {
                        capped += 1;
                        x_max
                    } else {
                        x
                    };
                }
            }
            "CO2" => {
                for k in 0..n {
                    let x = g.vmr[k] + dc[k] * 1e-6;
                    if !(0.0..=1.0).contains(&x) {
                        return Err(bad(format!(
                            "perturbed CO2 {} ppmv at level {k} is not physical",
                            x * 1e6
                        )));
                    }
                    g.vmr[k] = x;
                }
            }
            _ => {}
        }
    }
    let h2o = out.gas("H2O").map(|v| v.to_vec());
    out.altitude_m = hydrostatic_altitudes_m(
        &out.pressure_pa,
        &out.temperature_k,
        h2o.as_deref(),
        prof.altitude_m[0],
        mean.meta.latitude_deg,
    )?;
    out.validate()?;
    Ok((
        SetMember {
            meta: ProfileMeta {
                id: id.to_string(),
                ..mean.meta.clone()
            },
            profile: out,
        },
        capped,
    ))
}

/// A uniform change of the atmospheric state, for sensitivities and knowledge errors: every
/// level's temperature shifted, water vapour scaled, the surface pressure moved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateShift {
    /// Added to the temperature of every level \[K\].
    pub temperature_k: f64,
    /// Factor on the water vapour mixing ratio of every level (1.1: 10 % more).
    pub h2o_factor: f64,
    /// Added to the surface pressure \[hPa\] (levels follow by [`hybrid_shift_pa`]).
    pub surface_pressure_hpa: f64,
}

impl StateShift {
    /// No change.
    pub const NONE: StateShift = StateShift {
        temperature_k: 0.0,
        h2o_factor: 1.0,
        surface_pressure_hpa: 0.0,
    };
}

/// `member` changed by `shift`, as an ensemble member is perturbed ([`perturb_member`]: levels
/// moved to the new surface pressure, altitudes recomputed hydrostatically from the same surface
/// altitude), without the relative-humidity cap: a sensitivity to 10 % more water vapour must
/// not be clipped where the profile is near saturation.
///
/// The altitudes are hydrostatic even for [`StateShift::NONE`], so a finite difference compares
/// two shifted profiles (a shift against `NONE`), never a shifted one against the original,
/// whose altitudes may come from another integration (AFGL tables).
pub fn shift_member(member: &SetMember, shift: &StateShift) -> Result<SetMember, AtmosphereError> {
    if !(shift.temperature_k.is_finite()
        && shift.h2o_factor.is_finite()
        && shift.h2o_factor > 0.0
        && shift.surface_pressure_hpa.is_finite())
    {
        return Err(AtmosphereError::InvalidArgument(format!(
            "state shift {shift:?}: temperature and surface pressure must be finite, the water vapour factor positive"
        )));
    }
    let n = member.profile.len();
    let mut delta = vec![shift.temperature_k; n];
    delta.extend(std::iter::repeat_n(shift.h2o_factor.ln(), n));
    delta.extend(std::iter::repeat_n(0.0, n));
    delta.push(shift.surface_pressure_hpa);
    let cfg = EnsembleConfig {
        max_relative_humidity: f64::INFINITY,
        ..EnsembleConfig::new(1, 0)
    };
    let (mut out, _) = perturb_member(member, &delta, &member.meta.id, &cfg)?;
    out.profile.name = member.profile.name.clone();
    Ok(out)
}

/// An ensemble of `n` members around the mean of a latitude class's AFGL atmospheres with the
/// representative NWP forecast-error covariance scaled for the class
/// ([`super::ErrorModel::representative`], [`super::ErrorModel::scaled_for_class`]): what
/// `lidarsim profiles generate --class C --n N --seed S` writes. Member ids are `{class}-0001`….
pub fn class_ensemble(
    class: super::LatitudeClass,
    n: usize,
    seed: u64,
) -> Result<(ProfileSet, EnsembleReport), AtmosphereError> {
    let afgl = ProfileSet {
        name: format!("AFGL {class}"),
        members: class
            .afgl_atmospheres()
            .iter()
            .map(|s| s.member())
            .collect(),
        notes: Vec::new(),
    };
    let mean = afgl.mean_member()?;
    let cov = super::ErrorModel::representative()
        .scaled_for_class(class)
        .covariance(&mean.profile)?;
    let cfg = EnsembleConfig {
        id_prefix: format!("{}-", class.name()),
        ..EnsembleConfig::new(n, seed)
    };
    let (mut set, report) = generate_ensemble(&mean, &cov, &cfg)?;
    set.name = format!("{n} members around the AFGL {class} mean, seed {seed}");
    Ok((set, report))
}
