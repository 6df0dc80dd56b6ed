//! `lidarsim profiles`: the ensemble `generate` draws from its request, and the table `info`
//! prints of a profile set's members.

use std::fmt::Write as _;
use std::path::PathBuf;

use super::ProductError;
use crate::atmosphere::covariance::{Covariance, ErrorModel};
use crate::atmosphere::{
    Co2Scaling, EnsembleConfig, LatitudeClass, ProfileSet, SaturationOver, SetMember,
    StandardAtmosphere, generate_ensemble, read_profile_set,
};
use crate::output::csv_field;

/// One CSV row per member: id, latitude, class, levels, surface pressure, top, air column,
/// precipitable water and XCO2 (empty where the profile has no H2O or CO2).
pub fn info_csv(set: &ProfileSet) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "id,latitude_deg,class,levels,surface_p_hPa,top_altitude_km,air_column_per_cm2,precipitable_water_mm,xco2_ppm"
    );
    for m in &set.members {
        let p = &m.profile;
        let pw = p
            .precipitable_water_kg_per_m2()
            .map(|v| format!("{v:.3}"))
            .unwrap_or_default();
        let xco2 = p
            .column_average_dry_vmr("CO2")
            .map(|v| format!("{:.3}", v * 1e6))
            .unwrap_or_default();
        let _ = writeln!(
            s,
            "{},{},{},{},{:.2},{:.2},{:.5e},{pw},{xco2}",
            csv_field(&m.meta.id),
            m.meta.latitude_deg,
            m.meta.class(),
            p.len(),
            p.surface_pressure_pa() / 100.0,
            p.altitude_m[p.len() - 1] / 1e3,
            p.air_column_per_m2() * 1e-4
        );
    }
    s
}

/// What `profiles generate` asks for: the members, the mean profile (an AFGL atmosphere, the
/// mean of a set or of a class, one profile of a file), its CO2, the covariance (a file, an
/// error model, forecast/analysis pairs) and the humidity cap ([`generate`]).
#[derive(Debug, Clone)]
pub struct GenerateRequest {
    /// Number of members.
    pub n: usize,
    /// Seed of the random generator.
    pub seed: u64,
    /// Latitude class of the mean (of `set`, or of the AFGL atmospheres).
    pub class: Option<LatitudeClass>,
    /// Mean profile: a built-in AFGL atmosphere.
    pub atmosphere: Option<StandardAtmosphere>,
    /// Mean profile: the mean of this set.
    pub set: Option<PathBuf>,
    /// Mean profile: a profile of this set file.
    pub mean_profile: Option<PathBuf>,
    /// Which profile of `mean_profile`.
    pub profile_id: Option<String>,
    /// The mean's CO2 \[ppm\], applied as `co2_scaling` says.
    pub co2_ppm: Option<f64>,
    /// How `co2_ppm` is applied (well mixed in dry air by default).
    pub co2_scaling: Co2Scaling,
    /// A covariance file.
    pub covariance: Option<PathBuf>,
    /// A per-level error table; the representative NWP forecast error without one.
    pub error_model: Option<PathBuf>,
    /// Forecast and analysis profile sets.
    pub pairs: Option<Vec<PathBuf>>,
    /// Localization length (ln p) of the covariance from `pairs`.
    pub localization_lnp: Option<f64>,
    /// Error model: temperature correlation length (ln p).
    pub t_corr_length: Option<f64>,
    /// Error model: ln humidity correlation length (ln p).
    pub q_corr_length: Option<f64>,
    /// Error model: surface pressure standard deviation \[hPa\].
    pub ps_std_hpa: Option<f64>,
    /// Error model: CO2 standard deviation \[ppm\].
    pub co2_std_ppm: Option<f64>,
    /// Error model: CO2 correlation length (ln p).
    pub co2_corr_length: f64,
    /// Error model: no class scaling.
    pub no_class_scaling: bool,
    /// Repair a covariance that is not positive semi-definite.
    pub repair_covariance: bool,
    /// Humidity cap \[% relative humidity\].
    pub max_rh_percent: f64,
    /// Relative humidity over `water` or `ice`.
    pub rh_over: String,
}

impl GenerateRequest {
    /// Every number inside the range `profiles generate`'s options allow (its parser checks
    /// them; a request built in code, the Python package's, is checked here): an error names
    /// the field.
    pub fn check(&self) -> Result<(), ProductError> {
        use crate::input::{Bounds, check_finite_range as check};
        let bad =
            |name: &'static str| move |m: String| ProductError::Request(format!("{name}: {m}"));
        if self.n == 0 {
            return Err(ProductError::Request("n: at least one member".into()));
        }
        let optional = [
            ("co2_ppm", self.co2_ppm, Bounds::positive(1e6)),
            (
                "localization_lnp",
                self.localization_lnp,
                Bounds::positive(100.0),
            ),
            ("t_corr_length", self.t_corr_length, Bounds::positive(100.0)),
            ("q_corr_length", self.q_corr_length, Bounds::positive(100.0)),
            ("ps_std_hpa", self.ps_std_hpa, Bounds::closed(0.0, 100.0)),
            ("co2_std_ppm", self.co2_std_ppm, Bounds::closed(0.0, 1e3)),
        ];
        for (name, v, bounds) in optional {
            if let Some(v) = v {
                check(v, bounds).map_err(bad(name))?;
            }
        }
        check(self.co2_corr_length, Bounds::positive(100.0)).map_err(bad("co2_corr_length"))?;
        check(self.max_rh_percent, Bounds::positive(200.0)).map_err(bad("max_rh_percent"))?;
        if self.rh_over != "water" && self.rh_over != "ice" {
            return Err(ProductError::Request(format!(
                "rh_over: `{}` (known: water, ice)",
                self.rh_over
            )));
        }
        Ok(())
    }
}

