//! The optical atmosphere: horizontal homogeneous layers × channels, the one input of the
//! transport and of the analytic lidar equation.
//!
//! Consumes a [`Scene`] (molecular atmosphere, particle and absorber layers, surface) and
//! produces an [`OpticalAtmosphere`]: layer edges, per layer and channel the scattering and
//! absorption coefficients, the scatterers present (molecules, each particle layer) with their
//! phase functions, and cumulative vertical optical depths at the edges so that the optical depth
//! of any straight segment is O(1) per channel: τ = |T(z₂) − T(z₁)|/|μ| (docs/design.md §2).
//!
//! Every phase function comes with the scatterer's scattering matrix (`phases[i]` ↔
//! `matrices[i]`, F11 of the matrix = the phase function) for polarised transport: molecules the
//! molecular matrix with their depolarisation factor, Mie and `matrix_table` layers their
//! tables, other scalar phase functions a non-depolarising stand-in
//! ([`OpticalAtmosphere::stand_in_layers`] says where).
//!
//! Molecular scattering: σ_R(λ) · n̄, with n̄ the layer mean of the air number density, ln n
//! linear in altitude between profile levels (exact integral), and the Bucholtz (1995) cross-section.

use std::sync::Arc;

use thiserror::Error;

use crate::particles::matrix::ScatteringMatrix;
use crate::particles::phase::{PhaseFunction, RayleighPhase};
use crate::particles::rayleigh;
use crate::scene::{Atmosphere, Scene};
use crate::spectroscopy::LayerDepthMemo;

/// A problem building the optical atmosphere.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum OpticsError {
    /// Rayleigh cross-section or phase function not available at a channel.
    #[error("channel `{channel}`: {message}")]
    Channel {
        /// Channel name.
        channel: String,
        /// What went wrong.
        message: String,
    },
    /// Absorption table with the wrong shape.
    #[error("absorption optical depths: {0}")]
    Absorption(String),
    /// Line-by-line gas absorption failed.
    #[error("gas absorption: {0}")]
    Gas(#[from] crate::spectroscopy::SpectroscopyError),
}

/// One scatterer species in a layer (molecules, or one particle layer).
#[derive(Debug, Clone, PartialEq)]
pub struct Component {
    /// Scattering coefficient per channel [1/m].
    pub sigma_s_per_m: Vec<f64>,
    /// Index into [`OpticalAtmosphere::phases`] (and [`OpticalAtmosphere::matrices`]) per
    /// channel.
    pub phase: Vec<u32>,
    /// Absorption by these scatterers per channel [1/m]: a particle layer's extinction times
    /// 1 − its albedo (0 for molecules); already in the layer's total absorption.
    pub sigma_a_per_m: Vec<f64>,
    /// Molecules (Rayleigh scattering) rather than particles.
    pub molecular: bool,
}

/// Layers × channels of scattering and absorption; see the module documentation.
#[derive(Debug, Clone)]
pub struct OpticalAtmosphere {
    /// Layer edges \[m\], strictly increasing; layer l spans edges_m\[l\]..edges_m[l+1]. Below the
    /// first and above the last edge is vacuum.
    pub edges_m: Vec<f64>,
    /// Number of channels.
    pub n_channels: usize,
    /// Total scattering coefficient [1/m], index `layer * n_channels + channel`.
    pub sigma_s_per_m: Vec<f64>,
    /// Total absorption coefficient (gas and particles) [1/m], same index.
    pub sigma_a_per_m: Vec<f64>,
    /// Scatterers of each layer.
    pub components: Vec<Vec<Component>>,
    /// Distinct phase functions referenced by the components.
    pub phases: Vec<Arc<PhaseFunction>>,
    /// The scattering matrix of each entry of `phases`, same length and index (F11 of
    /// `matrices[i]` is `phases[i]`). Entries are distinct as pairs: two scatterers with the
    /// same phase function and different matrices keep separate indices.
    pub matrices: Vec<Arc<ScatteringMatrix>>,
    /// Cumulative vertical scattering optical depth from the bottom edge, `edge * n_channels + k`.
    pub cum_tau_s: Vec<f64>,
    /// Cumulative vertical absorption optical depth, same index.
    pub cum_tau_a: Vec<f64>,
    /// The line-by-line gases' part of `sigma_a_per_m` [1/m], same index (zeros without
    /// `[gas_absorption]`): what the Jacobians' `gas_amount` derivative scales.
    pub gas_sigma_a_per_m: Vec<f64>,
    /// True when every scatterer has the same coefficient and phase function in every channel:
    /// then only absorption differs between channels and the transport skips the ALIS
    /// scattering-ratio weights.
    pub grey_scattering: bool,
    /// What the gas absorption came from (for the run summary), if the scene has gases.
    pub gas_note: Option<String>,
    /// How the gas absorption was obtained, if the scene has gases.
    pub gas_source: Option<GasSource>,
}

