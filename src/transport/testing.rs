//! Set-up shared by the transport stage's unit tests.

use std::path::Path;

use super::{Plan, Setup, TransportOptions};
use crate::optics::OpticalAtmosphere;
use crate::scene::Scene;

/// The transport's set-up for the scene `text`, its options as the scene gives them and then
/// changed by `options`, handed to `check` with its optics.
pub(super) fn with_setup(
    text: &str,
    options: impl FnOnce(&mut TransportOptions),
    check: impl FnOnce(&Setup<'_>, &OpticalAtmosphere),
) {
    let scene = Scene::from_toml(Path::new("scene.toml"), text).unwrap();
    let atm = OpticalAtmosphere::build(&scene).unwrap();
    let mut opts = TransportOptions::from_scene(&scene);
    options(&mut opts);
    let plan = Plan::new(&scene, &atm, &opts).unwrap();
    check(&plan.setup, &atm);
}
