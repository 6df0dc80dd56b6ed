//! Vertical gas optical depths of Curtis-Godson layers computed directly, wavenumber by
//! wavenumber (no grid): the cross-sections of [`super::xsec`] times the columns of
//! [`super::layers`], and the count of (layer, gas) pairs computed and skipped.

use super::SpectroscopyError;
use super::layers::{curtis_godson_layers, line_gases};
use super::lines::LineList;
use super::xsec::{LblOptions, cross_section_at};
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