/// How the line-by-line gas absorption of a scene was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GasSource {
    /// Computed line by line at the channel wavenumbers (no table asked for).
    Direct,
    /// A cached table was computed line by line and written.
    TableComputed,
    /// A cached table was read and interpolated: no line-by-line work.
    TableReused,
}

impl OpticalAtmosphere {
    /// Build from a scene, gas absorption included: line by line at the channels' wavenumbers or
    /// from the scene's table (`gas_layer_tau`), added through
    /// [`OpticalAtmosphere::add_absorption_tau`].
    pub fn build(scene: &Scene) -> Result<Self, OpticsError> {
        Self::build_inner(scene, None)
    }

    /// [`Self::build`], the same numbers, with the line-by-line layers and cross-sections that
    /// `memo` holds reused and those it computes added to it: the truths of one profile under
    /// several lasers share their layers, and their channels and a reference state's nodes
    /// coincide in part ([`LayerDepthMemo`]).
    pub fn build_with(scene: &Scene, memo: &mut LayerDepthMemo) -> Result<Self, OpticsError> {
        Self::build_inner(scene, Some(memo))
    }

    fn build_inner(scene: &Scene, memo: Option<&mut LayerDepthMemo>) -> Result<Self, OpticsError> {
        let nch = scene.channels.len();
        let edges = layer_edges(scene);
        let n_layers = edges.len().saturating_sub(1);
        let mut phases: Vec<Arc<PhaseFunction>> = Vec::new();
        let mut matrices: Vec<Arc<ScatteringMatrix>> = Vec::new();
        // Equal phase functions share an index only when their matrices are equal too (a
        // scalar table and a matrix table with the same F11 must stay apart).
        let mut phase_index = |p: &Arc<PhaseFunction>, m: &Arc<ScatteringMatrix>| -> u32 {
            let same = |i: usize| {
                (Arc::ptr_eq(&phases[i], p) || *phases[i] == **p)
                    && (Arc::ptr_eq(&matrices[i], m) || *matrices[i] == **m)
            };
            match (0..phases.len()).find(|&i| same(i)) {
                Some(i) => i as u32,
                None => {
                    phases.push(p.clone());
                    matrices.push(m.clone());
                    (phases.len() - 1) as u32
                }
            }
        };

        // Molecules: cross-section and phase function per channel.
        let molecules = match &scene.atmosphere {
            Some(a) if a.rayleigh => {
                let mut sigma = Vec::with_capacity(nch);
                let mut phase = Vec::with_capacity(nch);
                for (k, c) in scene.channels.iter().enumerate() {
                    let err = |e: String| OpticsError::Channel {
                        channel: c.name.clone(),
                        message: e,
                    };
                    sigma.push(
                        rayleigh::cross_section_m2(c.wavelength_nm())
                            .map_err(|e| err(e.to_string()))?,
                    );
                    let rho = a.depolarisation_factor[k];
                    let rp =
                        RayleighPhase::from_depolarisation(rho).map_err(|e| err(e.to_string()))?;
                    phase.push(phase_index(
                        &Arc::new(PhaseFunction::Rayleigh(rp)),
                        &Arc::new(ScatteringMatrix::rayleigh(rho)),
                    ));
                }
                Some((a, sigma, phase))
            }
            _ => None,
        };
        let layer_phases: Vec<Vec<u32>> = scene
            .layers
            .iter()
            .map(|l| {
                l.phase
                    .iter()
                    .zip(&l.matrix)
                    .map(|(p, m)| phase_index(p, m))
                    .collect()
            })
            .collect();

        let mut sigma_s = vec![0.0; n_layers * nch];
        let mut sigma_a = vec![0.0; n_layers * nch];
        let mut components = Vec::with_capacity(n_layers);
        for l in 0..n_layers {
            let (z0, z1) = (edges[l], edges[l + 1]);
            let mut comps = Vec::new();
            if let Some((atm, sigma_r, phase)) = &molecules
                && z0 >= atm.profile.altitude_m[0] - 1e-9
                && z1 <= atm.top_m + 1e-9
            {
                let n = mean_number_density(atm, z0, z1);
                let s: Vec<f64> = sigma_r.iter().map(|c| c * n).collect();
                if s.iter().any(|v| *v > 0.0) {
                    comps.push(Component {
                        sigma_s_per_m: s,
                        phase: phase.clone(),
                        sigma_a_per_m: vec![0.0; nch],
                        molecular: true,
                    });
                }
            }
            for (j, layer) in scene.layers.iter().enumerate() {
                if layer.base_m <= z0 + 1e-9 && layer.top_m >= z1 - 1e-9 {
                    let s: Vec<f64> = (0..nch)
                        .map(|k| layer.extinction_per_m[k] * layer.single_scattering_albedo[k])
                        .collect();
                    for k in 0..nch {
                        sigma_a[l * nch + k] += layer.extinction_per_m[k]
                            * (1.0 - layer.single_scattering_albedo[k])
                            + layer.absorption_per_m[k];
                    }
                    if s.iter().any(|v| *v > 0.0) {
                        comps.push(Component {
                            sigma_s_per_m: s,
                            phase: layer_phases[j].clone(),
                            sigma_a_per_m: (0..nch)
                                .map(|k| {
                                    layer.extinction_per_m[k]
                                        * (1.0 - layer.single_scattering_albedo[k])
                                })
                                .collect(),
                            molecular: false,
                        });
                    }
                }
            }
            for c in &comps {
                for k in 0..nch {
                    sigma_s[l * nch + k] += c.sigma_s_per_m[k];
                }
            }
            components.push(comps);
        }
        let grey_scattering = components.iter().flatten().all(|c| {
            c.sigma_s_per_m.iter().all(|s| *s == c.sigma_s_per_m[0])
                && c.phase.iter().all(|p| *p == c.phase[0])
        });
        let mut atm = OpticalAtmosphere {
            edges_m: edges,
            n_channels: nch,
            sigma_s_per_m: sigma_s,
            sigma_a_per_m: sigma_a,
            components,
            phases,
            matrices,
            cum_tau_s: Vec::new(),
            cum_tau_a: Vec::new(),
            gas_sigma_a_per_m: vec![0.0; n_layers * nch],
            grey_scattering,
            gas_note: None,
            gas_source: None,
        };
        atm.accumulate();
        if let (Some(gas), Some(a)) = (&scene.gas, &scene.atmosphere) {
            let (tau, note, source) = gas_layer_tau(scene, a, gas, &atm.edges_m, memo)?;
            // Name the source of a bad optical depth (the spectroscopy stage refuses negative
            // ones itself, naming the line; this is the last guard).
            atm.add_absorption_tau(&tau).map_err(|e| match e {
                OpticsError::Absorption(m) => OpticsError::Absorption(format!(
                    "gas absorption of {}{}: {m}",
                    gas.lines.source,
                    gas.table
                        .as_ref()
                        .map(|t| format!(" (table {})", t.path.display()))
                        .unwrap_or_default()
                )),
                other => other,
            })?;
            for l in 0..n_layers {
                let h = atm.edges_m[l + 1] - atm.edges_m[l];
                for k in 0..nch {
                    atm.gas_sigma_a_per_m[l * nch + k] = tau[l * nch + k] / h;
                }
            }
            atm.gas_note = Some(note);
            atm.gas_source = Some(source);
        }
        Ok(atm)
    }

