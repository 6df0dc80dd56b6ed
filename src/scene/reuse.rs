//! Resolving an edited description against the scene it was edited from: what the edit left
//! unchanged is kept as resolved (a layer's Mie optics, the gas line lists, the retrieval's own
//! lines), what depends on the edit is resolved again. [`Scene::with_profile`] and
//! [`Scene::with_laser`] are such edits, run once per ensemble member.

use std::path::Path;

use super::description::{
    GasDescription, LaserDescription, LineShapeTableDescription, PerChannel, ProfileDescription,
    SceneDescription,
};
use super::resolver::Resolver;
use super::source::Source;
use super::{Atmosphere, GasAbsorption, Layer, Scene, validator};
use crate::atmosphere::Profile;
use crate::input::InputError;
use crate::instrument::laser::Laser;
use crate::instrument::line_shape::LineShape;
use crate::retrieval::AssumedSpectroscopy;
use crate::spectroscopy::isotopologues;

/// The resolved parts of a previous scene that an edited description may keep, per line (as
/// resolve builds them before the lines are sampled into channels).
#[derive(Default)]
pub(super) struct Reuse {
    /// Layer `i` as resolved, if its description (and the lines, polarisation and cache) are
    /// unchanged.
    pub layers: Vec<Option<Layer>>,
    /// The atmosphere, if `[atmosphere]` and the lines are unchanged.
    pub atmosphere: Option<Atmosphere>,
    /// The depolarisation factor per line, if the lines, `rayleigh` and
    /// `depolarization_factor` are unchanged (Bucholtz's values and the checks of the
    /// channels against his range need only those).
    pub depolarisation_factor: Option<Vec<f64>>,
    /// The gas absorption (its line lists), if `[gas_absorption]` and the lines are unchanged.
    pub gas: Option<GasAbsorption>,
    /// The retrieval's own spectroscopy, if `[retrieval]` is unchanged and the gas is kept.
    pub spectroscopy: Option<Option<AssumedSpectroscopy>>,
}

impl Reuse {
    /// What of `previous` the description `d`, resolved at `base_dir`, may keep.
    pub fn of(previous: &Scene, d: &SceneDescription, base_dir: &Path) -> Reuse {
        let p = &previous.spec;
        if p.channel != d.channel || previous.base_dir != base_dir {
            return Reuse::default();
        }
        let mut per_line = previous.clone();
        per_line.collapse_per_channel_values();
        let cache = |s: &SceneDescription| s.simulation.as_ref().and_then(|s| s.cache_dir.clone());
        let layers_kept = cache(p) == cache(d) && p.lidar.polarisation == d.lidar.polarisation;
        let layers = (0..d.layer.len())
            .map(|i| {
                (layers_kept && p.layer.get(i) == d.layer.get(i))
                    .then(|| per_line.layers[i].clone())
            })
            .collect();
        let gas = (p.gas_absorption == d.gas_absorption)
            .then(|| per_line.gas.clone())
            .flatten();
        let spectroscopy = (gas.is_some() && p.retrieval == d.retrieval)
            .then(|| per_line.retrieval.as_ref().map(|r| r.spectroscopy.clone()))
            .flatten();
        let same_rayleigh = match (&p.atmosphere, &d.atmosphere) {
            (Some(a), Some(b)) => {
                a.rayleigh == b.rayleigh && a.depolarization_factor == b.depolarization_factor
            }
            _ => false,
        };
        let depolarisation_factor = same_rayleigh
            .then(|| {
                per_line
                    .atmosphere
                    .as_ref()
                    .map(|a| a.depolarisation_factor.clone())
            })
            .flatten();
        Reuse {
            layers,
            depolarisation_factor,
            atmosphere: (p.atmosphere == d.atmosphere)
                .then(|| per_line.atmosphere.clone())
                .flatten(),
            gas,
            spectroscopy,
        }
    }
}

