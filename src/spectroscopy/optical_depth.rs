//! Vertical gas optical depths of Curtis-Godson layers computed directly, wavenumber by
//! wavenumber (no grid): the cross-sections of [`super::xsec`] times the columns of
//! [`super::layers`], and the count of (layer, gas) pairs computed and skipped.
//!
//! [`LayerDepthMemo`] computes the same optical depths remembering what it computed: the
//! layers of each profile, and per layer state the prepared lines and the cross-section at each
//! wavenumber. An ensemble study asks for one profile's layers many times (the truth at each
//! laser's channels, the profile's own reference state at the nominal nodes, which are some of
//! those channels, a re-levelled copy of it that has the same layers): each is computed once.

use std::collections::HashMap;
use std::sync::Arc;

use super::SpectroscopyError;
use super::layers::{CgLayer, check_profile, curtis_godson_layers, line_gases};
use super::lines::LineList;
use super::xsec::{GasState, LblOptions, PreparedLines, cross_section_at};
use crate::atmosphere::Profile;

/// Cross-sections of one gas in one layer: computed, and skipped for a zero column.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LayerGasCounts {
    /// (layer, gas) cross-sections computed line by line.
    pub computed: u64,
    /// (layer, gas) pairs skipped because the layer holds none of the gas (a zero mixing
    /// ratio): σ · 0 adds nothing, so no line is evaluated.
    pub skipped: u64,
}

thread_local! {
    static LAYER_GAS_COUNTS: std::cell::Cell<LayerGasCounts> =
        const { std::cell::Cell::new(LayerGasCounts { computed: 0, skipped: 0 }) };
}

/// The (layer, gas) cross-sections computed and skipped by [`layer_optical_depths_at`] and
/// [`super::GasOpticalDepthTable::compute`] called on this thread so far: the evidence that a
/// scene without gases, or with a gas of zero mixing ratio, does no line-by-line work for it.
pub fn layer_gas_counts() -> LayerGasCounts {
    LAYER_GAS_COUNTS.with(|c| c.get())
}

/// Count one (layer, gas) pair; true if its column is not zero, i.e. it must be computed.
pub(super) fn count_layer_gas(column_per_cm2: f64) -> bool {
    let compute = column_per_cm2 != 0.0;
    LAYER_GAS_COUNTS.with(|c| {
        let mut n = c.get();
        if compute {
            n.computed += 1;
        } else {
            n.skipped += 1;
        }
        c.set(n);
    });
    compute
}

/// A negative cross-section's message with the layer of `profile` it was found in: the optical
/// depth there would be negative.
pub(super) fn in_layer(
    e: SpectroscopyError,
    layer: &super::CgLayer,
    profile: &Profile,
) -> SpectroscopyError {
    match e {
        SpectroscopyError::NegativeAbsorption { location, message } => {
            SpectroscopyError::NegativeAbsorption {
                location,
                message: format!(
                    "{message} (in the layer {}–{} m of the profile `{}`, whose optical depth would be negative)",
                    layer.bottom_m, layer.top_m, profile.name
                ),
            }
        }
        other => other,
    }
}

/// Vertical gas optical depth of each layer between `edges_m` at each wavenumber, computed
/// directly (no grid): τ_l(ν) = Σ_gas σ_gas(ν; p̄_l, T̄_l) · U_gas,l with Curtis-Godson p̄, T̄ and
/// columns U (see [`super::layers`]). Returns `[layer][wavenumber]`.
///
/// Every molecule of `lines` must be carried by the profile (else an error); gases of the
/// profile without lines do not absorb.
pub fn layer_optical_depths_at(
    profile: &Profile,
    lines: &LineList,
    edges_m: &[f64],
    wavenumbers_cm1: &[f64],
    opts: &LblOptions,
) -> Result<Vec<Vec<f64>>, SpectroscopyError> {
    let layers = curtis_godson_layers(profile, edges_m)?;
    let gases = line_gases(profile, lines)?;
    let mut out = Vec::with_capacity(layers.len());
    for layer in &layers {
        let mut tau = vec![0.0; wavenumbers_cm1.len()];
        for (m, gi) in &gases {
            let col = layer.gas_columns_per_cm2[*gi];
            if !count_layer_gas(col) {
                continue;
            }
            let state = layer.state_for(*gi);
            let sigma = cross_section_at(lines, *m, &state, wavenumbers_cm1, opts)
                .map_err(|e| in_layer(e, layer, profile))?;
            for (t, s) in tau.iter_mut().zip(sigma) {
                *t += s * col;
            }
        }
        out.push(tau);
    }
    Ok(out)
}