    /// Add vertical absorption optical depths per layer and channel (`layer * n_channels + k`),
    /// e.g. gas absorption from line-by-line calculations, as layer-mean coefficients.
    pub fn add_absorption_tau(&mut self, tau: &[f64]) -> Result<(), OpticsError> {
        if tau.len() != self.sigma_a_per_m.len() {
            return Err(OpticsError::Absorption(format!(
                "{} values for {} layers × {} channels",
                tau.len(),
                self.n_layers(),
                self.n_channels
            )));
        }
        for l in 0..self.n_layers() {
            let dz = self.edges_m[l + 1] - self.edges_m[l];
            for k in 0..self.n_channels {
                let t = tau[l * self.n_channels + k];
                if !(t >= 0.0 && t.is_finite()) {
                    return Err(OpticsError::Absorption(format!(
                        "layer {l} ({}–{} m), channel {k}: optical depth τ = {t} is negative or not finite",
                        self.edges_m[l],
                        self.edges_m[l + 1]
                    )));
                }
                self.sigma_a_per_m[l * self.n_channels + k] += t / dz;
            }
        }
        self.accumulate();
        Ok(())
    }

    /// Recompute the cumulative optical depths from the layers' coefficients (after a caller
    /// changed them, e.g. a derivative's check by finite differences).
    pub fn accumulate(&mut self) {
        let nch = self.n_channels;
        let n = self.edges_m.len();
        self.cum_tau_s = vec![0.0; n * nch];
        self.cum_tau_a = vec![0.0; n * nch];
        for l in 0..n.saturating_sub(1) {
            let dz = self.edges_m[l + 1] - self.edges_m[l];
            for k in 0..nch {
                self.cum_tau_s[(l + 1) * nch + k] =
                    self.cum_tau_s[l * nch + k] + self.sigma_s_per_m[l * nch + k] * dz;
                self.cum_tau_a[(l + 1) * nch + k] =
                    self.cum_tau_a[l * nch + k] + self.sigma_a_per_m[l * nch + k] * dz;
            }
        }
    }

