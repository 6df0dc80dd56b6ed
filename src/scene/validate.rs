//! Step 2 of a scene: every check that needs only the description's values, with no file
//! read and no physics (this file uses only the scene, input and limits modules). What it
//! finds on the way (the lidar, the lines, the gates, the surface, the Monte Carlo settings)
//! it hands to resolve.

use std::path::PathBuf;

use super::description::{
    GasAbsorptionDescription, LayerDescription, OneOrMany, PerChannel, PhaseDescription,
    SceneDescription,
};
use super::ranges::*;
use super::source::KeyPath;
use super::validate_instrument::{LaserValues, ReceiverValues};
use super::validate_retrieval::{Known, RetrievalValues};
use super::validator::Validator;
use super::{
    BeamProfile, Channel, Gates, Lidar, MULTIPLE_SCATTERING_TOLERANCE, MultipleScattering,
    Polarisation, Simulation, Surface, VarianceReduction,
};
use crate::input::{Bounds, InputError, check_count, check_finite_range, names};

/// What validation finds on the way, for resolve to build on.
pub(super) struct Checked {
    /// The lidar; its pulse energy is set from the laser by resolve.
    pub lidar: Lidar,
    /// The laser lines (`[[channel]]`).
    pub lines: Vec<Channel>,
    pub gates: Gates,
    /// The Monte Carlo settings, `cache_dir` as written.
    pub simulation: Simulation,
    pub surface: Option<Surface>,
    /// The laser's values (`[laser]`, or the ideal laser of `[lidar] pulse_energy_j`).
    pub laser: LaserValues,
    /// The receiver's values (`[receiver]`, `[background]`), if any.
    pub receiver: Option<ReceiverValues>,
    /// What to retrieve (`[retrieval]`), if anything.
    pub retrieval: Option<RetrievalValues>,
}

/// What the size of the problem depends on, as far as it is known.
pub(super) struct ProblemSize<'a> {
    pub lidar: &'a Lidar,
    pub gates: &'a Gates,
    pub simulation: &'a Simulation,
    /// Monochromatic channels plus line sums.
    pub channels_and_sums: u64,
    pub n_lines: u64,
    /// Layers of the molecular grid, once the profile is known.
    pub molecular_layers: Option<u64>,
    pub n_particle_layers: usize,
}

