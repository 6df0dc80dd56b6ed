//! Step 3 of a scene: what a validated description names, read and computed into the
//! [`Scene`] the stages use: profiles, phase and matrix tables, Mie optics (cached), line lists
//! and the sampling of the laser lines; and the checks that need what those give. Errors still
//! name the scene key that led to them.

use std::path::Path;
use std::sync::Arc;

use super::description::{
    AtmosphereDescription, LayerDescription, OneOrMany, ParticlesDescription, PerChannel,
    PhaseDescription, SceneDescription,
};
use super::resolver::Resolver;
use super::reuse::Reuse;
use super::source::KeyPath;
use super::validate::{Checked, ProblemSize};
use super::validator::Validator;
use super::{
    Atmosphere, Channel, Layer, Polarisation, Scene, Surface, molecular_layer_count, sample_lines,
};
use crate::atmosphere::{Co2Scaling, GasProfile, Profile, StandardAtmosphere};
use crate::input::InputError;
use crate::particles::distribution::{BulkOptions, Component, SizeDistribution};
use crate::particles::matrix::ScatteringMatrix;
use crate::particles::matrix_table::MatrixTable;
use crate::particles::phase::{HenyeyGreenstein, PhaseFunction, RayleighPhase, TabulatedPhase};
use crate::particles::table::PhaseTable;
use crate::particles::water_content::{
    Condensate, geometric_optics_extinction_per_m, lognormal_median_for_effective_radius_um,
    number_density_for_content_per_m3,
};
use crate::particles::{builtin_table, rayleigh};