    /// The layers (indices into the layers of `edges_m`, increasing) where some scatterer
    /// scatters, in some channel, through a non-depolarising stand-in for its matrix (a scalar
    /// phase function such as Henyey-Greenstein or a scalar table): a polarised run is exact
    /// only where this is empty, and says so once.
    pub fn stand_in_layers(&self) -> Vec<usize> {
        (0..self.components.len())
            .filter(|&l| {
                self.components[l].iter().any(|c| {
                    c.phase.iter().zip(&c.sigma_s_per_m).any(|(i, s)| {
                        *s > 0.0
                            && self
                                .matrices
                                .get(*i as usize)
                                .is_some_and(|m| m.is_stand_in())
                    })
                })
            })
            .collect()
    }

    /// Number of layers.
    pub fn n_layers(&self) -> usize {
        self.edges_m.len().saturating_sub(1)
    }

    /// Bottom edge \[m\] (−∞ for an empty atmosphere).
    pub fn bottom_m(&self) -> f64 {
        self.edges_m.first().copied().unwrap_or(f64::NEG_INFINITY)
    }

    /// Top edge \[m\].
    pub fn top_m(&self) -> f64 {
        self.edges_m.last().copied().unwrap_or(f64::NEG_INFINITY)
    }

    /// The layer holding altitude z, clamped to the first/last layer outside the atmosphere.
    #[inline]
    pub fn layer_of(&self, z: f64) -> usize {
        // Above the top (a space lidar's photons start there) or below the bottom: no search.
        if z >= self.top_m() {
            return self.n_layers().saturating_sub(1);
        }
        let i = self.edges_m.partition_point(|e| *e <= z);
        i.saturating_sub(1).min(self.n_layers().saturating_sub(1))
    }

