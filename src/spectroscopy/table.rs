//! The gas optical-depth table: vertical optical depth of each layer on a wavenumber grid,
//! computed once line by line, saved, loaded and interpolated to any channel inside the grid.
//!
//! Changing range gates, geometry (sensor altitude, zenith angle: slant τ = τ/|cos θ|) or
//! channels inside the grid needs no line-by-line work: [`GasOpticalDepthTable::layer_tau`]
//! interpolates, [`GasOpticalDepthTable::layer_tau_for_edges`] merges layers, and a loaded
//! table needs no line list at all. A table carries fingerprints of what it was built from
//! (profile, line list, options) plus its edges and grid, so a cache can be reused safely
//! ([`GasOpticalDepthTable::check_matches`]).
//!
//! Interpolation in wavenumber is 6-point Lagrange (quintic). Its error at the grid step
//! recommended in `docs/spectroscopy.md` (0.0005 cm⁻¹ at 1.57 µm) is measured by the
//! integration test `spectroscopy::table_interpolation_error_in_line_cores` (≤ 1e-4
//! relative in the line cores of every layer up to 50 km).
//!
//! File format (little-endian): the 16 bytes `LIDARSIM-GASTAU1`, a u64 length, that many bytes
//! of JSON metadata (edges, grid, layers, fingerprints, sources), then layers × grid f64 values
//! of τ, layer-major.

use std::path::Path;

use super::SpectroscopyError;
use super::layers::{CgLayer, curtis_godson_layers, line_gases};
use super::lines::LineList;
use super::xsec::{LblOptions, WavenumberGrid, cross_section};
use crate::atmosphere::Profile;
use crate::digest::Fnv;
use crate::input::InputError;

/// Fingerprint of a profile (name excluded: same numbers, same table).
pub fn profile_fingerprint(profile: &Profile) -> u64 {
    let mut h = Fnv::new();
    for v in profile
        .altitude_m
        .iter()
        .chain(&profile.pressure_pa)
        .chain(&profile.temperature_k)
    {
        h.f64(*v);
    }
    for g in &profile.gases {
        h.update(g.name.as_bytes());
        h.update(&[0]);
        for v in &g.vmr {
            h.f64(*v);
        }
    }
    h.finish()
}

/// Fingerprint of the options.
pub fn options_fingerprint(opts: &LblOptions) -> u64 {
    let mut h = Fnv::new();
    // serde_json of a plain struct is deterministic (field order).
    h.update(serde_json::to_string(opts).unwrap_or_default().as_bytes());
    h.finish()
}

/// What a table was built from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TableFingerprint {
    /// [`profile_fingerprint`] of the profile.
    pub profile: u64,
    /// [`LineList::fingerprint`] of the line list.
    pub lines: u64,
    /// [`options_fingerprint`] of the options.
    pub options: u64,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct Header {
    format: String,
    profile_name: String,
    line_source: String,
    edges_m: Vec<f64>,
    grid: WavenumberGrid,
    options: LblOptions,
    layers: Vec<CgLayer>,
    fingerprint: TableFingerprint,
}

const MAGIC: &[u8; 16] = b"LIDARSIM-GASTAU1";

/// Vertical gas absorption optical depth per layer on a wavenumber grid (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct GasOpticalDepthTable {
    /// Layer edges \[m\], increasing; layer l is [edges_m\[l\], edges_m[l+1]].
    pub edges_m: Vec<f64>,
    /// The wavenumber grid.
    pub grid: WavenumberGrid,
    /// The Curtis-Godson layers (p̄, T̄, columns).
    pub layers: Vec<CgLayer>,
    /// Options of the line-by-line computation.
    pub options: LblOptions,
    /// Fingerprints of the inputs.
    pub fingerprint: TableFingerprint,
    /// Name of the profile.
    pub profile_name: String,
    /// Source of the line list.
    pub line_source: String,
    /// τ, layer-major: tau[l * grid.len + i].
    tau: Vec<f64>,
}

