//! Step 2 for `[atmosphere]`: one source of the profile, and the values of its keys and of a
//! profile given by values (the profile's own order and range are checked once resolve has
//! it).

use super::description::{AtmosphereDescription, ProfileDescription};
use super::ranges::*;
use super::source::KeyPath;
use super::validator::Validator;
use crate::atmosphere::Co2Scaling;
use crate::input::{InputError, check_finite_range, names};

impl Validator<'_> {
    /// `[atmosphere]`: one source of the profile, and the values of its keys (the profile's own
    /// range is checked once resolve has it).
    pub(super) fn atmosphere(
        &self,
        a: &AtmosphereDescription,
        n_lines: usize,
    ) -> Result<(), InputError> {
        let sec = KeyPath::table("atmosphere");
        let explicit = a.altitude_m.is_some() || a.air_number_density_per_m3.is_some();
        let sources = [
            a.standard.is_some(),
            a.profile_file.is_some(),
            a.profile.is_some(),
            explicit,
        ];
        if sources.iter().filter(|x| **x).count() != 1 {
            return Err(self.err(
                &sec,
                "needs exactly one of `standard` (an AFGL atmosphere), `profile_file` (a profile \
                 set, with `profile_id`), `profile` (a profile given by values), or `altitude_m` \
                 with `air_number_density_per_m3`",
            ));
        }
        if let Some(p) = &a.profile {
            self.inline_profile(&sec.key("profile"), p)?;
        }
        if explicit {
            match (&a.altitude_m, &a.air_number_density_per_m3) {
                (Some(z), Some(n)) => self.density_profile(&sec, z, n)?,
                _ => {
                    return Err(self.err(
                        &sec,
                        "`altitude_m` and `air_number_density_per_m3` go together",
                    ));
                }
            }
        }
        if let Some(name) = &a.standard {
            names::standard_atmosphere(name).map_err(|m| self.err(&sec.key("standard"), m))?;
        }
        if a.profile_id.is_some() && a.profile_file.is_none() {
            return Err(self.err(&sec.key("profile_id"), "goes with `profile_file`"));
        }
        if let Some(ppm) = a.co2_ppm {
            self.range(&sec.key("co2_ppm"), ppm, CO2_PPM)?;
        }
        if let Some(s) = &a.co2_scaling {
            let at = sec.key("co2_scaling");
            s.parse::<Co2Scaling>().map_err(|m| self.err(&at, m))?;
            if a.co2_ppm.is_none() {
                return Err(self.err(&at, "goes with `co2_ppm`"));
            }
        }
        if let Some(t) = a.top_m {
            self.range(&sec.key("top_m"), t, ALTITUDE_M)?;
        }
        if let Some(t) = a.layer_thickness_m {
            self.range(&sec.key("layer_thickness_m"), t, LAYER_THICKNESS_M)?;
        }
        if let Some(v) = &a.depolarization_factor {
            let at = sec.key("depolarization_factor");
            let d = self.per_channel(&at, v, n_lines)?;
            self.range_all(&at, &d, DEPOLARISATION)?;
        }
        Ok(())
    }

    /// A profile given by values: as many values of each quantity as levels, each finite and in
    /// its range (the profile's own order and range are checked when resolved).
    fn inline_profile(&self, at: &KeyPath, p: &ProfileDescription) -> Result<(), InputError> {
        let n = p.altitude_m.len();
        if n < 2 {
            return Err(self.err(at, format!("has {n} levels, at least 2 are needed")));
        }
        let mut quantities = vec![
            ("altitude_m", &p.altitude_m, ALTITUDE_M),
            ("pressure_pa", &p.pressure_pa, PROFILE_PRESSURE_PA),
            ("temperature_k", &p.temperature_k, PROFILE_TEMPERATURE_K),
        ];
        for g in &p.gases {
            quantities.push((g.name.as_str(), &g.vmr, FRACTION));
        }
        for (name, v, bounds) in quantities {
            if v.len() != n {
                return Err(self.err(
                    at,
                    format!("`{name}` has {} values, `altitude_m` {n}", v.len()),
                ));
            }
            for x in v.iter() {
                check_finite_range(*x, bounds)
                    .map_err(|m| self.err(at, format!("`{name}`: {m}")))?;
            }
        }
        let mut names = std::collections::HashSet::new();
        if let Some(g) = p.gases.iter().find(|g| !names.insert(g.name.as_str())) {
            return Err(self.err(at, format!("gas `{}` is given twice", g.name)));
        }
        Ok(())
    }

    /// An air-density profile given as values.
    fn density_profile(&self, sec: &KeyPath, z: &[f64], n: &[f64]) -> Result<(), InputError> {
        let at_z = sec.key("altitude_m");
        let at_n = sec.key("air_number_density_per_m3");
        if z.len() != n.len() || z.len() < 2 {
            return Err(self.err(&at_n, "needs as many values as `altitude_m`, at least two"));
        }
        self.range_all(&at_z, z, ALTITUDE_M)?;
        self.range_all(&at_n, n, AIR_NUMBER_DENSITY_PER_M3)?;
        if z.windows(2).any(|w| w[1] <= w[0]) {
            return Err(self.err(&at_z, "must strictly increase"));
        }
        Ok(())
    }
}