    /// [`Self::layer_of`] starting from a layer `hint` that is usually right or next to it (a
    /// photon moves between neighbouring layers far more often than it jumps): three
    /// comparisons instead of a search through hundreds of edges.
    #[inline]
    pub fn layer_near(&self, z: f64, hint: usize) -> usize {
        self.layer_near_or(z, hint, |z| self.layer_of(z))
    }

    /// [`Self::layer_near`] with its own `search` of the layers where the hint and its
    /// neighbours miss (the transport's bucketed index).
    #[inline]
    pub(crate) fn layer_near_or(
        &self,
        z: f64,
        hint: usize,
        search: impl FnOnce(f64) -> usize,
    ) -> usize {
        let e = &self.edges_m;
        let n = self.n_layers();
        if hint < n {
            let inside = |l: usize| (l == 0 || e[l] <= z) && (l + 1 == n || z < e[l + 1]);
            if inside(hint) {
                return hint;
            }
            if hint + 1 < n && inside(hint + 1) {
                return hint + 1;
            }
            if hint > 0 && inside(hint - 1) {
                return hint - 1;
            }
        }
        search(z)
    }

    /// Every channel's cumulative vertical optical depths at an altitude z in layer l (clamped
    /// to it), into `ts` (scattering) and `ta` (absorption): [`Self::cumulative_tau_in`] for all
    /// channels at once, one contiguous pass over the layer's rows.
    #[inline]
    pub fn cumulative_taus_in(&self, l: usize, z: f64, ts: &mut [f64], ta: &mut [f64]) {
        let nch = self.n_channels;
        let dz = z.clamp(self.edges_m[l], self.edges_m[l + 1]) - self.edges_m[l];
        let row = l * nch..(l + 1) * nch;
        let (cs, ss) = (
            &self.cum_tau_s[row.clone()],
            &self.sigma_s_per_m[row.clone()],
        );
        let (ca, sa) = (&self.cum_tau_a[row.clone()], &self.sigma_a_per_m[row]);
        for k in 0..nch.min(ts.len()).min(ta.len()) {
            ts[k] = cs[k] + dz * ss[k];
            ta[k] = ca[k] + dz * sa[k];
        }
    }

    /// Cumulative vertical optical depth (scattering, absorption) of channel k at altitude z:
    /// T(z) = cum\[l\] + (z − edge_l) σ_l, constant outside the atmosphere.
    #[inline]
    pub fn cumulative_tau(&self, z: f64, k: usize) -> (f64, f64) {
        if self.n_layers() == 0 {
            return (0.0, 0.0);
        }
        let z = z.clamp(self.bottom_m(), self.top_m());
        self.cumulative_tau_in(self.layer_of(z), z, k)
    }

    /// [`Self::cumulative_tau`] at an altitude z already known to lie in layer l (clamped to
    /// it): no search.
    #[inline]
    pub fn cumulative_tau_in(&self, l: usize, z: f64, k: usize) -> (f64, f64) {
        let nch = self.n_channels;
        let dz = z.clamp(self.edges_m[l], self.edges_m[l + 1]) - self.edges_m[l];
        (
            self.cum_tau_s[l * nch + k] + dz * self.sigma_s_per_m[l * nch + k],
            self.cum_tau_a[l * nch + k] + dz * self.sigma_a_per_m[l * nch + k],
        )
    }