impl SceneDescription {
    /// Validate and resolve, keeping what `previous` resolved from parts of its description
    /// that this one leaves unchanged (a layer's optics, the gas line lists); the rest (the
    /// profile and all that depends on it) is resolved anew. The same scene as
    /// [`Self::resolve`], faster. Errors name the field path.
    pub fn resolve_reusing(&self, base_dir: &Path, previous: &Scene) -> Result<Scene, InputError> {
        let source = Source::code(Path::new(super::DESCRIPTION_NAME), self.to_toml()?);
        Scene::resolve_edit(self.clone(), source, base_dir, previous)
    }
}

impl Scene {
    /// Validate and resolve `d` with what `previous` may lend it.
    fn resolve_edit(
        d: SceneDescription,
        source: Source,
        base_dir: &Path,
        previous: &Scene,
    ) -> Result<Scene, InputError> {
        let checked = validator::Validator { src: &source }.check(&d)?;
        let reuse = Reuse::of(previous, &d, base_dir);
        Resolver {
            src: &source,
            base_dir,
        }
        .scene_reusing(d, checked, Some(reuse))
    }

    /// An edit of this scene's description, resolved with what this scene resolved; errors
    /// name the keys of this scene's file. The Monte Carlo settings (which the command line
    /// may have overridden) are kept.
    fn edited(&self, d: SceneDescription) -> Result<Scene, InputError> {
        let source = (*self.source).clone();
        let base_dir = self.base_dir.clone();
        let mut scene = Scene::resolve_edit(d, source, &base_dir, self)?;
        scene.simulation = self.simulation.clone();
        Ok(scene)
    }

    /// The scene with another atmospheric profile (an ensemble member, say): its description
    /// with the profile given by values ([`ProfileDescription`]), validated and resolved again,
    /// keeping the layers' optics and the line lists. The scene's `co2_ppm` is applied to it as
    /// its `co2_scaling` says (well mixed by default: the profile's own CO2 is replaced); it
    /// must cover the scene's surface and top of the atmosphere (which it keeps).
    /// Errors name the scene key that the profile does not fit.
    pub fn with_profile(&self, profile: Profile) -> Result<Scene, InputError> {
        let Some(a) = &self.atmosphere else {
            return Err(self.input_error(
                "atmosphere",
                "",
                "the scene has no atmosphere to swap a profile into",
            ));
        };
        self.profile_fits(&profile, a)?;
        let mut d = (*self.spec).clone();
        if let Some(atm) = &mut d.atmosphere {
            atm.standard = None;
            atm.profile_file = None;
            atm.profile_id = None;
            atm.altitude_m = None;
            atm.air_number_density_per_m3 = None;
            atm.top_m = Some(a.top_m);
            atm.profile = Some(ProfileDescription {
                name: Some(profile.name.clone()),
                altitude_m: profile.altitude_m,
                pressure_pa: profile.pressure_pa,
                temperature_k: profile.temperature_k,
                gases: profile
                    .gases
                    .into_iter()
                    .map(|g| GasDescription {
                        name: g.name,
                        vmr: g.vmr,
                    })
                    .collect(),
            });
        }
        self.edited(d)
    }