impl GasOpticalDepthTable {
    /// Line-by-line optical depths of the layers between `edges_m` on `grid` (the expensive
    /// step: one multigrid cross-section per layer and molecule).
    pub fn compute(
        profile: &Profile,
        lines: &LineList,
        edges_m: &[f64],
        grid: &WavenumberGrid,
        opts: &LblOptions,
    ) -> Result<Self, SpectroscopyError> {
        Self::compute_reporting(profile, lines, edges_m, grid, opts, &|_, _| {})
    }

    /// [`Self::compute`], calling `progress(done, total)` after each layer (a command's
    /// progress report; the numbers do not depend on it).
    pub fn compute_reporting(
        profile: &Profile,
        lines: &LineList,
        edges_m: &[f64],
        grid: &WavenumberGrid,
        opts: &LblOptions,
        progress: &dyn Fn(usize, usize),
    ) -> Result<Self, SpectroscopyError> {
        let layers = curtis_godson_layers(profile, edges_m)?;
        let gases = line_gases(profile, lines)?;
        let n = grid.len;
        let mut tau = vec![0.0; layers.len() * n];
        for (l, layer) in layers.iter().enumerate() {
            let row = &mut tau[l * n..(l + 1) * n];
            for &(m, gi) in &gases {
                let col = layer.gas_columns_per_cm2[gi];
                // A layer without the gas adds σ · 0: no line-by-line work.
                if !super::optical_depth::count_layer_gas(col) {
                    continue;
                }
                let sigma = cross_section(lines, m, &layer.state_for(gi), grid, opts)
                    .map_err(|e| super::optical_depth::in_layer(e, layer, profile))?;
                for (t, s) in row.iter_mut().zip(sigma) {
                    *t += s * col;
                }
            }
            progress(l + 1, layers.len());
        }
        Ok(GasOpticalDepthTable {
            edges_m: edges_m.to_vec(),
            grid: *grid,
            layers,
            options: *opts,
            fingerprint: TableFingerprint {
                profile: profile_fingerprint(profile),
                lines: lines.fingerprint(),
                options: options_fingerprint(opts),
            },
            profile_name: profile.name.clone(),
            line_source: lines.source.clone(),
            tau,
        })
    }

    /// Number of layers.
    pub fn n_layers(&self) -> usize {
        self.layers.len()
    }

    /// τ of layer `l` at grid point `i` (no interpolation).
    pub fn tau_at_grid(&self, l: usize, i: usize) -> f64 {
        self.tau[l * self.grid.len + i]
    }

    /// The usable wavenumber range [cm⁻¹] (6-point interpolation needs 3 grid points on each
    /// side; the first and last two steps are excluded, grid points themselves are exact).
    pub fn usable_range_cm1(&self) -> (f64, f64) {
        (
            self.grid.at(2),
            self.grid.at(self.grid.len.saturating_sub(3)),
        )
    }