/// [`layer_optical_depths_at`] remembering what it computed (module docs), for one profile's
/// work: the values are those of [`layer_optical_depths_at`], bit for bit, because a layer's
/// state fixes its layers and prepared lines, and a cross-section at one wavenumber depends on
/// that wavenumber and the prepared lines alone. Memory grows with the distinct profiles,
/// states and wavenumbers asked for: keep one memo per unit of work (an ensemble member).
#[derive(Debug, Default)]
pub struct LayerDepthMemo {
    /// Curtis-Godson layers of each (profile, edges, gases kept) asked for.
    layers: Vec<LayersOf>,
    /// The (line list, options) pairs asked for; their index keys `states`.
    lists: Vec<(LineList, LblOptions)>,
    /// Per (list, molecule, state bit for bit): the prepared lines and the cross-sections
    /// computed so far.
    states: HashMap<(usize, u8, [u64; 3]), StateMemo>,
}

/// The Curtis-Godson layers of a profile on a grid, for some of its gases.
#[derive(Debug)]
struct LayersOf {
    profile: Profile,
    edges_m: Vec<f64>,
    /// Which of the profile's gases the layers hold.
    keep: Vec<bool>,
    layers: Arc<Vec<CgLayer>>,
}

/// One layer state's prepared lines and cross-sections, by wavenumber.
#[derive(Debug)]
struct StateMemo {
    lines: PreparedLines,
    /// Wavenumbers computed \[cm⁻¹\], sorted by bits (`total_cmp`), and their cross-sections.
    nu_cm1: Vec<f64>,
    sigma: Vec<f64>,
}

impl LayerDepthMemo {
    /// An empty memo.
    pub fn new() -> Self {
        Self::default()
    }

