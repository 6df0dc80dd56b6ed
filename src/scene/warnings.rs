//! Warnings about a scene: values a run accepts but that are seldom meant, or that make its
//! numbers mean less than they seem to. They are data ([`Scene::warnings`]), each a line naming
//! the file, line and key (`FILE:LINE: key: …`); the command line prints them once, to stderr,
//! and a run's summary records them. They are not errors: the scene runs as given.
//!
//! * A layer of vertical optical depth above [`MAX_PLAUSIBLE_LAYER_OPTICAL_DEPTH`]: a beam
//!   crosses e^−100 of itself, nothing behind the layer can be seen, and the usual cause is a
//!   unit slip (`extinction_per_km = 17230`, optical depth 5000, where 17.23 was meant).
//! * A gate shorter than c/(2B), B the detector's electrical bandwidth: the detector's impulse
//!   response (≈ 1/(2B)) is then longer than the gate, so neighbouring gates hold the same
//!   noise; the random errors computed per gate as if independent are optimistic.
//!
//! The warning of an on-line whose signal-to-noise ratio per shot is below 1 needs the signals
//! and is a run's ([`crate::pipeline::RunOutput::warnings`]).

use super::description::{LayerDescription, SceneDescription};
use super::source::{KeyPath, Source};
use super::{Channel, Gates, Layer};
use crate::constants::SPEED_OF_LIGHT_M_PER_S;
use crate::instrument::signals::Receiver;

/// The vertical optical depth of one layer above which a warning is given.
pub const MAX_PLAUSIBLE_LAYER_OPTICAL_DEPTH: f64 = 100.0;

/// The key a layer's amount was given at, for the warning's location.
fn amount_key(l: &LayerDescription) -> &'static str {
    [
        ("extinction_per_km", l.extinction_per_km.is_some()),
        ("extinction_per_m", l.extinction_per_m.is_some()),
        ("lwc_g_per_m3", l.lwc_g_per_m3.is_some()),
        ("iwc_g_per_m3", l.iwc_g_per_m3.is_some()),
        ("number_density_per_cm3", l.number_density_per_cm3.is_some()),
        ("absorption_per_m", l.absorption_per_m.is_some()),
    ]
    .into_iter()
    .find(|(_, given)| *given)
    .map_or("top_m", |(k, _)| k)
}

/// The warnings of a resolved scene's parts (module docs), in the order of the file.
pub(super) fn scene_warnings(
    src: &Source,
    d: &SceneDescription,
    lines: &[Channel],
    layers: &[Layer],
    gates: &Gates,
    receiver: Option<&Receiver>,
) -> Vec<String> {
    let mut out = Vec::new();
    for (i, (l, ld)) in layers.iter().zip(&d.layer).enumerate() {
        let thickness_m = l.top_m - l.base_m;
        // The channel (line) where the layer is thickest.
        let worst = l
            .extinction_per_m
            .iter()
            .zip(&l.absorption_per_m)
            .map(|(e, a)| (e + a) * thickness_m)
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((k, tau)) = worst
            && tau > MAX_PLAUSIBLE_LAYER_OPTICAL_DEPTH
        {
            let at = KeyPath::array("layer", i).key(amount_key(ld));
            let line = lines.get(k).map_or("?", |c| c.name.as_str());
            out.push(
                src.err(
                    &at,
                    format!(
                        "layer `{}` has a vertical optical depth of {tau:.1} at `{line}` \
                         (extinction {:.4e} /m over {thickness_m} m), above {MAX_PLAUSIBLE_LAYER_OPTICAL_DEPTH}: \
                         the beam keeps e^-{tau:.0} of itself and nothing beyond the layer is seen; \
                         check the value and its unit",
                        l.name,
                        tau / thickness_m
                    ),
                )
                .to_string(),
            );
        }
    }
    if let (Some(r), Some(bw)) = (receiver, d.receiver.as_ref().and_then(|r| r.bandwidth_mhz)) {
        let resolved_m = SPEED_OF_LIGHT_M_PER_S / (2.0 * r.detector.bandwidth_hz);
        if gates.width_m < resolved_m {
            out.push(
                src.err(
                    &KeyPath::table("gates").key("width_m"),
                    format!(
                        "gates of {} m are shorter than c/(2B) = {resolved_m:.1} m of the detector's \
                         {bw} MHz bandwidth (`receiver.bandwidth_mhz`): the detector does not \
                         resolve them, neighbouring gates share their noise, and the random errors \
                         (computed per gate as if independent) are optimistic",
                        gates.width_m
                    ),
                )
                .to_string(),
            );
        }
    }
    out
}

/// The warning of a run whose on-line's expected signal-to-noise ratio per shot, in the
/// window of its hard-target (IPDA) measurement, is below 1 (from the analytic single-scatter
/// signals, the expected signal): a single shot pair then says little, and the averaged error
/// rests on the noise statistics of many weak shots (an on-line at a line centre, typically).
/// One line per on-line, with the worst field of view; named at `[retrieval] on`.
pub fn on_line_snr_warnings(
    scene: &super::Scene,
    retrieval: &crate::retrieval::Retrieval,
    signals: &[crate::instrument::signals::Signals],
) -> Vec<String> {
    use crate::returns::{Order, Source as ReturnsSource};
    let Some(s) = signals
        .iter()
        .find(|s| s.source == ReturnsSource::Analytic && s.order == Order::Exactly(1))
    else {
        return Vec::new();
    };
    let worst = retrieval
        .ipda_on_line_snr(s)
        .into_iter()
        .min_by(|a, b| a.1.total_cmp(&b.1));
    match worst {
        Some((fov, snr)) if snr < 1.0 => {
            let line = scene
                .lines
                .get(retrieval.config.on)
                .map_or("?", |c| c.name.as_str());
            vec![
                scene
                    .input_error(
                        "retrieval",
                        "on",
                        format!(
                            "the on-line `{line}` has an expected signal-to-noise ratio per shot of \
                             {snr:.3} at the hard target (FOV {fov} mrad), below 1: one shot pair \
                             says little and the averaged random error rests on many weak shots; \
                             an on-line further from the line centre absorbs less"
                        ),
                    )
                    .to_string(),
            ]
        }
        _ => Vec::new(),
    }
}
