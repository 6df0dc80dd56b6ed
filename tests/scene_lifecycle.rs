//! The scene's three steps (issue 38, item 1): a description built in code is checked like a
//! file, with the field path where a file has its line; a description written as TOML and read
//! back resolves to the same scene; validation reads no file; a swapped profile is checked.

use std::path::Path;

use lidarsim::atmosphere::StandardAtmosphere;
use lidarsim::input::InputError;
use lidarsim::lidar_eq;
use lidarsim::optics::OpticalAtmosphere;
use lidarsim::scene::{OneOrMany, ParticlesDescription, PerChannel, Scene, SceneDescription};

use crate::util::project_root;

/// A small valid scene; the cases edit it.
const BASE: &str = r#"description = "lifecycle"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 0.1
beam_divergence_full_angle_mrad = 0.1
telescope_diameter_m = 0.3
optical_efficiency = 0.5
fov_full_angle_mrad = [0.5, 1.0]
[[channel]]
name = "on"
wavelength_nm = 1572.0
[[channel]]
name = "off"
wavenumber_cm1 = 6361.0
[gates]
start_m = 100.0
end_m = 5000.0
width_m = 10.0
[atmosphere]
standard = "us_standard"
[[layer]]
name = "aerosol"
base_m = 0.0
top_m = 1500.0
extinction_per_km = [0.1, 0.1]
single_scattering_albedo = 0.95
phase = { kind = "henyey_greenstein", g = 0.7 }
[surface]
altitude_m = 0.0
albedo = 0.2
[simulation]
photons = 1000
"#;

fn base() -> SceneDescription {
    SceneDescription::parse(Path::new("base.toml"), BASE).unwrap()
}

/// The same problem found in a file and in a description built in code: the same message,
/// the file's line and dotted key against the code's field path.
fn same_message(file: &InputError, code: &InputError, field_path: &str) {
    assert_eq!(file.message, code.message, "{file} / {code}");
    assert!(file.line.is_some(), "{file}");
    assert_eq!(code.line, None, "{code}");
    assert_eq!(code.field.as_deref(), Some(field_path), "{code}");
    assert_eq!(
        file.field.as_deref(),
        Some(field_path.replace("[0]", "").replace("[1]", "").as_str()),
        "{file}"
    );
}

#[test]
fn a_description_built_in_code_is_checked_like_the_file_naming_the_field_path() {
    // A layer whose top is below its base.
    let file = Scene::from_toml(
        Path::new("bad.toml"),
        &BASE.replacen("top_m = 1500.0", "top_m = -5.0", 1),
    )
    .unwrap_err();
    let mut d = base();
    d.layer[0].top_m = -5.0;
    let code = d.validate().unwrap_err();
    same_message(&file, &code, "layer[0].top_m");
    assert_eq!(d.resolve(Path::new(".")).unwrap_err(), code);
    assert_eq!(file.line, Some(25));

    // A per-channel list of the wrong length.
    let file = Scene::from_toml(
        Path::new("bad.toml"),
        &BASE.replacen("albedo = 0.2", "albedo = [0.2, 0.3, 0.4]", 1),
    )
    .unwrap_err();
    let mut d = base();
    d.surface.as_mut().unwrap().albedo = PerChannel::Many(vec![0.2, 0.3, 0.4]);
    same_message(&file, &d.validate().unwrap_err(), "surface.albedo");

    // A name that must exist: the second channel named like the first.
    let mut d = base();
    d.channel[1].name = "on".into();
    let file = Scene::from_toml(
        Path::new("bad.toml"),
        &BASE.replacen("name = \"off\"", "name = \"on\"", 1),
    )
    .unwrap_err();
    same_message(&file, &d.validate().unwrap_err(), "channel[1].name");

    // A Mie layer with one refractive index too many, and the gates beyond the surface.
    let mut d = base();
    let l = &mut d.layer[0];
    l.single_scattering_albedo = None;
    l.phase = None;
    l.extinction_per_km = Some(PerChannel::One(0.1));
    l.particles = Some(ParticlesDescription {
        distribution: "lognormal".into(),
        median_radius_um: Some(0.1),
        sigma_g: Some(1.8),
        alpha: None,
        b: None,
        gamma: None,
        r_min_um: None,
        r_max_um: None,
        aerosol_type: None,
        refractive_index: Some(OneOrMany::Many(vec!["1.5+0.01i".into(); 3])),
    });
    let e = d.validate().unwrap_err();
    assert_eq!(e.field.as_deref(), Some("layer[0].particles"), "{e}");
    assert!(
        e.message
            .contains("refractive_index has 3 entries; give one or one per channel (2)"),
        "{e}"
    );
    let mut d = base();
    d.lidar.altitude_m = Some(3000.0);
    d.lidar.zenith_angle_deg = 180.0;
    d.gates.start_m = 4000.0;
    d.gates.end_m = 5000.0;
    let e = d.validate().unwrap_err();
    assert_eq!(e.field.as_deref(), Some("gates.start_m"), "{e}");
    assert!(
        e.message.contains("every gate lies beyond the surface"),
        "{e}"
    );
}