impl Validator<'_> {
    /// Every check of the description's values, in the order of the file's sections.
    pub fn check(&self, d: &SceneDescription) -> Result<Checked, InputError> {
        let (lidar, lidar_pulse_energy_j) = self.lidar(d)?;
        let lines = self.channels(d)?;
        let gates = self.gates(d)?;
        let simulation = self.simulation(d)?;
        if simulation.jacobians && lidar.polarisation != Polarisation::None {
            return Err(self.err(
                &KeyPath::table("simulation").key("jacobians"),
                "Jacobians are tallied for unpolarised light only: set \
                 `[lidar] polarisation = \"none\"` or leave `jacobians` out",
            ));
        }
        // A first look at the size with what is known (each line is at least one channel and
        // one line sum), so that a huge problem is refused before Mie theory and line-by-line
        // work on each of its channels.
        self.problem_size(
            d,
            &ProblemSize {
                lidar: &lidar,
                gates: &gates,
                simulation: &simulation,
                channels_and_sums: 2 * lines.len() as u64,
                n_lines: lines.len() as u64,
                molecular_layers: None,
                n_particle_layers: 0,
            },
        )?;
        if let Some(a) = &d.atmosphere {
            self.atmosphere(a, lines.len())?;
        }
        for (i, l) in d.layer.iter().enumerate() {
            self.layer(i, l, lines.len())?;
        }
        let surface = self.surface(d, &lidar, &gates, lines.len())?;
        if let Some(g) = &d.gas_absorption {
            self.gas(g, d.atmosphere.is_some())?;
        }
        let laser = self.laser(d, &lines, lidar_pulse_energy_j)?;
        let receiver = self.receiver(d, surface.as_ref().map(|s| s.albedo[0]))?;
        let retrieval = self.retrieval(
            d,
            &Known {
                lines: &lines,
                lidar: &lidar,
                laser: &laser,
                gates: &gates,
                surface: surface.as_ref(),
            },
        )?;
        Ok(Checked {
            lidar,
            lines,
            gates,
            simulation,
            surface,
            laser,
            receiver,
            retrieval,
        })
    }

    /// The whole problem against the limits of memory and time ([`crate::limits`]), before
    /// anything large is allocated; an error names the key of the largest factor.
    pub fn problem_size(&self, raw: &SceneDescription, p: &ProblemSize) -> Result<(), InputError> {
        use crate::limits::{MAX_OPTICAL_CELLS, MAX_RETURN_BINS, check_product};
        let (channels_and_sums, n_lines) = (p.channels_and_sums, p.n_lines);
        // Every channel, every line sum (and its derivatives) and every pair of lines whose
        // covariance is kept has its own returns.
        let series = channels_and_sums + n_lines * n_lines.saturating_sub(1) / 2;
        let n_channels = channels_and_sums.saturating_sub(n_lines);
        let gates_n = p.gates.count as u64;
        let fovs = p.lidar.fov_full_angle_mrad.len() as u64;
        // total, 1..=N, N+ and (N ≥ 2) 2+.
        let order_bins =
            u64::from(p.simulation.max_order) + 2 + u64::from(p.simulation.max_order >= 2);
        let blame = [
            (gates_n, KeyPath::table("gates").key("width_m")),
            (fovs, KeyPath::table("lidar").key("fov_full_angle_mrad")),
            (order_bins, KeyPath::table("simulation").key("max_order")),
            (
                series,
                if raw.laser.is_some() && n_channels > n_lines {
                    KeyPath::table("laser").key("line_shape_nodes")
                } else {
                    KeyPath::array("channel", raw.channel.len().saturating_sub(1))
                },
            ),
        ];
        check_product(
            "the returns",
            &[
                ("gates", gates_n),
                ("fields of view", fovs),
                ("order bins", order_bins),
                ("channels, line sums and line pairs", series),
            ],
            MAX_RETURN_BINS,
        )
        .map_err(|m| {
            let at = &blame
                .iter()
                .max_by_key(|(n, _)| *n)
                .expect("four factors")
                .1;
            self.err(at, m)
        })?;
        if let Some(molecular) = p.molecular_layers {
            // Molecular layers, split again at every particle-layer boundary.
            let layers = molecular + 2 * p.n_particle_layers as u64 + 2;
            check_product(
                "the optical atmosphere",
                &[("layers", layers), ("channels", n_channels)],
                MAX_OPTICAL_CELLS,
            )
            .map_err(|m| self.err(&KeyPath::table("atmosphere").key("layer_thickness_m"), m))?;
        }
        Ok(())
    }

    /// The lidar, and the pulse energy if `[lidar]` gives one (it may come from `[laser]`).
    fn lidar(&self, raw: &SceneDescription) -> Result<(Lidar, Option<f64>), InputError> {
        let l = &raw.lidar;
        let sec = KeyPath::table("lidar");
        let (_, altitude_m) = self.one_of(
            &sec,
            ("altitude_m", l.altitude_m, 1.0, ALTITUDE_M),
            ("altitude_km", l.altitude_km, 1e3, ALTITUDE_KM),
        )?;
        let zenith_angle_deg =
            self.range(&sec.key("zenith_angle_deg"), l.zenith_angle_deg, ZENITH_DEG)?;
        let azimuth_deg = match l.azimuth_deg {
            Some(a) => self.range(&sec.key("azimuth_deg"), a, AZIMUTH_DEG)?,
            None => 0.0,
        };
        let pulse_energy_j = match l.pulse_energy_j {
            Some(e) => Some(self.range(&sec.key("pulse_energy_j"), e, PULSE_ENERGY_J)?),
            None => None,
        };
        let div = self.range(
            &sec.key("beam_divergence_full_angle_mrad"),
            l.beam_divergence_full_angle_mrad,
            DIVERGENCE_MRAD,
        )?;
        let beam_profile = match l.beam_profile.as_deref() {
            None | Some("uniform") => BeamProfile::Uniform,
            Some("gaussian") => BeamProfile::Gaussian,
            Some(other) => {
                return Err(self.err(
                    &sec.key("beam_profile"),
                    format!("`{other}` is not a beam profile (uniform, gaussian)"),
                ));
            }
        };
        let polarisation = match l.polarisation.as_deref() {
            None | Some("none") => Polarisation::None,
            Some("linear") => Polarisation::Linear,
            Some("circular") => Polarisation::Circular,
            Some(other) => {
                return Err(self.err(
                    &sec.key("polarisation"),
                    format!("`{other}` is not a polarisation (none, linear, circular)"),
                ));
            }
        };
        let telescope_diameter_m = self.range(
            &sec.key("telescope_diameter_m"),
            l.telescope_diameter_m,
            TELESCOPE_DIAMETER_M,
        )?;
        let optical_efficiency = self.range(
            &sec.key("optical_efficiency"),
            l.optical_efficiency,
            EFFICIENCY,
        )?;
        let fov_at = sec.key("fov_full_angle_mrad");
        let fov_full_angle_mrad = match &l.fov_full_angle_mrad {
            PerChannel::One(x) => vec![*x],
            PerChannel::Many(xs) => xs.clone(),
        };
        if fov_full_angle_mrad.is_empty() {
            return Err(self.err(&fov_at, "needs at least one field of view"));
        }
        self.range_all(&fov_at, &fov_full_angle_mrad, FOV_MRAD)?;
        // Sorted, so that a list of any length is checked in n log n.
        let mut sorted = fov_full_angle_mrad.clone();
        sorted.sort_by(f64::total_cmp);
        if let Some(w) = sorted.windows(2).find(|w| w[0] == w[1]) {
            return Err(self.err(&fov_at, format!("{} mrad is given twice", w[0])));
        }
        Ok((
            Lidar {
                altitude_m,
                zenith_angle_deg,
                azimuth_deg,
                // Set from the laser once it is known.
                pulse_energy_j: f64::NAN,
                beam_divergence_full_angle_mrad: div,
                beam_profile,
                telescope_diameter_m,
                optical_efficiency,
                fov_full_angle_mrad,
                polarisation,
            },
            pulse_energy_j,
        ))
    }

    fn channels(&self, raw: &SceneDescription) -> Result<Vec<Channel>, InputError> {
        if raw.channel.is_empty() {
            return Err(self.err(&KeyPath::root(), "needs at least one [[channel]]"));
        }
        let mut out: Vec<Channel> = Vec::new();
        let mut names = std::collections::HashSet::new();
        for (i, c) in raw.channel.iter().enumerate() {
            let sec = KeyPath::array("channel", i);
            let wavenumber_cm1 = match (c.wavelength_nm, c.wavenumber_cm1) {
                (Some(w), None) => 1e7 / self.range(&sec.key("wavelength_nm"), w, WAVELENGTH_NM)?,
                (None, Some(k)) => self.range(&sec.key("wavenumber_cm1"), k, WAVENUMBER_CM1)?,
                (Some(_), Some(_)) => {
                    return Err(self.err(
                        &sec.key("wavenumber_cm1"),
                        "give `wavelength_nm` or `wavenumber_cm1`, not both",
                    ));
                }
                (None, None) => {
                    return Err(self.err(&sec, "needs `wavelength_nm` or `wavenumber_cm1`"));
                }
            };
            if !names.insert(c.name.as_str()) {
                return Err(self.err(
                    &sec.key("name"),
                    format!("channel `{}` is given twice", c.name),
                ));
            }
            // Any other text is a name: CSV files quote it (`crate::output::csv_field`).
            if c.name.is_empty() {
                return Err(self.err(&sec.key("name"), "must not be empty"));
            }
            out.push(Channel {
                name: c.name.clone(),
                wavenumber_cm1,
            });
        }
        Ok(out)
    }

    fn gates(&self, raw: &SceneDescription) -> Result<Gates, InputError> {
        let g = &raw.gates;
        let sec = KeyPath::table("gates");
        // r = 0 is excluded: the single-scatter return diverges as 1/r² at the lidar.
        let start_m = self.range(&sec.key("start_m"), g.start_m, RANGE_M)?;
        let width_m = self.range(&sec.key("width_m"), g.width_m, GATE_WIDTH_M)?;
        let end_m = self.range(&sec.key("end_m"), g.end_m, RANGE_M)?;
        if !(end_m > start_m) {
            return Err(self.err(&sec.key("end_m"), "must be greater than `start_m`"));
        }
        let n = (end_m - start_m) / width_m;
        let count = n.round();
        if (n - count).abs() > 1e-6 * n.max(1.0) {
            return Err(self.err(
                &sec.key("end_m"),
                format!(
                    "end_m − start_m = {} m is not a whole number of {width_m} m gates",
                    end_m - start_m
                ),
            ));
        }
        // The gates alone must fit in the returns; with channels, fields of view and orders
        // they are checked again once all are known.
        crate::limits::check_product(
            "the range gates",
            &[("gates", count as u64)],
            crate::limits::MAX_RETURN_BINS,
        )
        .map_err(|m| self.err(&sec.key("width_m"), m))?;
        Ok(Gates {
            start_m,
            width_m,
            count: count as usize,
        })
    }

    fn simulation(&self, raw: &SceneDescription) -> Result<Simulation, InputError> {
        let s = raw.simulation.clone().unwrap_or_default();
        let sec = KeyPath::table("simulation");
        let sim = Simulation {
            photons: s.photons.unwrap_or(1_000_000),
            seed: s.seed.unwrap_or(1),
            max_order: s.max_order.unwrap_or(5),
            threads: s.threads.unwrap_or(0),
            batches: s.batches.unwrap_or(100),
            // Anchored at the base directory by resolve.
            cache_dir: s.cache_dir.as_ref().map(PathBuf::from),
            multiple_scattering: match s.multiple_scattering.as_deref() {
                None | Some("auto") => MultipleScattering::Auto,
                Some("always") => MultipleScattering::Always,
                Some("never") => MultipleScattering::Never,
                Some(other) => {
                    return Err(self.err(
                        &sec.key("multiple_scattering"),
                        format!("`{other}` is not a choice (auto, always, never)"),
                    ));
                }
            },
            multiple_scattering_tolerance: match s.multiple_scattering_tolerance {
                None => MULTIPLE_SCATTERING_TOLERANCE,
                Some(v) => {
                    self.range(&sec.key("multiple_scattering_tolerance"), v, MS_TOLERANCE)?
                }
            },
            jacobians: s.jacobians.unwrap_or(false),
            variance_reduction: VarianceReduction::default(),
        };
        check_count(sim.max_order.into(), 1, 1000)
            .map_err(|m| self.err(&sec.key("max_order"), m))?;
        check_count(sim.batches as u64, 2, crate::limits::MAX_BATCHES).map_err(|m| {
            self.err(
                &sec.key("batches"),
                format!("{m} (at least 2 for error bars)"),
            )
        })?;
        check_count(sim.photons, 0, crate::limits::MAX_PHOTONS)
            .map_err(|m| self.err(&sec.key("photons"), m))?;
        check_count(sim.threads as u64, 0, crate::limits::MAX_THREADS)
            .map_err(|m| self.err(&sec.key("threads"), format!("{m} (0: all cores)")))?;
        if sim.multiple_scattering == MultipleScattering::Always && sim.photons == 0 {
            return Err(self.err(
                &sec.key("multiple_scattering"),
                "\"always\" needs photons > 0 (`photons = 0` runs the analytic lidar equation only)",
            ));
        }
        // 0 photons: the analytic lidar equation only.
        if sim.photons != 0 && sim.photons < sim.batches as u64 {
            return Err(self.err(
                &sec.key("photons"),
                "must be 0 (analytic only) or at least the number of batches",
            ));
        }
        Ok(sim)
    }

    /// `[[layer]]` number `i`: its extent, and its particles given by optics or by a size
    /// distribution, or its absorption.
    fn layer(&self, i: usize, l: &LayerDescription, nch: usize) -> Result<(), InputError> {
        let sec = KeyPath::array("layer", i);
        self.range(&sec.key("base_m"), l.base_m, ALTITUDE_M)?;
        self.range(&sec.key("top_m"), l.top_m, ALTITUDE_M)?;
        if !(l.top_m > l.base_m) {
            return Err(self.err(&sec.key("top_m"), "must be above `base_m`"));
        }
        if l.particles.is_some() {
            self.particles(&sec, l, nch)?;
            return self.absorption(&sec, l, nch);
        }
        if l.number_density_per_cm3.is_some() {
            return Err(self.err(&sec.key("number_density_per_cm3"), "goes with `particles`"));
        }
        let content = self.water_content(&sec, l)?;
        match (&content, l.r_eff_um) {
            (Some(_), None) => {
                return Err(self.err(
                    &sec,
                    "a layer given by its water content needs `r_eff_um` (the effective radius, µm)",
                ));
            }
            (None, Some(_)) => {
                return Err(self.err(
                    &sec.key("r_eff_um"),
                    "goes with `lwc_g_per_m3` or `iwc_g_per_m3` (or with a lognormal of `particles`)",
                ));
            }
            (Some(_), Some(r)) => {
                self.range(&sec.key("r_eff_um"), r, RADIUS_UM)?;
            }
            (None, None) => {}
        }
        if let (Some((at, _)), true) = (
            &content,
            l.extinction_per_m.is_some() || l.extinction_per_km.is_some(),
        ) {
            return Err(self.err(
                at,
                "give the particles' amount as `extinction_per_m`, `extinction_per_km` or a water content with `r_eff_um`, one of them",
            ));
        }
        let ext = match (&l.extinction_per_m, &l.extinction_per_km) {
            (Some(v), None) => Some((sec.key("extinction_per_m"), v, COEFFICIENT_PER_M)),
            (None, Some(v)) => Some((sec.key("extinction_per_km"), v, COEFFICIENT_PER_KM)),
            (Some(_), Some(_)) => {
                return Err(self.err(
                    &sec.key("extinction_per_km"),
                    "give `extinction_per_m` or `extinction_per_km`, not both",
                ));
            }
            (None, None) => None,
        };
        let has_particles = ext.is_some() || content.is_some();
        if let Some((at, v, bounds)) = ext {
            let e = self.per_channel(&at, v, nch)?;
            self.range_all(&at, &e, bounds)?;
        }
        match has_particles {
            true => {
                let ssa_at = sec.key("single_scattering_albedo");
                let ssa_raw = l.single_scattering_albedo.as_ref().ok_or_else(|| {
                    self.err(
                        &sec,
                        "a layer with extinction needs `single_scattering_albedo`",
                    )
                })?;
                let ssa = self.per_channel(&ssa_at, ssa_raw, nch)?;
                self.range_all(&ssa_at, &ssa, FRACTION)?;
                let specs = l
                    .phase
                    .as_ref()
                    .ok_or_else(|| self.err(&sec, "a layer with extinction needs `phase`"))?;
                for s in self.phase_specs(&sec.key("phase"), specs, nch)? {
                    self.phase(&sec.key("phase"), s)?;
                }
            }
            false => {
                if l.single_scattering_albedo.is_some() || l.phase.is_some() {
                    return Err(self.err(
                        &sec,
                        "`single_scattering_albedo` and `phase` need `extinction_per_m`, `extinction_per_km` or a water content (`lwc_g_per_m3`/`iwc_g_per_m3` with `r_eff_um`)",
                    ));
                }
            }
        }
        self.absorption(&sec, l, nch)?;
        if !has_particles && l.absorption_per_m.is_none() {
            return Err(self.err(
                &sec,
                "a layer needs particles (`extinction_per_m`/`_per_km`, or `lwc_g_per_m3`/`iwc_g_per_m3` with `r_eff_um`) or `absorption_per_m`",
            ));
        }
        Ok(())
    }

    /// A layer's condensed-water content, `lwc_g_per_m3` or `iwc_g_per_m3` (not both), in its
    /// range: the key it was given at, and the value.
    fn water_content(
        &self,
        sec: &KeyPath,
        l: &LayerDescription,
    ) -> Result<Option<(KeyPath, f64)>, InputError> {
        match (l.lwc_g_per_m3, l.iwc_g_per_m3) {
            (Some(_), Some(_)) => Err(self.err(
                &sec.key("iwc_g_per_m3"),
                "give `lwc_g_per_m3` (liquid) or `iwc_g_per_m3` (ice), not both: a mixed-phase cloud is two layers",
            )),
            (Some(w), None) => {
                let at = sec.key("lwc_g_per_m3");
                self.range(&at, w, WATER_CONTENT_G_PER_M3)?;
                Ok(Some((at, w)))
            }
            (None, Some(w)) => {
                let at = sec.key("iwc_g_per_m3");
                self.range(&at, w, WATER_CONTENT_G_PER_M3)?;
                Ok(Some((at, w)))
            }
            (None, None) => Ok(None),
        }
    }

    /// A layer's phase-function specs, one per channel.
    pub fn phase_specs<'d>(
        &self,
        phase_at: &KeyPath,
        specs: &'d OneOrMany<PhaseDescription>,
        nch: usize,
    ) -> Result<Vec<&'d PhaseDescription>, InputError> {
        match specs {
            OneOrMany::One(s) => Ok(vec![s; nch]),
            OneOrMany::Many(v) if v.len() == nch => Ok(v.iter().collect()),
            OneOrMany::Many(v) => Err(self.err(
                phase_at,
                format!(
                    "has {} entries; give one or one per channel ({nch})",
                    v.len()
                ),
            )),
        }
    }

    /// The keys of a phase-function spec that go together (its values are checked by the
    /// phase function itself, when resolved).
    fn phase(&self, at: &KeyPath, spec: &PhaseDescription) -> Result<(), InputError> {
        if let PhaseDescription::Table { file, builtin } = spec
            && file.is_some() == builtin.is_some()
        {
            return Err(self.err(
                at,
                "a table phase function needs `file` (relative to the scene) or `builtin`, not both",
            ));
        }
        Ok(())
    }

    /// Extra (non-particle) absorption per channel of a layer.
    fn absorption(
        &self,
        sec: &KeyPath,
        l: &LayerDescription,
        nch: usize,
    ) -> Result<(), InputError> {
        let Some(v) = &l.absorption_per_m else {
            return Ok(());
        };
        let at = sec.key("absorption_per_m");
        let a = self.per_channel(&at, v, nch)?;
        self.range_all(&at, &a, COEFFICIENT_PER_M)
    }

    /// A layer of `particles`: a size distribution and refractive index (or an OPAC type), and
    /// its amount; the optics come from Mie theory when resolved.
    fn particles(&self, sec: &KeyPath, l: &LayerDescription, nch: usize) -> Result<(), InputError> {
        let Some(p) = &l.particles else {
            return Ok(());
        };
        let at = sec.key("particles");
        if l.single_scattering_albedo.is_some() || l.phase.is_some() {
            return Err(self.err(
                &at,
                "a layer of `particles` gets its single-scattering albedo and phase function from Mie theory: remove `single_scattering_albedo` and `phase`",
            ));
        }
        let need = |v: Option<f64>, key: &str, bounds: Bounds| {
            let v =
                v.ok_or_else(|| self.err(&at, format!("`{}` needs `{key}`", p.distribution)))?;
            check_finite_range(v, bounds).map_err(|m| self.err(&at, format!("`{key}`: {m}")))
        };
        if let Some(n) = l.number_density_per_cm3 {
            self.range(
                &sec.key("number_density_per_cm3"),
                n,
                PARTICLE_DENSITY_PER_CM3,
            )?;
        }
        for (key, v, b) in [
            ("extinction_per_m", &l.extinction_per_m, COEFFICIENT_PER_M),
            (
                "extinction_per_km",
                &l.extinction_per_km,
                COEFFICIENT_PER_KM,
            ),
        ] {
            if let Some(PerChannel::One(e)) = v {
                self.range(&sec.key(key), *e, Bounds::positive(b.hi))?;
            }
        }
        for (key, v) in [("r_min_um", p.r_min_um), ("r_max_um", p.r_max_um)] {
            if let Some(r) = v {
                check_finite_range(r, Bounds::closed(0.0, RADIUS_UM.hi))
                    .map_err(|m| self.err(&at, format!("`{key}`: {m}")))?;
            }
        }
        if p.distribution == "opac" {
            if l.r_eff_um.is_some() {
                return Err(self.err(
                    &sec.key("r_eff_um"),
                    "an OPAC type has its own sizes: remove `r_eff_um`",
                ));
            }
            if l.lwc_g_per_m3.is_some() || l.iwc_g_per_m3.is_some() {
                return Err(self.err(
                    &at,
                    "an OPAC aerosol type's amount is `number_density_per_cm3` or an extinction, not a water content",
                ));
            }
            if p.refractive_index.is_some() {
                return Err(self.err(&at, "OPAC aerosol types carry their own refractive indices: remove `refractive_index`"));
            }
            let Some(name) = &p.aerosol_type else {
                return Err(self.err(&at, "`opac` needs `aerosol_type`"));
            };
            if names::opac_type(name).is_none() {
                return Err(self.err(
                    &at,
                    format!(
                        "unknown OPAC aerosol type `{name}` (known: {})",
                        names::OPAC_TYPES.join(", ")
                    ),
                ));
            }
        } else {
            if p.aerosol_type.is_some() {
                return Err(self.err(&at, "`aerosol_type` goes with distribution = \"opac\""));
            }
            match p.distribution.as_str() {
                "lognormal" => {
                    // Its size by the median radius, or by the layer's effective radius.
                    match (p.median_radius_um, l.r_eff_um) {
                        (Some(_), Some(_)) => {
                            return Err(self.err(
                                &sec.key("r_eff_um"),
                                "the lognormal's size is given twice: give `median_radius_um` or `r_eff_um`, not both",
                            ));
                        }
                        (None, Some(r)) => {
                            self.range(&sec.key("r_eff_um"), r, RADIUS_UM)?;
                        }
                        _ => {
                            need(p.median_radius_um, "median_radius_um", RADIUS_UM)?;
                        }
                    }
                    need(p.sigma_g, "sigma_g", SIGMA_G)?;
                }
                "modified_gamma" => {
                    if l.r_eff_um.is_some() {
                        return Err(self.err(
                            &sec.key("r_eff_um"),
                            "a modified gamma's size is its `alpha`, `b` and `gamma`: `r_eff_um` goes with a lognormal (for its `median_radius_um`) or a layer without `particles`",
                        ));
                    }
                    need(p.alpha, "alpha", GAMMA_SHAPE)?;
                    need(p.b, "b", GAMMA_SHAPE)?;
                    need(p.gamma, "gamma", GAMMA_SHAPE)?;
                }
                other => {
                    return Err(self.err(
                        &at,
                        format!(
                            "distribution `{other}` is not one of: lognormal, modified_gamma, opac"
                        ),
                    ));
                }
            }
            if p.r_min_um.is_some() != p.r_max_um.is_some() {
                return Err(self.err(&at, "`r_min_um` and `r_max_um` go together"));
            }
            match &p.refractive_index {
                None => {
                    return Err(self.err(
                        &at,
                        format!("`{}` needs `refractive_index`", p.distribution),
                    ));
                }
                Some(OneOrMany::Many(v)) if v.len() != nch => {
                    return Err(self.err(
                        &at,
                        format!(
                            "refractive_index has {} entries; give one or one per channel ({nch})",
                            v.len()
                        ),
                    ));
                }
                Some(_) => {}
            }
        }
        // The amount: a number density, or one extinction at the first channel.
        let ext0 = match (&l.extinction_per_m, &l.extinction_per_km) {
            (Some(PerChannel::One(_)), None) | (None, Some(PerChannel::One(_))) => true,
            (None, None) => false,
            _ => {
                return Err(self.err(
                    &at,
                    "give one extinction (at the first channel), `extinction_per_m` or `_per_km`; Mie theory gives the others",
                ));
            }
        };
        let content = self.water_content(sec, l)?;
        let amounts = [l.number_density_per_cm3.is_some(), ext0, content.is_some()];
        if amounts.iter().filter(|a| **a).count() != 1 {
            return Err(self.err(
                &at,
                "give the amount as `number_density_per_cm3`, as an extinction at the first channel, or as a water content (`lwc_g_per_m3` or `iwc_g_per_m3`): one of them",
            ));
        }
        Ok(())
    }

    /// `[surface]`, and where it lies against the lidar, the layers and the gates.
    fn surface(
        &self,
        d: &SceneDescription,
        lidar: &Lidar,
        gates: &Gates,
        nch: usize,
    ) -> Result<Option<Surface>, InputError> {
        let Some(s) = &d.surface else {
            return Ok(None);
        };
        let sec = KeyPath::table("surface");
        let altitude_m = self.range(&sec.key("altitude_m"), s.altitude_m, ALTITUDE_M)?;
        let albedo = self.per_channel(&sec.key("albedo"), &s.albedo, nch)?;
        self.range_all(&sec.key("albedo"), &albedo, FRACTION)?;
        let at = sec.key("altitude_m");
        if lidar.altitude_m < altitude_m {
            return Err(self.err(&at, "the lidar is below the surface"));
        }
        for (i, l) in d.layer.iter().enumerate() {
            if l.base_m < altitude_m {
                let name = l.name.clone().unwrap_or_else(|| format!("layer {}", i + 1));
                return Err(self.err(
                    &KeyPath::array("layer", i).key("base_m"),
                    format!("layer `{name}` reaches below the surface"),
                ));
            }
        }
        // A beam that meets the surface ends there: gates that all start beyond it can
        // receive nothing.
        let mu = lidar.axis().z;
        if mu < 0.0 {
            let surface_range_m = (lidar.altitude_m - altitude_m) / -mu;
            if gates.start_m > surface_range_m {
                return Err(self.err(
                    &KeyPath::table("gates").key("start_m"),
                    format!(
                        "every gate lies beyond the surface, which the beam meets at {surface_range_m:.1} m range"
                    ),
                ));
            }
        }
        Ok(Some(Surface { altitude_m, albedo }))
    }

    /// `[gas_absorption]`'s own values (the lines and the table's grid against the channels
    /// are checked when resolved).
    fn gas(&self, g: &GasAbsorptionDescription, has_atmosphere: bool) -> Result<(), InputError> {
        let sec = KeyPath::table("gas_absorption");
        if !has_atmosphere {
            return Err(self.err(
                &sec,
                "needs an [atmosphere] with gas profiles (`standard` or `profile_file`)",
            ));
        }
        if let Some(w) = g.wing_cm1 {
            self.range(&sec.key("wing_cm1"), w, WING_CM1)?;
        }
        if let Some(shape) = &g.line_shape {
            names::gas_line_shape(shape).map_err(|m| self.err(&sec.key("line_shape"), m))?;
        }
        for (k, v) in [
            ("table_start_cm1", g.table_start_cm1),
            ("table_end_cm1", g.table_end_cm1),
        ] {
            if let Some(v) = v {
                if g.table.is_none() {
                    return Err(self.err(&sec.key(k), "goes with `table`"));
                }
                self.range(&sec.key(k), v, WAVENUMBER_CM1)?;
            }
        }
        if let Some(v) = g.table_step_cm1 {
            if g.table.is_none() {
                return Err(self.err(&sec.key("table_step_cm1"), "goes with `table`"));
            }
            self.range(&sec.key("table_step_cm1"), v, TABLE_STEP_CM1)?;
        }
        Ok(())
    }
}