    /// [`curtis_godson_layers`] of `profile` on `edges_m` for the gases `gases` (and water
    /// vapour, whose share of the air the integration needs), computed once per distinct
    /// (profile, edges, gases); the profile is checked whole, as [`curtis_godson_layers`] checks
    /// it. Every value is that of the layers of the whole profile, bit for bit (a gas's column
    /// depends on its own and the water vapour's mixing ratios alone), but the layers hold only
    /// those gases: look a gas up by name in [`CgLayer::gas_names`]. A profile of many gases
    /// (the AFGL sets carry seven) costs a fraction.
    pub fn layers(
        &mut self,
        profile: &Profile,
        edges_m: &[f64],
        gases: &[&str],
    ) -> Result<Arc<Vec<CgLayer>>, SpectroscopyError> {
        let keep: Vec<bool> = profile
            .gases
            .iter()
            .map(|g| g.name == "H2O" || gases.contains(&g.name.as_str()))
            .collect();
        if let Some(l) = self
            .layers
            .iter()
            .find(|l| l.keep == keep && l.edges_m == edges_m && l.profile == *profile)
        {
            return Ok(l.layers.clone());
        }
        check_profile(profile)?;
        let reduced = Profile {
            gases: profile
                .gases
                .iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(g, _)| g.clone())
                .collect(),
            ..profile.clone()
        };
        let l = Arc::new(curtis_godson_layers(&reduced, edges_m)?);
        self.layers.push(LayersOf {
            profile: profile.clone(),
            edges_m: edges_m.to_vec(),
            keep,
            layers: l.clone(),
        });
        Ok(l)
    }

    /// [`layer_optical_depths_at`], bit for bit, computing only what this memo has not.
    pub fn layer_optical_depths_at(
        &mut self,
        profile: &Profile,
        lines: &LineList,
        edges_m: &[f64],
        wavenumbers_cm1: &[f64],
        opts: &LblOptions,
    ) -> Result<Vec<Vec<f64>>, SpectroscopyError> {
        let gases = line_gases(profile, lines)?;
        let names: Vec<&str> = gases
            .iter()
            .map(|(_, gi)| profile.gases[*gi].name.as_str())
            .collect();
        let layers = self.layers(profile, edges_m, &names)?;
        // Each line gas's index in the layers.
        let gases: Vec<(u8, usize)> = gases
            .iter()
            .zip(&names)
            .filter_map(|((m, _), name)| {
                let at = layers.first()?.gas_names.iter().position(|n| n == name)?;
                Some((*m, at))
            })
            .collect();
        let list = match self.lists.iter().position(|(l, o)| o == opts && l == lines) {
            Some(i) => i,
            None => {
                self.lists.push((lines.clone(), *opts));
                self.lists.len() - 1
            }
        };
        // The wavenumbers asked for, sorted and each once, and where each request sits in them.
        let mut wanted: Vec<f64> = wavenumbers_cm1.to_vec();
        wanted.sort_by(f64::total_cmp);
        wanted.dedup_by(|a, b| a.to_bits() == b.to_bits());
        let at: Vec<usize> = wavenumbers_cm1
            .iter()
            .map(|nu| wanted.partition_point(|v| v.total_cmp(nu).is_lt()))
            .collect();
        let mut out = Vec::with_capacity(layers.len());
        for layer in layers.iter() {
            let mut tau = vec![0.0; wavenumbers_cm1.len()];
            for (m, gi) in &gases {
                let col = layer.gas_columns_per_cm2[*gi];
                if !count_layer_gas(col) {
                    continue;
                }
                let state = layer.state_for(*gi);
                let sigma = self
                    .cross_sections(list, *m, &state, &wanted)
                    .map_err(|e| in_layer(e, layer, profile))?;
                for (t, k) in tau.iter_mut().zip(&at) {
                    *t += sigma[*k] * col;
                }
            }
            out.push(tau);
        }
        Ok(out)
    }

    /// Cross-sections of molecule `m` of list `list` at `state` and at `wanted` (sorted by
    /// `total_cmp`, each once): those computed before looked up, the others computed (and
    /// checked) together and kept.
    fn cross_sections(
        &mut self,
        list: usize,
        m: u8,
        state: &GasState,
        wanted: &[f64],
    ) -> Result<Vec<f64>, SpectroscopyError> {
        let (lines, opts) = &self.lists[list];
        let key = (
            list,
            m,
            [
                state.pressure_pa.to_bits(),
                state.temperature_k.to_bits(),
                state.self_vmr.to_bits(),
            ],
        );
        let entry = match self.states.entry(key) {
            std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::hash_map::Entry::Vacant(v) => v.insert(StateMemo {
                lines: PreparedLines::new(lines, m, state, opts)?,
                nu_cm1: Vec::new(),
                sigma: Vec::new(),
            }),
        };
        // Both lists sorted: one merge finds what is known and what is missing.
        let mut known: Vec<Option<f64>> = Vec::with_capacity(wanted.len());
        let mut missing = Vec::new();
        let mut j = 0;
        for nu in wanted {
            while j < entry.nu_cm1.len() && entry.nu_cm1[j].total_cmp(nu).is_lt() {
                j += 1;
            }
            if j < entry.nu_cm1.len() && entry.nu_cm1[j].to_bits() == nu.to_bits() {
                known.push(Some(entry.sigma[j]));
            } else {
                known.push(None);
                missing.push(*nu);
            }
        }
        if missing.is_empty() {
            return Ok(known.into_iter().map(|s| s.unwrap_or(f64::NAN)).collect());
        }
        let computed = entry.lines.cross_section_at(lines, &missing, opts)?;
        let mut computed_iter = computed.iter();
        let sigma: Vec<f64> = known
            .into_iter()
            .map(|s| {
                s.or_else(|| computed_iter.next().copied())
                    .unwrap_or(f64::NAN)
            })
            .collect();
        // Keep them: the union of the two sorted lists, merged.
        let (mut nu_all, mut sigma_all) = (
            Vec::with_capacity(entry.nu_cm1.len() + missing.len()),
            Vec::with_capacity(entry.nu_cm1.len() + missing.len()),
        );
        let (mut a, mut b) = (0, 0);
        while a < entry.nu_cm1.len() || b < missing.len() {
            let take_old = b == missing.len()
                || (a < entry.nu_cm1.len() && entry.nu_cm1[a].total_cmp(&missing[b]).is_lt());
            if take_old {
                nu_all.push(entry.nu_cm1[a]);
                sigma_all.push(entry.sigma[a]);
                a += 1;
            } else {
                nu_all.push(missing[b]);
                sigma_all.push(computed[b]);
                b += 1;
            }
        }
        (entry.nu_cm1, entry.sigma) = (nu_all, sigma_all);
        Ok(sigma)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atmosphere::StandardAtmosphere;

    /// The memo gives what `layer_optical_depths_at` gives, bit for bit, whatever it was asked
    /// before: overlapping and repeated wavenumbers, another profile, another grid, another
    /// line list and a cooler copy of the profile in between.
    #[test]
    fn memo_is_the_direct_computation_bit_for_bit() {
        let warm = StandardAtmosphere::UsStandard.profile();
        let mut cool = warm.clone();
        cool.temperature_k.iter_mut().for_each(|t| *t -= 1.0);
        let tropical = StandardAtmosphere::Tropical.profile();
        let band = LineList::co2_30012_band_model().filtered(&crate::spectroscopy::LineFilter {
            min_cm1: Some(6335.0),
            max_cm1: Some(6391.0),
            ..Default::default()
        });
        let fewer = LineList {
            lines: band.lines[..band.len() / 2].to_vec(),
            ..band.clone()
        };
        let fine: Vec<f64> = (0..=40).map(|i| 500.0 * i as f64).collect();
        let coarse: Vec<f64> = (0..=10).map(|i| 2000.0 * i as f64).collect();
        let a: Vec<f64> = (0..20).map(|i| 6359.9 + 0.01 * i as f64).collect();
        let b: Vec<f64> = (0..20)
            .map(|i| 6359.95 + 0.013 * i as f64)
            .chain([6366.1, a[3]])
            .collect();
        let opts = LblOptions::default();
        let mut memo = LayerDepthMemo::new();
        for (profile, lines, edges, nu) in [
            (&warm, &band, &fine, &a),
            (&warm, &band, &fine, &b),
            (&cool, &band, &fine, &b),
            (&tropical, &band, &coarse, &a),
            (&warm, &fewer, &fine, &a),
            (&warm, &band, &coarse, &b),
            (&warm, &band, &fine, &a),
        ] {
            let got = memo
                .layer_optical_depths_at(profile, lines, edges, nu, &opts)
                .unwrap();
            let want = layer_optical_depths_at(profile, lines, edges, nu, &opts).unwrap();
            assert_eq!(got.len(), want.len());
            for (g, w) in got.iter().flatten().zip(want.iter().flatten()) {
                assert_eq!(g.to_bits(), w.to_bits(), "{g} vs {w}");
            }
            // The layers of a few gases hold the whole profile's values for them.
            let few = memo.layers(profile, edges, &["CO2"]).unwrap();
            let all = curtis_godson_layers(profile, edges).unwrap();
            assert_eq!(few.len(), all.len());
            for (f, a) in few.iter().zip(&all) {
                assert_eq!(f.gas_names, ["H2O", "CO2"]);
                assert_eq!(
                    (
                        f.bottom_m,
                        f.top_m,
                        f.pressure_pa,
                        f.temperature_k,
                        f.air_column_per_cm2
                    ),
                    (
                        a.bottom_m,
                        a.top_m,
                        a.pressure_pa,
                        a.temperature_k,
                        a.air_column_per_cm2
                    )
                );
                for (name, col) in f.gas_names.iter().zip(&f.gas_columns_per_cm2) {
                    let i = a.gas_names.iter().position(|n| n == name).unwrap();
                    assert_eq!(col.to_bits(), a.gas_columns_per_cm2[i].to_bits());
                }
            }
        }
    }
}