    /// Vertical optical depth of every layer at `wavenumber_cm1` (inside the grid),
    /// interpolated with 6-point Lagrange. No line-by-line work.
    pub fn layer_tau(&self, wavenumber_cm1: f64) -> Result<Vec<f64>, SpectroscopyError> {
        let (lo, hi) = self.usable_range_cm1();
        let n = self.grid.len;
        if n < 6 || !(wavenumber_cm1 >= lo && wavenumber_cm1 <= hi) {
            return Err(SpectroscopyError::OutsideGrid {
                wavenumber_cm1,
                start_cm1: lo,
                end_cm1: hi,
            });
        }
        let u = (wavenumber_cm1 - self.grid.start_cm1) / self.grid.step_cm1;
        let mut i = u.floor() as usize;
        let mut t = u - i as f64;
        if i + 3 >= n {
            i = n - 4;
            t = u - i as f64;
        }
        if t.abs() < 1e-12 {
            return Ok((0..self.n_layers())
                .map(|l| self.tau_at_grid(l, i))
                .collect());
        }
        let mut w = [0.0; 6];
        for (s, ws) in w.iter_mut().enumerate() {
            let xs = s as f64 - 2.0;
            *ws = (0..6)
                .filter(|&o| o != s)
                .map(|o| (t - (o as f64 - 2.0)) / (xs - (o as f64 - 2.0)))
                .product();
        }
        let tau: Vec<f64> = (0..self.n_layers())
            .map(|l| {
                let row = &self.tau[l * n + i - 2..l * n + i + 4];
                row.iter().zip(&w).map(|(a, b)| a * b).sum()
            })
            .collect();
        // The table's values are ≥ 0 (computed or loaded); quintic interpolation of them can
        // overshoot below 0 next to a line the grid step does not resolve: no optical depth.
        if let Some(l) = (0..tau.len()).find(|&l| !(tau[l] >= 0.0)) {
            let row = &self.tau[l * n + i - 2..l * n + i + 4];
            return Err(SpectroscopyError::NegativeAbsorption {
                location: format!("the optical-depth table of {}", self.line_source),
                message: format!(
                    "6-point interpolation to {wavenumber_cm1} cm⁻¹ gives the layer {}–{} m the optical depth {:.4e} < 0 \
                     (its grid values there: {}): the grid step {} cm⁻¹ does not resolve the absorption at this \
                     wavenumber; compute the table with a finer step",
                    self.edges_m[l],
                    self.edges_m[l + 1],
                    tau[l],
                    row.iter()
                        .map(|v| format!("{v:.3e}"))
                        .collect::<Vec<_>>()
                        .join(", "),
                    self.grid.step_cm1
                ),
            });
        }
        Ok(tau)
    }

    /// Optical depths of coarser layers whose edges are a subset of the table's edges (each
    /// coarse layer sums the table layers it contains). No line-by-line work.
    pub fn layer_tau_for_edges(
        &self,
        edges_m: &[f64],
        wavenumber_cm1: f64,
    ) -> Result<Vec<f64>, SpectroscopyError> {
        let idx: Vec<usize> = edges_m
            .iter()
            .map(|e| {
                self.edges_m.iter().position(|x| x == e).ok_or_else(|| {
                    SpectroscopyError::TableMismatch(format!(
                        "edge {e} m is not one of the table's layer edges"
                    ))
                })
            })
            .collect::<Result<_, _>>()?;
        if idx.len() < 2 || idx.windows(2).any(|w| w[1] <= w[0]) {
            return Err(SpectroscopyError::TableMismatch(
                "edges must be at least two, increasing".into(),
            ));
        }
        let fine = self.layer_tau(wavenumber_cm1)?;
        Ok(idx
            .windows(2)
            .map(|w| fine[w[0]..w[1]].iter().sum())
            .collect())
    }

    /// Slant optical depth of the whole path between `bottom_m` and `top_m` (which must be
    /// table edges) along a direction with |cos θ| = `mu`: Σ τ_l / μ (plane-parallel).
    pub fn slant_tau(
        &self,
        bottom_m: f64,
        top_m: f64,
        mu: f64,
        wavenumber_cm1: f64,
    ) -> Result<f64, SpectroscopyError> {
        if !(mu > 0.0 && mu <= 1.0) {
            return Err(SpectroscopyError::InvalidArgument {
                name: "mu",
                value: mu,
                reason: "|cos θ| must be within (0, 1]".into(),
            });
        }
        Ok(self.layer_tau_for_edges(&[bottom_m, top_m], wavenumber_cm1)?[0] / mu)
    }

    /// Check that this table was built from `profile`, `lines` (when given), `edges_m`,
    /// `grid` and `opts`; the error says what differs.
    pub fn check_matches(
        &self,
        profile: &Profile,
        lines: Option<&LineList>,
        edges_m: &[f64],
        grid: &WavenumberGrid,
        opts: &LblOptions,
    ) -> Result<(), SpectroscopyError> {
        let mis = |s: &str| Err(SpectroscopyError::TableMismatch(s.into()));
        if self.fingerprint.profile != profile_fingerprint(profile) {
            return mis("the profile differs");
        }
        if let Some(l) = lines
            && self.fingerprint.lines != l.fingerprint()
        {
            return mis("the line list differs");
        }
        if self.fingerprint.options != options_fingerprint(opts) {
            return mis("the line-by-line options differ");
        }
        if self.edges_m != edges_m {
            return mis("the layer edges differ");
        }
        if self.grid != *grid {
            return mis("the wavenumber grid differs");
        }
        Ok(())
    }