/// The ensemble of `a` and the covariance it was drawn with; each line of its report (the
/// bias removed, a repair, the humidity cap, the covariance's notes) is handed to `say` as it
/// is known.
pub fn generate(
    a: &GenerateRequest,
    say: &mut dyn FnMut(&str) -> Result<(), ProductError>,
) -> Result<(ProfileSet, Covariance), ProductError> {
    a.check()?;
    let (mut mean, source) = mean_member(a)?;
    // Before the covariance is built: a huge ensemble is refused at once.
    crate::limits::check_product(
        "--n",
        &[
            ("profiles", a.n as u64),
            ("levels", mean.profile.len() as u64),
        ],
        crate::limits::MAX_ENSEMBLE_LEVELS,
    )
    .map_err(ProductError::Request)?;
    let mut notes = vec![format!(
        "generated by lidarsim profiles generate: {} members, seed {}",
        a.n, a.seed
    )];
    notes.push(format!("mean profile: {source}"));
    if let Some(ppm) = a.co2_ppm {
        mean.profile.set_co2_ppm(ppm, a.co2_scaling)?;
        notes.push(format!("mean {}", a.co2_scaling.describe(ppm)));
    }
    let class = LatitudeClass::of_latitude_deg(mean.meta.latitude_deg);
    let cov = if let Some(path) = &a.covariance {
        Covariance::read(path)?.on_profile(&mean.profile)
    } else if let Some(p) = &a.pairs {
        let f = read_profile_set(&p[0])?;
        let an = read_profile_set(&p[1])?;
        let (c, bias) = Covariance::from_pairs(&f, &an, &mean.profile, a.localization_lnp)?;
        let n = mean.profile.len();
        let rms = |s: &[f64]| (s.iter().map(|x| x * x).sum::<f64>() / s.len() as f64).sqrt();
        say(&format!(
            "forecast − analysis bias (removed): rms over levels T {:.3} K, ln q {:.3}, CO2 {:.3} ppm; p_s {:.3} hPa",
            rms(&bias[..n]),
            rms(&bias[n..2 * n]),
            rms(&bias[2 * n..3 * n]),
            bias[3 * n]
        ))?;
        c
    } else {
        let mut m = match &a.error_model {
            Some(path) => ErrorModel::read(path)?,
            None => ErrorModel::representative(),
        };
        if let Some(v) = a.t_corr_length {
            m.temperature_corr_length_lnp = v;
        }
        if let Some(v) = a.q_corr_length {
            m.ln_h2o_corr_length_lnp = v;
        }
        if let Some(v) = a.ps_std_hpa {
            m.surface_pressure_std_hpa = v;
        }
        if let Some(v) = a.co2_std_ppm {
            m = m.with_co2(v, a.co2_corr_length);
        }
        if !a.no_class_scaling {
            m = m.scaled_for_class(class);
        }
        m.covariance(&mean.profile)?
    };
    notes.extend(cov.notes.iter().cloned());
    let saturation = match a.rh_over.as_str() {
        "ice" => SaturationOver::IceBelowTriplePoint,
        _ => SaturationOver::Water,
    };
    let cfg = EnsembleConfig {
        n: a.n,
        seed: a.seed,
        max_relative_humidity: a.max_rh_percent / 100.0,
        saturation,
        id_prefix: format!("{}-", class.name()),
        allow_repair: a.repair_covariance,
    };
    let (mut set, report) = generate_ensemble(&mean, &cov, &cfg)?;
    if let Some(r) = &report.repair {
        notes.push(r.to_string());
        say(&format!("note: {r}"))?;
    }
    let cap = format!(
        "water vapour capped at {} % relative humidity over {} (Murphy and Koop 2005): {} of {} values in {} of {} members",
        a.max_rh_percent,
        a.rh_over,
        report.capped_values,
        report.total_values,
        report.capped_members,
        a.n
    );
    say(&cap)?;
    notes.push(cap);
    if report.mean_levels_above_limit > 0 {
        let w = format!(
            "the mean profile itself exceeds {} % relative humidity at {} of {} levels (a mean over different climates?); members are capped there",
            a.max_rh_percent,
            report.mean_levels_above_limit,
            mean.profile.len()
        );
        say(&format!("warning: {w}"))?;
        notes.push(w);
    }
    for n in &cov.notes {
        say(&format!("covariance: {n}"))?;
    }
    set.notes = notes;
    Ok((set, cov))
}