/// Every shipped scene, written as TOML by serde and read back, is the same description and
/// resolves to the same scene: the analytic lidar-equation returns identical to the last bit.
#[test]
fn a_description_written_as_toml_and_read_back_resolves_to_the_same_scene() {
    let dir = project_root().join("scenes");
    for name in [
        "bissonnette_c1",
        "ground_rayleigh_aerosol_cloud",
        "spaceborne_co2_ipda",
    ] {
        let path = dir.join(format!("{name}.toml"));
        let original = Scene::read(&path).unwrap();
        let text = original.as_description().to_toml().unwrap();
        let back = SceneDescription::parse(Path::new("written.toml"), &text).unwrap();
        assert_eq!(&back, original.as_description(), "{name}");
        let resolved = back.resolve(&dir).unwrap();
        assert_eq!(
            resolved.text(),
            text,
            "{name}: a code-built scene's text is its TOML"
        );
        let returns = |s: &Scene| {
            let atm = OpticalAtmosphere::build(s).unwrap();
            lidar_eq::single_scatter(s, &atm).energy_j
        };
        let (a, b) = (returns(&original), returns(&resolved));
        assert!(!a.is_empty() && a.iter().any(|v| *v > 0.0), "{name}");
        assert!(
            a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()) && a.len() == b.len(),
            "{name}: the returns differ"
        );
    }
}

/// Validation reads no file: a line list, a phase table and a profile set that do not exist,
/// and a Mie cache directory, pass it; resolving then names the key that led to the file.
#[test]
fn validation_touches_no_file_and_resolve_names_the_key() {
    let text = BASE.replacen(
        "[simulation]\nphotons = 1000",
        "[simulation]\nphotons = 1000\ncache_dir = \"no/such/cache\"\n[gas_absorption]\nlines = \"no/such/lines.par\"",
        1,
    );
    let path = Path::new("/nonexistent-dir/lifecycle.toml");
    Scene::check_toml(path, &text).unwrap();
    let e = Scene::from_toml(path, &text).unwrap_err();
    assert_eq!(e.field.as_deref(), Some("gas_absorption.lines"), "{e}");
    assert_eq!(
        e.line,
        Some(text.lines().position(|l| l.starts_with("lines =")).unwrap() + 1)
    );

    let mut d = SceneDescription::parse(path, &text).unwrap();
    d.atmosphere.as_mut().unwrap().standard = None;
    d.atmosphere.as_mut().unwrap().profile_file = Some("no/such/set.csv".into());
    d.layer[0].phase = Some(OneOrMany::One(lidarsim::scene::PhaseDescription::Table {
        file: Some("no/such/table.txt".into()),
        builtin: None,
    }));
    d.validate().unwrap();
    let e = d.resolve(Path::new("/nonexistent-dir")).unwrap_err();
    assert_eq!(e.field.as_deref(), Some("atmosphere.profile_file"), "{e}");
    assert_eq!(e.line, None);
    assert!(!Path::new("/nonexistent-dir").exists());
}

/// A profile swapped in is checked as before: one that ends below the scene's top of the
/// atmosphere is refused at `atmosphere.top_m`, on its line.
#[test]
fn with_profile_keeps_its_checks() {
    let text = BASE.replacen(
        "standard = \"us_standard\"",
        "standard = \"us_standard\"\ntop_m = 50000.0",
        1,
    );
    let scene = Scene::from_toml(Path::new("p.toml"), &text).unwrap();
    let mut low = StandardAtmosphere::Tropical.profile();
    let keep = low.altitude_m.iter().take_while(|z| **z <= 30000.0).count();
    low.altitude_m.truncate(keep);
    low.pressure_pa.truncate(keep);
    low.temperature_k.truncate(keep);
    for g in &mut low.gases {
        g.vmr.truncate(keep);
    }
    let e = scene.with_profile(low).unwrap_err();
    assert_eq!(e.field.as_deref(), Some("atmosphere.top_m"), "{e}");
    assert_eq!(e.line, Some(22));
    assert!(
        e.message
            .contains("below the scene's top of the atmosphere"),
        "{e}"
    );
    scene
        .with_profile(StandardAtmosphere::Tropical.profile())
        .unwrap();
}