    /// Extinction optical depth of channel k along a straight segment from altitude z0 with
    /// direction cosine μ over length s (plane-parallel: vertical τ/|μ|).
    pub fn segment_tau_ext(&self, z0: f64, mu: f64, s: f64, k: usize) -> f64 {
        if mu.abs() < 1e-12 {
            if self.n_layers() == 0 || z0 < self.bottom_m() || z0 > self.top_m() {
                return 0.0;
            }
            let i = self.layer_of(z0) * self.n_channels + k;
            return (self.sigma_s_per_m[i] + self.sigma_a_per_m[i]) * s;
        }
        let (s0, a0) = self.cumulative_tau(z0, k);
        let (s1, a1) = self.cumulative_tau(z0 + mu * s, k);
        ((s1 - s0) + (a1 - a0)).abs() / mu.abs()
    }
}

impl OpticalAtmosphere {
    /// Fraction of a beam of unit weight absorbed along a straight segment from altitude z0
    /// with direction cosine μ over length s, for channel k:
    /// ∫ σ_a e^{−τ_ext(s')} ds', summed exactly layer by layer.
    pub fn absorbed_fraction(&self, z0: f64, mu: f64, s: f64, k: usize) -> f64 {
        let nch = self.n_channels;
        let piece = |l: usize, ds: f64, tau_in: f64| -> (f64, f64) {
            let sa = self.sigma_a_per_m[l * nch + k];
            let se = self.sigma_s_per_m[l * nch + k] + sa;
            if se <= 0.0 {
                return (0.0, 0.0);
            }
            let dt = se * ds;
            (sa / se * (-tau_in).exp() * -(-dt).exp_m1(), dt)
        };
        if self.n_layers() == 0 || s <= 0.0 {
            return 0.0;
        }
        if mu.abs() < 1e-12 {
            if z0 < self.bottom_m() || z0 > self.top_m() {
                return 0.0;
            }
            return piece(self.layer_of(z0), s, 0.0).0;
        }
        let z1 = z0 + mu * s;
        let (lo, hi) = (
            z0.min(z1).max(self.bottom_m()),
            z0.max(z1).min(self.top_m()),
        );
        if hi <= lo {
            return 0.0;
        }
        let (mut frac, mut tau) = (0.0, 0.0);
        if mu > 0.0 {
            let mut l = self.layer_of(lo);
            let mut z = lo;
            while z < hi && l < self.n_layers() {
                let top = self.edges_m[l + 1].min(hi);
                let (f, dt) = piece(l, (top - z) / mu, tau);
                frac += f;
                tau += dt;
                z = top;
                l += 1;
            }
        } else {
            let mut l = self.layer_of(hi);
            if l > 0 && self.edges_m[l] >= hi {
                l -= 1;
            }
            let mut z = hi;
            loop {
                let bottom = self.edges_m[l].max(lo);
                let (f, dt) = piece(l, (z - bottom) / -mu, tau);
                frac += f;
                tau += dt;
                z = bottom;
                if z <= lo || l == 0 {
                    break;
                }
                l -= 1;
            }
        }
        frac
    }
}