/// The mean profile and a description of where it comes from.
/// Give every member of `set` (a converted set: `profiles convert --co2-ppm`) `ppm` of CO2 as
/// `scaling` says, and note it in the set's header. An error names the first member that cannot
/// take it (with `profile_shape`, one without CO2).
pub fn set_co2(set: &mut ProfileSet, ppm: f64, scaling: Co2Scaling) -> Result<(), ProductError> {
    for m in &mut set.members {
        m.profile.set_co2_ppm(ppm, scaling).map_err(|e| {
            ProductError::Request(format!("--co2-ppm: profile `{}`: {e}", m.meta.id))
        })?;
    }
    set.notes.push(scaling.describe(ppm));
    Ok(())
}

fn mean_member(a: &GenerateRequest) -> Result<(SetMember, String), ProductError> {
    if let Some(atm) = a.atmosphere {
        if a.class.is_some() {
            return Err(ProductError::Request(
                "give --atmosphere or --class without --set, not both".into(),
            ));
        }
        return Ok((atm.member(), format!("AFGL {}", atm.name())));
    }
    if let Some(path) = &a.mean_profile {
        let set = read_profile_set(path)?;
        let m = match &a.profile_id {
            Some(id) => set
                .members
                .iter()
                .find(|m| &m.meta.id == id)
                .ok_or_else(|| {
                    ProductError::Request(format!("{}: no profile `{id}`", path.display()))
                })?
                .clone(),
            None if set.len() == 1 => set.members[0].clone(),
            None => {
                return Err(ProductError::Request(format!(
                    "{} has {} profiles: choose one with --profile-id",
                    path.display(),
                    set.len()
                )));
            }
        };
        let d = format!("profile `{}` of {}", m.meta.id, path.display());
        return Ok((m, d));
    }
    if let Some(path) = &a.set {
        let set = read_profile_set(path)?;
        let (sub, d) = match a.class {
            Some(c) => (
                set.class(c),
                format!("mean of class {c} of {}", path.display()),
            ),
            None => (set.clone(), format!("mean of {}", path.display())),
        };
        if sub.is_empty() {
            return Err(ProductError::Request(format!(
                "{}: no profiles in class {:?}",
                path.display(),
                a.class.map(|c| c.name())
            )));
        }
        let n = sub.len();
        return Ok((sub.mean_member()?, format!("{d} ({n} profiles)")));
    }
    if let Some(c) = a.class {
        let set = ProfileSet {
            name: format!("AFGL {c}"),
            members: c.afgl_atmospheres().iter().map(|s| s.member()).collect(),
            notes: vec![],
        };
        let names: Vec<_> = c.afgl_atmospheres().iter().map(|s| s.name()).collect();
        return Ok((
            set.mean_member()?,
            format!("mean of AFGL {}", names.join(" + ")),
        ));
    }
    Err(ProductError::Request(
        "no mean profile: give --class, --atmosphere, --set or --mean-profile".into(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request() -> GenerateRequest {
        GenerateRequest {
            n: 3,
            seed: 1,
            class: None,
            atmosphere: None,
            set: None,
            mean_profile: None,
            profile_id: None,
            co2_ppm: Some(420.0),
            co2_scaling: Co2Scaling::WellMixed,
            covariance: None,
            error_model: None,
            pairs: None,
            localization_lnp: None,
            t_corr_length: None,
            q_corr_length: None,
            ps_std_hpa: Some(0.0),
            co2_std_ppm: Some(1e3),
            co2_corr_length: 0.35,
            no_class_scaling: false,
            repair_covariance: false,
            max_rh_percent: 200.0,
            rh_over: "ice".into(),
        }
    }

    /// A request built in code is held to `profiles generate`'s ranges, each refusal naming
    /// the field; the ends the options allow pass.
    #[test]
    fn requests_are_held_to_the_options_ranges() {
        assert!(request().check().is_ok());
        let with = |f: fn(&mut GenerateRequest)| {
            let mut r = request();
            f(&mut r);
            r.check().map_err(|e| e.to_string())
        };
        for (bad, name) in [
            (with(|r| r.n = 0), "n:"),
            (with(|r| r.co2_ppm = Some(0.0)), "co2_ppm"),
            (
                with(|r| r.localization_lnp = Some(-1.0)),
                "localization_lnp",
            ),
            (with(|r| r.t_corr_length = Some(101.0)), "t_corr_length"),
            (
                with(|r| r.q_corr_length = Some(f64::INFINITY)),
                "q_corr_length",
            ),
            (with(|r| r.ps_std_hpa = Some(-0.1)), "ps_std_hpa"),
            (with(|r| r.co2_std_ppm = Some(1001.0)), "co2_std_ppm"),
            (with(|r| r.co2_corr_length = 0.0), "co2_corr_length"),
            (with(|r| r.max_rh_percent = 200.1), "max_rh_percent"),
            (with(|r| r.rh_over = "steam".into()), "rh_over"),
        ] {
            assert!(
                bad.as_ref().is_err_and(|m| m.contains(name)),
                "{name}: {bad:?}"
            );
        }
        assert!(with(|r| r.rh_over = "water".into()).is_ok());
    }
}
