//! Set-up shared by the transport stage's unit tests.

use std::path::Path;

use super::{Plan, Setup, TallyLayout};
use crate::optics::OpticalAtmosphere;
use crate::scene::{Scene, Simulation};

/// A cloud from 500 to 700 m (10 km⁻¹, HG g = 0.8) over a ground lidar with a 1 mrad field
/// of view, gates to 10 km (a budget that cuts no ray below).
pub(super) const CLOUD: &str = r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.5
telescope_diameter_m = 1.0
optical_efficiency = 1.0
fov_full_angle_mrad = [1.0]
[[channel]]
name = "a"
wavelength_nm = 1064.0
[gates]
start_m = 100.0
end_m = 10000.0
width_m = 100.0
[[layer]]
name = "cloud"
base_m = 500.0
top_m = 700.0
extinction_per_km = 10.0
single_scattering_albedo = 1.0
phase = { kind = "henyey_greenstein", g = 0.8 }
"#;

/// `text` with each `from` replaced by its `to`; fails on a pattern it does not find (the test
/// would otherwise run another scene than the one it describes).
pub(super) fn edited(text: &str, edits: &[(&str, &str)]) -> String {
    let mut out = text.to_string();
    for (from, to) in edits {
        assert!(out.contains(from), "the scene has no {from:?}");
        out = out.replace(from, to);
    }
    out
}

/// The transport's set-up for the scene `text`, handed to `check` with its optics.
pub(super) fn with_setup(text: &str, check: impl FnOnce(&Setup<'_>, &OpticalAtmosphere)) {
    with_options(text, |_| {}, check);
}

/// As [`with_setup`], with the scene's run settings changed by `settings` first.
pub(super) fn with_options(
    text: &str,
    settings: impl FnOnce(&mut Simulation),
    check: impl FnOnce(&Setup<'_>, &OpticalAtmosphere),
) {
    let mut scene = Scene::from_toml(Path::new("scene.toml"), text).unwrap();
    settings(&mut scene.simulation);
    let atm = OpticalAtmosphere::build(&scene).unwrap();
    let plan = Plan::new(&scene, &atm, &TallyLayout::default()).unwrap();
    check(&plan.setup, &atm);
}