/// Vertical gas optical depth of every optical layer at every channel, `layer * nch + k`.
///
/// Line by line on the molecular grid (Curtis-Godson layers of the profile), so that the result
/// and a cached table do not depend on particle layers, gates or geometry; an optical layer
/// inside a molecular layer gets that layer's mean absorption coefficient times its thickness.
fn gas_layer_tau(
    scene: &Scene,
    a: &Atmosphere,
    gas: &crate::scene::GasAbsorption,
    edges: &[f64],
    memo: Option<&mut LayerDepthMemo>,
) -> Result<(Vec<f64>, String, GasSource), OpticsError> {
    use crate::spectroscopy::{GasOpticalDepthTable, WavenumberGrid, layer_optical_depths_at};
    let nch = scene.channels.len();
    let nu: Vec<f64> = scene.channels.iter().map(|c| c.wavenumber_cm1).collect();
    let mol = scene.molecular_edges().unwrap_or_default();
    // τ per molecular layer per channel: [mol layer][channel].
    let (tau_mol, note, source): (Vec<Vec<f64>>, String, GasSource) = match &gas.table {
        None => {
            let t = match memo {
                Some(memo) => {
                    memo.layer_optical_depths_at(&a.profile, &gas.lines, &mol, &nu, &gas.options)?
                }
                None => layer_optical_depths_at(&a.profile, &gas.lines, &mol, &nu, &gas.options)?,
            };
            let note = format!(
                "gas absorption: {} lines of {} line by line at {} channels in {} layers",
                gas.lines.len(),
                gas.lines.source,
                nch,
                mol.len() - 1
            );
            (t, note, GasSource::Direct)
        }
        Some(spec) => {
            let reusable = if spec.path.is_file() {
                match GasOpticalDepthTable::load(&spec.path) {
                    Ok(t) => t
                        .check_matches(&a.profile, Some(&gas.lines), &mol, &t.grid, &gas.options)
                        .ok()
                        .filter(|_| {
                            let (lo, hi) = t.usable_range_cm1();
                            nu.iter().all(|v| *v >= lo && *v <= hi)
                        })
                        .map(|_| t),
                    Err(_) => None,
                }
            } else {
                None
            };
            let (table, note, source) = match reusable {
                Some(t) => {
                    let note = format!(
                        "gas absorption: table {} reused (no line-by-line work)",
                        spec.path.display()
                    );
                    (t, note, GasSource::TableReused)
                }
                None => {
                    let grid = WavenumberGrid::new(spec.start_cm1, spec.end_cm1, spec.step_cm1)?;
                    let t = GasOpticalDepthTable::compute(
                        &a.profile,
                        &gas.lines,
                        &mol,
                        &grid,
                        &gas.options,
                    )?;
                    t.save(&spec.path)?;
                    let note = format!(
                        "gas absorption: table {} computed ({} layers × {} wavenumbers) and saved",
                        spec.path.display(),
                        mol.len() - 1,
                        grid.len
                    );
                    (t, note, GasSource::TableComputed)
                }
            };
            // Interpolated columns per channel → [layer][channel].
            let per_channel: Vec<Vec<f64>> = nu
                .iter()
                .map(|v| table.layer_tau(*v))
                .collect::<Result<_, _>>()?;
            let t = (0..mol.len() - 1)
                .map(|l| per_channel.iter().map(|c| c[l]).collect())
                .collect();
            (t, note, source)
        }
    };
    let mut tau = vec![0.0; (edges.len().saturating_sub(1)) * nch];
    for l in 0..edges.len().saturating_sub(1) {
        let mid = 0.5 * (edges[l] + edges[l + 1]);
        if mid < mol[0] || mid > mol[mol.len() - 1] {
            continue;
        }
        let m = (mol.partition_point(|e| *e <= mid).saturating_sub(1)).min(mol.len() - 2);
        let scale = (edges[l + 1] - edges[l]) / (mol[m + 1] - mol[m]);
        for k in 0..nch {
            tau[l * nch + k] = tau_mol[m][k] * scale;
        }
    }
    Ok((tau, note, source))
}

/// Layer edges: the molecular grid (from the profile bottom or the surface to the top, in steps
/// of the layer thickness) merged with every particle-layer and surface boundary.
fn layer_edges(scene: &Scene) -> Vec<f64> {
    let mut edges: Vec<f64> = match &scene.atmosphere {
        Some(_) => scene.molecular_edges().unwrap_or_default(),
        None => Vec::new(),
    };
    for l in &scene.layers {
        edges.push(l.base_m);
        edges.push(l.top_m);
    }
    if let Some(s) = &scene.surface {
        edges.push(s.altitude_m);
    }
    edges.sort_by(f64::total_cmp);
    edges.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    // Nothing exists below a surface.
    if let Some(s) = &scene.surface {
        edges.retain(|e| *e >= s.altitude_m - 1e-6);
    }
    if edges.len() < 2 {
        edges.clear();
        // A surface in vacuum still needs a bottom edge: one empty layer above it.
        if let Some(s) = &scene.surface {
            edges = vec![s.altitude_m, s.altitude_m + 1.0];
        }
    }
    edges
}