impl Resolver<'_> {
    /// The scene of a description that has passed [`Validator::check`], given what it found,
    /// keeping what `reuse` holds of a previous scene.
    pub fn scene_reusing(
        &self,
        d: SceneDescription,
        c: Checked,
        reuse: Option<Reuse>,
    ) -> Result<Scene, InputError> {
        let mut reuse = reuse.unwrap_or_default();
        let Checked {
            mut lidar,
            lines,
            gates,
            mut simulation,
            surface,
            laser,
            receiver,
            retrieval,
        } = c;
        // The Mie cache: the scene's `cache_dir` (relative to the scene; `off` for none), else
        // the user's cache directory (README, "The Mie cache").
        simulation.cache_dir = match simulation.cache_dir {
            Some(p) if p.as_os_str() == "off" => None,
            Some(p) => Some(self.base_dir.join(p)),
            None => crate::particles::cache::default_cache_dir(),
        };
        // Until the channels are expanded at the end, every per-channel value is per line.
        let laser = self.laser(&laser, lines.len())?;
        // The transport runs with the first line's energy; combinations scale the others.
        lidar.pulse_energy_j = laser.pulse_energy_j[0];
        let atmosphere = match (&d.atmosphere, reuse.atmosphere.take()) {
            (Some(_), Some(kept)) => Some(kept),
            (Some(a), None) => {
                Some(self.atmosphere(a, &lines, reuse.depolarisation_factor.take())?)
            }
            (None, _) => None,
        };
        let mut layers = Vec::new();
        for (i, l) in d.layer.iter().enumerate() {
            if let Some(kept) = reuse.layers.get_mut(i).and_then(Option::take) {
                layers.push(kept);
                continue;
            }
            let cache_dir = simulation.cache_dir.as_deref();
            layers.push(self.layer(i, l, &lines, cache_dir, lidar.polarisation)?);
        }
        if let (Some(s), Some(a)) = (&surface, &atmosphere) {
            self.surface_in_profile(s, a)?;
        }
        let receiver = self.receiver(receiver.as_ref(), &lines)?;
        let (sampling, sampled) = sample_lines(&laser, &lines, receiver.as_ref());
        if let Some(c) = sampled.iter().find(|c| !(c.wavenumber_cm1 > 0.0)) {
            return Err(self.err(
                &KeyPath::table("laser").key("frequency_offset_mhz"),
                format!("channel `{}` falls at {} cm⁻¹", c.name, c.wavenumber_cm1),
            ));
        }
        let gas = match (&d.gas_absorption, &atmosphere, reuse.gas.take()) {
            (Some(g), Some(a), Some(kept)) => {
                self.gas_in_profile(g, &kept, a)?;
                Some(kept)
            }
            (Some(g), Some(a), None) => Some(self.gas(g, &sampled, a)?),
            _ => None,
        };
        Validator { src: self.src }.problem_size(
            &d,
            &ProblemSize {
                lidar: &lidar,
                gates: &gates,
                simulation: &simulation,
                channels_and_sums: (sampled.len() + sampling.combinations().len()) as u64,
                n_lines: lines.len() as u64,
                molecular_layers: atmosphere.as_ref().map(molecular_layer_count),
                n_particle_layers: layers.len(),
            },
        )?;
        let retrieval = self.retrieval(
            &d,
            retrieval.as_ref(),
            atmosphere.as_ref(),
            gas.as_ref(),
            reuse.spectroscopy.take(),
        )?;
        let warnings = super::warnings::scene_warnings(
            self.src,
            &d,
            &lines,
            &layers,
            &gates,
            receiver.as_ref(),
        );
        let mut scene = Scene {
            warnings,
            path: self.path.clone(),
            description: d.description.clone().unwrap_or_default(),
            lidar,
            lines,
            channels: sampled,
            laser,
            sampling,
            receiver,
            retrieval,
            gates,
            atmosphere,
            layers,
            surface,
            gas,
            simulation,
            spec: Arc::new(d),
            base_dir: self.base_dir.to_path_buf(),
            source: Arc::new(self.src.clone()),
        };
        scene.expand_per_channel_values();
        Ok(scene)
    }

    /// The surface inside the atmosphere's profile.
    fn surface_in_profile(&self, s: &Surface, a: &Atmosphere) -> Result<(), InputError> {
        if s.altitude_m < a.profile.altitude_m[0] || s.altitude_m >= a.top_m {
            return Err(self.err(
                &KeyPath::table("surface").key("altitude_m"),
                format!(
                    "{} m is outside the atmosphere profile ({} to {} m)",
                    s.altitude_m, a.profile.altitude_m[0], a.top_m
                ),
            ));
        }
        Ok(())
    }

    /// The molecular atmosphere: its profile, rescaled to the scene's CO2, cut at its top.
    /// `kept_depolarisation`: the factors of a previous scene with the same lines and
    /// Rayleigh keys, which need neither computing nor checking again.
    fn atmosphere(
        &self,
        a: &AtmosphereDescription,
        channels: &[Channel],
        kept_depolarisation: Option<Vec<f64>>,
    ) -> Result<Atmosphere, InputError> {
        let sec = KeyPath::table("atmosphere");
        let mut profile = if let Some(name) = &a.standard {
            name.parse::<StandardAtmosphere>()
                .map_err(|m| self.err(&sec.key("standard"), m))?
                .profile()
        } else if let Some(file) = &a.profile_file {
            self.set_profile(&sec, file, a.profile_id.as_deref())?
        } else if let Some(p) = &a.profile {
            let profile = Profile {
                name: p.name.clone().unwrap_or_else(|| "scene profile".into()),
                altitude_m: p.altitude_m.clone(),
                pressure_pa: p.pressure_pa.clone(),
                temperature_k: p.temperature_k.clone(),
                gases: p
                    .gases
                    .iter()
                    .map(|g| GasProfile {
                        name: g.name.clone(),
                        vmr: g.vmr.clone(),
                    })
                    .collect(),
            };
            profile
                .validate()
                .map_err(|e| self.err(&sec.key("profile"), e.to_string()))?;
            profile
        } else {
            let (z, n) = (
                a.altitude_m.as_deref(),
                a.air_number_density_per_m3.as_deref(),
            );
            density_profile(z.unwrap_or_default(), n.unwrap_or_default())
        };
        // Checked by validate; the default is a well-mixed dry-air mole fraction.
        let co2_scaling = match &a.co2_scaling {
            Some(s) => s
                .parse::<Co2Scaling>()
                .map_err(|m| self.err(&sec.key("co2_scaling"), m))?,
            None => Co2Scaling::default(),
        };
        if let Some(ppm) = a.co2_ppm {
            profile
                .set_co2_ppm(ppm, co2_scaling)
                .map_err(|e| self.err(&sec.key("co2_ppm"), e.to_string()))?;
        }
        let z_top = *profile.altitude_m.last().unwrap_or(&0.0);
        let top_m = match a.top_m {
            Some(t) => {
                if t > z_top || t <= profile.altitude_m[0] {
                    return Err(self.err(
                        &sec.key("top_m"),
                        format!(
                            "{t} m is outside the profile ({} to {z_top} m)",
                            profile.altitude_m[0]
                        ),
                    ));
                }
                t
            }
            None => z_top,
        };
        let layer_thickness_m = a.layer_thickness_m.unwrap_or(100.0);
        let layers = ((top_m - profile.altitude_m[0]) / layer_thickness_m).ceil() as u64;
        crate::limits::check_product(
            "the molecular grid",
            &[("layers", layers)],
            crate::limits::MAX_PATH_LAYERS,
        )
        .map_err(|m| self.err(&sec.key("layer_thickness_m"), m))?;
        let rayleigh_on = a.rayleigh.unwrap_or(true);
        // Bucholtz's depolarisation and cross-section are needed only with Rayleigh scattering
        // on; a channel outside their range is an error then, and only then.
        let depolarisation_factor = match kept_depolarisation {
            Some(kept) => kept,
            None => self.depolarisation(a, &sec, channels, rayleigh_on)?,
        };
        Ok(Atmosphere {
            profile,
            layer_thickness_m,
            top_m,
            rayleigh: rayleigh_on,
            depolarisation_factor,
            co2_ppm: a.co2_ppm,
            co2_scaling,
        })
    }

    /// The molecular depolarisation factor of each channel: given, Bucholtz's with Rayleigh
    /// scattering on (each channel then inside his range), none without.
    fn depolarisation(
        &self,
        a: &AtmosphereDescription,
        sec: &KeyPath,
        channels: &[Channel],
        rayleigh_on: bool,
    ) -> Result<Vec<f64>, InputError> {
        let depolarisation_factor = match &a.depolarization_factor {
            Some(v) => self.per_channel(&sec.key("depolarization_factor"), v, channels.len())?,
            None if rayleigh_on => channels
                .iter()
                .map(|c| rayleigh::depolarisation_factor(c.wavelength_nm()))
                .collect::<Result<_, _>>()
                .map_err(|e| self.err(&sec.key("rayleigh"), e.to_string()))?,
            None => vec![0.0; channels.len()],
        };
        if rayleigh_on {
            for (i, c) in channels.iter().enumerate() {
                rayleigh::cross_section_m2(c.wavelength_nm())
                    .map_err(|e| self.err(&KeyPath::array("channel", i), e.to_string()))?;
            }
        }
        Ok(depolarisation_factor)
    }

    /// One profile of a profile-set file (lidarsim's set format, `docs/atmosphere.md`), the file
    /// relative to the scene.
    fn set_profile(
        &self,
        sec: &KeyPath,
        file: &str,
        id: Option<&str>,
    ) -> Result<Profile, InputError> {
        let at = sec.key("profile_file");
        let path = self.base_dir.join(file);
        let set = crate::atmosphere::read_profile_set(&path)
            .map_err(|e| self.err(&at, format!("profile set: {e}")))?;
        let member = match id {
            Some(id) => set.member(id).ok_or_else(|| {
                let ids: Vec<&str> = set
                    .members
                    .iter()
                    .take(10)
                    .map(|m| m.meta.id.as_str())
                    .collect();
                self.err(
                    &sec.key("profile_id"),
                    format!(
                        "no profile `{id}` in {} (ids: {}{})",
                        path.display(),
                        ids.join(", "),
                        if set.len() > 10 { ", …" } else { "" }
                    ),
                )
            })?,
            None if set.len() == 1 => &set.members[0],
            None => {
                return Err(self.err(
                    &at,
                    format!(
                        "{} holds {} profiles: say which with `profile_id`",
                        path.display(),
                        set.len()
                    ),
                ));
            }
        };
        Ok(member.profile.clone())
    }

    /// A layer: particles given by their optics or by a size distribution, and/or absorption.
    fn layer(
        &self,
        i: usize,
        l: &LayerDescription,
        channels: &[Channel],
        cache_dir: Option<&Path>,
        polarisation: Polarisation,
    ) -> Result<Layer, InputError> {
        let nch = channels.len();
        let sec = KeyPath::array("layer", i);
        let name = l.name.clone().unwrap_or_else(|| format!("layer {}", i + 1));
        if let Some(p) = &l.particles {
            return self.mie_layer(&sec, name, l, p, channels, cache_dir);
        }
        // A water content with its effective radius: one extinction for every channel, the
        // geometric-optics limit (`particles::water_content`).
        let from_content = condensate(l).map(|(w, c)| {
            PerChannel::One(geometric_optics_extinction_per_m(
                w,
                l.r_eff_um.unwrap_or(f64::NAN),
                c,
            ))
        });
        let ext = match (&l.extinction_per_m, &l.extinction_per_km, &from_content) {
            (Some(v), _, _) => Some((sec.key("extinction_per_m"), v, 1.0)),
            (None, Some(v), _) => Some((sec.key("extinction_per_km"), v, 1e-3)),
            (None, None, Some(v)) => Some((sec.key("lwc_g_per_m3"), v, 1.0)),
            (None, None, None) => None,
        };
        let (extinction_per_m, single_scattering_albedo, phase, matrix) =
            match (ext, &l.single_scattering_albedo, &l.phase) {
                (Some((at, v, scale)), Some(ssa), Some(specs)) => {
                    let e = self.per_channel(&at, v, nch)?;
                    let ssa = self.per_channel(&sec.key("single_scattering_albedo"), ssa, nch)?;
                    let phase_at = sec.key("phase");
                    let specs = Validator { src: self.src }.phase_specs(&phase_at, specs, nch)?;
                    let (phase, matrix) = self.phases(&phase_at, &specs, channels, polarisation)?;
                    let e = e.iter().map(|x| x * scale).collect();
                    (e, ssa, phase, matrix)
                }
                _ => {
                    // Nothing scatters: isotropic placeholders.
                    let p = Arc::new(PhaseFunction::Isotropic);
                    let m = Arc::new(ScatteringMatrix::NonDepolarising(p.clone()));
                    (vec![0.0; nch], vec![1.0; nch], vec![p; nch], vec![m; nch])
                }
            };
        Ok(Layer {
            name,
            base_m: l.base_m,
            top_m: l.top_m,
            extinction_per_m,
            single_scattering_albedo,
            phase,
            matrix,
            absorption_per_m: self.absorption(&sec, l, nch)?,
        })
    }

    /// The phase functions and scattering matrices of a layer's phase specs, one per channel.
    #[allow(clippy::type_complexity)]
    fn phases(
        &self,
        phase_at: &KeyPath,
        specs: &[&PhaseDescription],
        channels: &[Channel],
        polarisation: Polarisation,
    ) -> Result<(Vec<Arc<PhaseFunction>>, Vec<Arc<ScatteringMatrix>>), InputError> {
        let mut phase: Vec<Arc<PhaseFunction>> = Vec::new();
        let mut matrix: Vec<Arc<ScatteringMatrix>> = Vec::new();
        for (k, s) in specs.iter().enumerate() {
            // Identical specs share one phase function (tables are large).
            if let Some(j) = (0..k).find(|&j| specs[j] == *s) {
                phase.push(phase[j].clone());
                matrix.push(matrix[j].clone());
                continue;
            }
            let (p, m) = self.phase(phase_at, s, &channels[k])?;
            if let (Polarisation::Circular, Some(ScatteringMatrix::Tabulated(t))) =
                (polarisation, &m)
                && !t.circular
            {
                let file = match s {
                    PhaseDescription::MatrixTable { file } => file.as_str(),
                    _ => "",
                };
                return Err(self.err(
                    phase_at,
                    format!(
                        "`{file}` is a linear-only scattering-matrix table (no F44, F34): a circularly polarised lidar needs all six elements"
                    ),
                ));
            }
            let p = Arc::new(p);
            let m = m.unwrap_or_else(|| ScatteringMatrix::NonDepolarising(p.clone()));
            phase.push(p);
            matrix.push(Arc::new(m));
        }
        Ok((phase, matrix))
    }

    /// Extra (non-particle) absorption per channel of a layer, zero if not given.
    fn absorption(
        &self,
        sec: &KeyPath,
        l: &LayerDescription,
        nch: usize,
    ) -> Result<Vec<f64>, InputError> {
        match &l.absorption_per_m {
            Some(v) => self.per_channel(&sec.key("absorption_per_m"), v, nch),
            None => Ok(vec![0.0; nch]),
        }
    }

    /// A layer of particles given by a size distribution and refractive index: extinction,
    /// single-scattering albedo and phase function per channel by Mie theory (cached).
    fn mie_layer(
        &self,
        sec: &KeyPath,
        name: String,
        l: &LayerDescription,
        p: &ParticlesDescription,
        channels: &[Channel],
        cache_dir: Option<&Path>,
    ) -> Result<Layer, InputError> {
        let at = sec.key("particles");
        let mie_err = |e: String| self.err(&at, e);
        let components = if p.distribution == "opac" {
            self.opac_components(&at, p, channels)?
        } else {
            self.mie_components(&at, name.clone(), p, l.r_eff_um, channels)?
        };
        let optics = self.mie_optics(&at, channels, &components, cache_dir)?;
        // The amount: a number density, an extinction at the first channel, or a water
        // content (the number of particles of the distribution that hold it).
        let content = condensate(l);
        let number_density_per_m3 = match (l.number_density_per_cm3, &l.extinction_per_m) {
            (Some(n), _) => n * 1e6,
            (None, None) if content.is_some() => {
                let (w, c) = content.unwrap_or((f64::NAN, Condensate::Liquid));
                // Every channel's components are the same distribution (an OPAC type, which
                // holds several, is refused a water content by validation).
                number_density_for_content_per_m3(w, &components[0][0].distribution, c)
            }
            (None, Some(PerChannel::One(e))) => e / optics[0].extinction_cross_section_m2,
            _ => match &l.extinction_per_km {
                Some(PerChannel::One(e)) => e * 1e-3 / optics[0].extinction_cross_section_m2,
                // Refused by validation.
                _ => return Err(mie_err("no amount".into())),
            },
        };
        let mut phase: Vec<Arc<PhaseFunction>> = Vec::with_capacity(channels.len());
        let mut matrix: Vec<Arc<ScatteringMatrix>> = Vec::with_capacity(channels.len());
        for (k, o) in optics.iter().enumerate() {
            if let Some(j) = (0..k).find(|&j| Arc::ptr_eq(&optics[j], o)) {
                phase.push(phase[j].clone());
                matrix.push(matrix[j].clone());
            } else {
                // Both from the matrix table, whose F11 column is the Mie phase table number
                // for number: the phase function is the one that table gives.
                let (p, m) = o
                    .matrix
                    .phase_and_matrix()
                    .map_err(|e| mie_err(e.to_string()))?;
                phase.push(Arc::new(p));
                matrix.push(Arc::new(m));
            }
        }
        Ok(Layer {
            name,
            base_m: l.base_m,
            top_m: l.top_m,
            extinction_per_m: optics
                .iter()
                .map(|o| number_density_per_m3 * o.extinction_cross_section_m2)
                .collect(),
            single_scattering_albedo: optics.iter().map(|o| o.single_scattering_albedo).collect(),
            phase,
            matrix,
            absorption_per_m: self.absorption(sec, l, channels.len())?,
        })
    }

    /// Per channel, the components of an OPAC aerosol type.
    fn opac_components(
        &self,
        at: &KeyPath,
        p: &ParticlesDescription,
        channels: &[Channel],
    ) -> Result<Vec<Vec<Component>>, InputError> {
        use crate::particles::opac::OpacType;
        let name = p.aerosol_type.as_deref().unwrap_or_default();
        let t = OpacType::from_name(name).ok_or_else(|| {
            let known: Vec<&str> = OpacType::ALL.iter().map(|t| t.name()).collect();
            self.err(
                at,
                format!(
                    "unknown OPAC aerosol type `{name}` (known: {})",
                    known.join(", ")
                ),
            )
        })?;
        channels
            .iter()
            .map(|c| {
                t.components(c.wavelength_nm() * 1e-9)
                    .map_err(|e| self.err(at, e.to_string()))
            })
            .collect()
    }

    /// Per channel, the one component of a size distribution with its refractive index.
    fn mie_components(
        &self,
        at: &KeyPath,
        name: String,
        p: &ParticlesDescription,
        r_eff_um: Option<f64>,
        channels: &[Channel],
    ) -> Result<Vec<Vec<Component>>, InputError> {
        let mie_err = |e: String| self.err(at, e);
        // Validation has checked that the distribution's parameters are given.
        let given = |v: Option<f64>| v.unwrap_or(f64::NAN);
        let mut dist = match p.distribution.as_str() {
            "lognormal" => {
                // The median radius, or the one that gives the layer's effective radius.
                let median = match (p.median_radius_um, r_eff_um) {
                    (None, Some(r)) => {
                        lognormal_median_for_effective_radius_um(r, given(p.sigma_g))
                    }
                    (m, _) => given(m),
                };
                SizeDistribution::lognormal(1.0, median, given(p.sigma_g))
            }
            _ => SizeDistribution::modified_gamma(1.0, given(p.alpha), given(p.b), given(p.gamma)),
        }
        .map_err(|e| mie_err(e.to_string()))?;
        if let (Some(a), Some(b)) = (p.r_min_um, p.r_max_um) {
            dist = dist.truncated(a, b).map_err(|e| mie_err(e.to_string()))?;
        }
        let m_text: Vec<&String> = match &p.refractive_index {
            Some(OneOrMany::Many(v)) => v.iter().collect(),
            Some(OneOrMany::One(m)) => vec![m; channels.len()],
            None => Vec::new(),
        };
        m_text
            .iter()
            .map(|m| {
                let m = crate::particles::mie::parse_refractive_index(m)
                    .map_err(|e| self.err(at, format!("refractive_index: {e}")))?;
                Ok(vec![Component {
                    name: name.clone(),
                    distribution: dist.clone(),
                    refractive_index: m,
                }])
            })
            .collect()
    }

    /// The Mie optics of each channel's components, from the cache or computed (and cached).
    fn mie_optics(
        &self,
        at: &KeyPath,
        channels: &[Channel],
        components: &[Vec<Component>],
        cache_dir: Option<&Path>,
    ) -> Result<Vec<Arc<crate::particles::cache::LayerOptics>>, InputError> {
        let mie_err = |e: String| self.err(at, e);
        // Mie theory is the slow part: its cost over every channel, bounded before any of it
        // is done (README, "Limits").
        let work = crate::particles::distribution::mie_work_of(
            channels
                .iter()
                .zip(components)
                .map(|(c, comps)| (comps.as_slice(), c.wavelength_nm() * 1e-9)),
            &BulkOptions::default(),
        )
        .map_err(|e| mie_err(e.to_string()))?;
        work.check().map_err(mie_err)?;
        if let Some(note) = work.warning() {
            crate::limits::warn(&mie_err(note).to_string());
        }
        let mut optics = Vec::with_capacity(channels.len());
        for (c, comps) in channels.iter().zip(components) {
            let (o, _) = crate::particles::cache::layer_optics(
                comps,
                c.wavelength_nm() * 1e-9,
                &BulkOptions::default(),
                cache_dir,
            )
            .map_err(mie_err)?;
            optics.push(o);
        }
        Ok(optics)
    }

    /// The phase function of a layer's `phase` spec at one channel, and its scattering matrix
    /// where the spec gives one (`None`: a scalar phase function, for which the caller makes a
    /// non-depolarising stand-in).
    fn phase(
        &self,
        at: &KeyPath,
        spec: &PhaseDescription,
        channel: &Channel,
    ) -> Result<(PhaseFunction, Option<ScatteringMatrix>), InputError> {
        let bad = |m: String| self.err(at, m);
        let scalar = |p: PhaseFunction| (p, None);
        Ok(match spec {
            PhaseDescription::Isotropic {} => scalar(PhaseFunction::Isotropic),
            PhaseDescription::Rayleigh {
                depolarization_factor,
            } => {
                let rho = match depolarization_factor {
                    Some(r) => *r,
                    None => rayleigh::depolarisation_factor(channel.wavelength_nm())
                        .map_err(|e| bad(e.to_string()))?,
                };
                // Molecule-like scatterers: the molecular matrix with the same ρ, whose F11 is
                // this phase function.
                (
                    PhaseFunction::Rayleigh(
                        RayleighPhase::from_depolarisation(rho).map_err(|e| bad(e.to_string()))?,
                    ),
                    Some(ScatteringMatrix::rayleigh(rho)),
                )
            }
            PhaseDescription::HenyeyGreenstein { g } => scalar(PhaseFunction::HenyeyGreenstein(
                HenyeyGreenstein::new(*g).map_err(|e| bad(e.to_string()))?,
            )),
            PhaseDescription::DoubleHenyeyGreenstein { f, g1, g2 } => {
                scalar(PhaseFunction::double_hg(*f, *g1, *g2).map_err(|e| bad(e.to_string()))?)
            }
            PhaseDescription::Table { file, builtin } => {
                let table = match (file, builtin) {
                    (Some(f), None) => {
                        let p = self.base_dir.join(f);
                        PhaseTable::read(&p).map_err(|e| {
                            let hint = crate::particles::missing_table_hint(f, &p)
                                .map(|h| format!(" ({h})"))
                                .unwrap_or_default();
                            bad(format!("phase-function table: {e}{hint}"))
                        })?
                    }
                    (None, Some(name)) => builtin_table(name).map_err(bad)?,
                    _ => {
                        return Err(bad(
                            "a table phase function needs `file` (relative to the scene) or `builtin`, not both".into(),
                        ));
                    }
                };
                scalar(PhaseFunction::Tabulated(Box::new(
                    TabulatedPhase::from_table(&table).map_err(|e| bad(e.to_string()))?,
                )))
            }
            PhaseDescription::MatrixTable { file } => {
                let p = self.base_dir.join(file);
                let table = MatrixTable::read(&p)
                    .map_err(|e| bad(format!("scattering-matrix table: {e}")))?;
                let (phase, matrix) = table
                    .phase_and_matrix()
                    .map_err(|e| bad(format!("scattering-matrix table {}: {e}", p.display())))?;
                (phase, Some(matrix))
            }
        })
    }
}

/// An air-density profile given as values (checked by validation). Only the number density
/// matters for Rayleigh scattering: carry it as p = n k T at a nominal 273.15 K.
fn density_profile(z: &[f64], n: &[f64]) -> Profile {
    let t = 273.15;
    Profile {
        name: "scene air-density profile".into(),
        altitude_m: z.to_vec(),
        pressure_pa: n
            .iter()
            .map(|v| v * crate::constants::BOLTZMANN_J_PER_K * t)
            .collect(),
        temperature_k: vec![t; z.len()],
        gases: Vec::new(),
    }
}

/// A layer's condensed-water content \[g/m³\] and what it is of (`lwc_g_per_m3` or
/// `iwc_g_per_m3`; validation allows one).
fn condensate(l: &LayerDescription) -> Option<(f64, Condensate)> {
    match (l.lwc_g_per_m3, l.iwc_g_per_m3) {
        (Some(w), _) => Some((w, Condensate::Liquid)),
        (None, Some(w)) => Some((w, Condensate::Ice)),
        (None, None) => None,
    }
}