    /// Save to `path`, whole or not at all ([`crate::output`]; format in the module docs).
    pub fn save(&self, path: &Path) -> Result<(), SpectroscopyError> {
        let bytes = self
            .to_bytes()
            .map_err(|error| crate::output::OutputError::Io {
                path: path.to_path_buf(),
                error,
            })?;
        Ok(crate::output::write_file(path, &bytes)?)
    }

    /// The table in its file format (module docs), as [`Self::save`] writes it.
    pub fn to_bytes(&self) -> std::io::Result<Vec<u8>> {
        let header = Header {
            format: "lidarsim gas optical-depth table v1".into(),
            profile_name: self.profile_name.clone(),
            line_source: self.line_source.clone(),
            edges_m: self.edges_m.clone(),
            grid: self.grid,
            options: self.options,
            layers: self.layers.clone(),
            fingerprint: self.fingerprint,
        };
        let json = serde_json::to_vec(&header).map_err(std::io::Error::other)?;
        let mut bytes = Vec::with_capacity(24 + json.len() + 8 * self.tau.len());
        bytes.extend_from_slice(MAGIC);
        bytes.extend_from_slice(&(json.len() as u64).to_le_bytes());
        bytes.extend_from_slice(&json);
        for v in &self.tau {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        Ok(bytes)
    }

    /// Load a table saved by [`Self::save`]; a damaged file is an error naming the file.
    pub fn load(path: &Path) -> Result<Self, SpectroscopyError> {
        let bytes = std::fs::read(path)
            .map_err(|e| InputError::file(path, format!("cannot read the file: {e}")))?;
        let bad = |field: &str, msg: &str| -> SpectroscopyError {
            InputError {
                path: path.to_path_buf(),
                line: None,
                field: Some(field.into()),
                message: msg.into(),
            }
            .into()
        };
        if bytes.len() < 24 || &bytes[..16] != MAGIC {
            return Err(bad("magic", "not a lidarsim gas optical-depth table"));
        }
        let len = u64::from_le_bytes(bytes[16..24].try_into().unwrap_or([0; 8])) as usize;
        let json = bytes
            .get(24..24usize.saturating_add(len))
            .ok_or_else(|| bad("header", "the file is truncated"))?;
        let h: Header = serde_json::from_slice(json)
            .map_err(|e| bad("header", &format!("damaged metadata: {e}")))?;
        let body = &bytes[24 + len..];
        let n_layers = h.edges_m.len().saturating_sub(1);
        if h.layers.len() != n_layers || h.edges_m.len() < 2 {
            return Err(bad("layers", "layer count does not match the edges"));
        }
        let expected = n_layers
            .checked_mul(h.grid.len)
            .and_then(|v| v.checked_mul(8))
            .ok_or_else(|| bad("grid", "sizes overflow"))?;
        if body.len() != expected {
            return Err(bad(
                "tau",
                &format!("{} bytes of data, {expected} expected", body.len()),
            ));
        }
        let tau: Vec<f64> = body
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
            .collect();
        if tau.iter().any(|v| !v.is_finite()) {
            return Err(bad("tau", "non-finite optical depth"));
        }
        if let Some(v) = tau.iter().find(|v| **v < 0.0) {
            return Err(bad(
                "tau",
                &format!("negative optical depth {v:e} (a table lidarsim writes has none)"),
            ));
        }
        Ok(GasOpticalDepthTable {
            edges_m: h.edges_m,
            grid: h.grid,
            layers: h.layers,
            options: h.options,
            fingerprint: h.fingerprint,
            profile_name: h.profile_name,
            line_source: h.line_source,
            tau,
        })
    }
}