/// Mean air number density over [z0, z1] with ln n linear in z between profile levels.
fn mean_number_density(atm: &Atmosphere, z0: f64, z1: f64) -> f64 {
    let z = &atm.profile.altitude_m;
    let n = atm.profile.air_number_density_per_m3();
    let mut integral = 0.0;
    for i in 0..z.len() - 1 {
        let (a, b) = (z0.max(z[i]), z1.min(z[i + 1]));
        if b <= a {
            continue;
        }
        let h = z[i + 1] - z[i];
        let k = (n[i + 1] / n[i]).ln() / h; // d ln n / dz
        let na = n[i] * (k * (a - z[i])).exp();
        let x = k * (b - a);
        // ∫ n_a e^{k t} dt over [0, b − a], with (e^x − 1)/x → 1 as x → 0.
        let f = if x.abs() < 1e-8 {
            1.0 + 0.5 * x
        } else {
            x.exp_m1() / x
        };
        integral += na * (b - a) * f;
    }
    integral / (z1 - z0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;
    use std::path::Path;

    const SCENE: &str = r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 0.1
beam_divergence_full_angle_mrad = 0.0
telescope_diameter_m = 0.2
optical_efficiency = 1.0
fov_full_angle_mrad = 1.0
[[channel]]
name = "a"
wavelength_nm = 532.0
[gates]
start_m = 100.0
end_m = 10000.0
width_m = 100.0
[atmosphere]
standard = "us_standard"
layer_thickness_m = 250.0
[[layer]]
base_m = 1000.0
top_m = 1300.0
extinction_per_km = 2.0
single_scattering_albedo = 0.9
phase = { kind = "henyey_greenstein", g = 0.7 }
"#;

    #[test]
    fn rayleigh_column_optical_depth_matches_bucholtz() {
        // Bucholtz (1995) / shared/data/rayleigh: vertical Rayleigh optical depth of the US
        // standard column at 532 nm is 0.111 for p0 = 1013.25 hPa (σ N_col, no gravity height
        // correction). Our column integrates the AFGL density profile, 1013 hPa at the ground.
        let scene = Scene::from_toml(Path::new("t.toml"), SCENE).unwrap();
        let atm = OpticalAtmosphere::build(&scene).unwrap();
        let (t_s, _) = atm.cumulative_tau(1e9, 0);
        let particles = 2e-3 * 0.9 * 300.0;
        let molecular = t_s - particles;
        assert!((molecular / 0.110953 - 1.0).abs() < 0.01, "{molecular}");
        // The particle layer's edges are layer edges; absorption is ext (1 − ϖ) Δz.
        assert!(atm.edges_m.contains(&1000.0) && atm.edges_m.contains(&1300.0));
        let (_, t_a) = atm.cumulative_tau(1e9, 0);
        assert!((t_a - 2e-3 * 0.1 * 300.0).abs() < 1e-12);
        assert!(atm.grey_scattering);
    }

    #[test]
    fn mean_density_is_exact_for_an_exponential_profile() {
        let mut scene = Scene::from_toml(Path::new("t.toml"), SCENE).unwrap();
        let a = scene.atmosphere.as_mut().unwrap();
        // n = n0 exp(−z/H) sampled on levels: the layer mean must be exact.
        let h = 8000.0;
        a.profile.altitude_m = vec![0.0, 5000.0, 20000.0];
        a.profile.temperature_k = vec![250.0; 3];
        a.profile.pressure_pa = a
            .profile
            .altitude_m
            .iter()
            .map(|z| 1e5 * (-z / h).exp())
            .collect();
        let n0 = 1e5 / (crate::constants::BOLTZMANN_J_PER_K * 250.0);
        let (z0, z1) = (3000.0, 9000.0);
        let exact = n0 * h * ((-z0 / h).exp() - (-z1 / h).exp()) / (z1 - z0);
        let got = mean_number_density(a, z0, z1);
        assert!((got / exact - 1.0).abs() < 1e-12);
    }
}