    /// The checks of a profile swapped in, named at the keys of this scene it does not fit.
    fn profile_fits(&self, profile: &Profile, a: &Atmosphere) -> Result<(), InputError> {
        profile
            .validate()
            .map_err(|e| self.input_error("atmosphere", "", e.to_string()))?;
        // The scene's `co2_ppm` is applied (and its failure named) when resolved.
        let (bottom, top) = (profile.altitude_m[0], profile.altitude_m[profile.len() - 1]);
        if top < a.top_m {
            return Err(self.input_error(
                "atmosphere",
                "top_m",
                format!(
                    "profile `{}` ends at {top:.0} m, below the scene's top of the atmosphere ({:.0} m)",
                    profile.name, a.top_m
                ),
            ));
        }
        if let Some(s) = &self.surface
            && s.altitude_m < bottom
        {
            return Err(self.input_error(
                "surface",
                "altitude_m",
                format!(
                    "profile `{}` starts at {bottom:.0} m, above the scene's surface ({:.0} m)",
                    profile.name, s.altitude_m
                ),
            ));
        }
        if let Some(g) = &self.gas {
            for id in g.lines.molecules() {
                let name = isotopologues::molecule_name(id).unwrap_or("?");
                if profile.gas(name).is_none() {
                    return Err(self.input_error(
                        "gas_absorption",
                        "",
                        format!(
                            "profile `{}` has no {name}, which the lines absorb",
                            profile.name
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The scene with another laser on the same lines (another frequency offset, jitter, line
    /// width or purity): its description with the laser's values (a table line shape given by
    /// values), validated and resolved again, keeping the layers, the atmosphere and the line
    /// lists. The laser must have one entry per line in its per-line vectors.
    pub fn with_laser(&self, laser: Laser) -> Result<Scene, InputError> {
        let n = self.lines.len();
        if laser.pulse_energy_j.len() != n
            || laser.frequency_offset_mhz.len() != n
            || laser.impurity_wavenumber_cm1.len() != n
        {
            return Err(self.input_error(
                "laser",
                "",
                format!("a laser for {n} lines needs {n} values per line"),
            ));
        }
        let mut d = (*self.spec).clone();
        // Only the ideal laser (a scene without `[laser]`) has no repetition rate.
        if laser.repetition_rate_hz.is_nan() && is_ideal(&laser) {
            d.laser = None;
            d.lidar.pulse_energy_j = Some(laser.pulse_energy_j[0]);
        } else {
            d.lidar.pulse_energy_j = None;
            d.laser = Some(laser_description(&laser));
        }
        self.edited(d)
    }
}

/// Whether `l` is [`Laser::ideal`] with its pulse energies.
fn is_ideal(l: &Laser) -> bool {
    let ideal = Laser::ideal(l.pulse_energy_j[0], l.pulse_energy_j.len());
    l.line_shape == ideal.line_shape
        && l.nodes == ideal.nodes
        && l.frequency_offset_mhz == ideal.frequency_offset_mhz
        && l.frequency_jitter_rms_mhz == ideal.frequency_jitter_rms_mhz
        && l.spectral_purity == ideal.spectral_purity
        && l.pulse_energy_j == ideal.pulse_energy_j
        && l.pulse_energy_jitter_fraction == ideal.pulse_energy_jitter_fraction
        && l.energy_monitor_error_fraction == ideal.energy_monitor_error_fraction
}

/// A laser as its `[laser]` section.
fn laser_description(l: &Laser) -> LaserDescription {
    let (line_shape, linewidth_fwhm_mhz, line_shape_table) = match &l.line_shape {
        LineShape::Monochromatic => ("monochromatic", None, None),
        LineShape::Gaussian { fwhm_mhz } => ("gaussian", Some(*fwhm_mhz), None),
        LineShape::Lorentzian { fwhm_mhz } => ("lorentzian", Some(*fwhm_mhz), None),
        LineShape::Table(t) => (
            "table",
            None,
            Some(LineShapeTableDescription {
                name: Some(t.source.display().to_string()),
                offset_mhz: t.offset_mhz.clone(),
                relative_intensity: t.relative_intensity.clone(),
            }),
        ),
    };
    let monochromatic = matches!(l.line_shape, LineShape::Monochromatic);
    LaserDescription {
        pulse_energy_j: PerChannel::Many(l.pulse_energy_j.clone()),
        repetition_rate_hz: l.repetition_rate_hz,
        line_shape: Some(line_shape.into()),
        linewidth_fwhm_mhz,
        line_shape_file: None,
        line_shape_table,
        line_shape_nodes: (!monochromatic).then_some(l.nodes),
        frequency_offset_mhz: Some(PerChannel::Many(l.frequency_offset_mhz.clone())),
        frequency_jitter_rms_mhz: Some(l.frequency_jitter_rms_mhz),
        spectral_purity: Some(l.spectral_purity),
        impurity_wavenumber_cm1: (l.spectral_purity < 1.0)
            .then(|| PerChannel::Many(l.impurity_wavenumber_cm1.clone())),
        pulse_energy_jitter_fraction: Some(l.pulse_energy_jitter_fraction),
        energy_monitor_error_fraction: Some(l.energy_monitor_error_fraction),
    }
}
