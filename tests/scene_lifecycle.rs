//! The scene's three steps (`docs/design.md` §5): a description built in code is checked like a
//! file, with the field path where a file has its line; a description written as TOML and read
//! back resolves to the same scene; validation reads no file; a swapped profile is checked.

use std::path::Path;

use lidarsim::atmosphere::StandardAtmosphere;
use lidarsim::input::InputError;
use lidarsim::lidar_eq;
use lidarsim::optics::OpticalAtmosphere;
use lidarsim::scene::{
    GasDescription, OneOrMany, ParticlesDescription, PerChannel, ProfileDescription, Scene,
    SceneDescription,
};

use crate::util::project_root;

/// A small valid scene ([`crate::scene`]'s); the cases edit it.
use crate::scene::BASE;

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

/// A bad value: the file's text to replace and its replacement, the field path, and the same
/// edit of the description.
type Case = (
    &'static str,
    &'static str,
    &'static str,
    fn(&mut SceneDescription),
);

/// The instrument and retrieval sections are checked by validation alone, with the messages of
/// the file: a bad laser, receiver, retrieval or name is refused before anything is resolved.
#[test]
fn validation_alone_refuses_bad_laser_receiver_and_retrieval_values() {
    let full = BASE.replacen("pulse_energy_j = 0.1\n", "", 1)
        + "[laser]\npulse_energy_j = 0.05\nrepetition_rate_hz = 50.0\n\
           [receiver]\nquantum_efficiency = 0.8\n\
           [gas_absorption]\n\
           [retrieval]\non = \"on\"\noff = \"off\"\naveraging_shots = 100\ndial_cell_m = 100.0\n";
    let path = Path::new("full.toml");
    let d = Scene::check_toml(path, &full).unwrap();
    d.validate().unwrap();
    let cases: [Case; 6] = [
        (
            "repetition_rate_hz = 50.0",
            "repetition_rate_hz = -3.0",
            "laser.repetition_rate_hz",
            |d| d.laser.as_mut().unwrap().repetition_rate_hz = -3.0,
        ),
        (
            "repetition_rate_hz = 50.0",
            "repetition_rate_hz = 50.0\nline_shape = \"gaussian\"",
            "laser.line_shape",
            |d| d.laser.as_mut().unwrap().line_shape = Some("gaussian".into()),
        ),
        (
            "quantum_efficiency = 0.8",
            "quantum_efficiency = 1.5",
            "receiver.quantum_efficiency",
            |d| d.receiver.as_mut().unwrap().quantum_efficiency = 1.5,
        ),
        ("on = \"on\"", "on = \"online\"", "retrieval.on", |d| {
            d.retrieval.as_mut().unwrap().on = Some("online".into())
        }),
        (
            "averaging_shots = 100",
            "averaging_shots = 0",
            "retrieval.averaging_shots",
            |d| d.retrieval.as_mut().unwrap().averaging_shots = Some(0),
        ),
        (
            "standard = \"us_standard\"",
            "standard = \"us_standart\"",
            "atmosphere.standard",
            |d| d.atmosphere.as_mut().unwrap().standard = Some("us_standart".into()),
        ),
    ];
    for (from, to, field, edit) in cases {
        let text = full.replacen(from, to, 1);
        assert_ne!(text, full, "{from}");
        let file = Scene::check_toml(path, &text).unwrap_err();
        let mut code = d.clone();
        edit(&mut code);
        let e = code.validate().unwrap_err();
        same_message(&file, &e, field);
        let line = text
            .lines()
            .position(|l| l.starts_with(to.lines().last().unwrap()));
        assert_eq!(file.line, line.map(|i| i + 1), "{file}");
    }
    // The messages themselves say what is wrong.
    let mut code = d.clone();
    code.retrieval.as_mut().unwrap().on = Some("online".into());
    let e = code.validate().unwrap_err();
    assert!(
        e.message
            .contains("no channel named `online` (channels: on, off)"),
        "{e}"
    );
}

/// A profile swapped in by values is the scene of a file holding that profile inline: the same
/// analytic returns to the last bit; the description with the inline profile reads back equal.
#[test]
fn with_profile_is_the_scene_of_the_profile_written_inline() {
    let text = BASE.to_string() + "[gas_absorption]\nmolecules = [\"CO2\"]\n";
    let scene = Scene::from_toml(Path::new("p.toml"), &text).unwrap();
    let profile = StandardAtmosphere::Tropical.profile();
    let swapped = scene.with_profile(profile.clone()).unwrap();

    let mut d = SceneDescription::parse(Path::new("p.toml"), &text).unwrap();
    let a = d.atmosphere.as_mut().unwrap();
    a.standard = None;
    a.top_m = Some(scene.atmosphere.as_ref().unwrap().top_m);
    a.profile = Some(ProfileDescription {
        name: Some(profile.name.clone()),
        altitude_m: profile.altitude_m.clone(),
        pressure_pa: profile.pressure_pa.clone(),
        temperature_k: profile.temperature_k.clone(),
        gases: profile
            .gases
            .iter()
            .map(|g| GasDescription {
                name: g.name.clone(),
                vmr: g.vmr.clone(),
            })
            .collect(),
    });
    assert_eq!(swapped.as_description(), &d);
    let written = d.to_toml().unwrap();
    assert!(written.contains("[atmosphere.profile]"), "{written}");
    let back = SceneDescription::parse(Path::new("inline.toml"), &written).unwrap();
    assert_eq!(back, d);
    let from_file = Scene::from_toml(Path::new("inline.toml"), &written).unwrap();
    let returns = |s: &Scene| {
        let atm = OpticalAtmosphere::build(s).unwrap();
        lidar_eq::single_scatter(s, &atm).energy_j
    };
    let (a, b) = (returns(&swapped), returns(&from_file));
    assert!(a.iter().any(|v| *v > 0.0));
    assert_eq!(a.len(), b.len());
    assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
    // The profile is the tropical one (not the scene's US standard), its CO2 as given.
    let got = &swapped.atmosphere.as_ref().unwrap().profile;
    assert_eq!(got.temperature_k, profile.temperature_k);
    assert_ne!(returns(&scene), a);

    // An inline profile with a gas of the wrong length is refused by validation alone.
    let mut bad = d.clone();
    let p = bad.atmosphere.as_mut().unwrap().profile.as_mut().unwrap();
    p.gases[0].vmr.pop();
    let e = bad.validate().unwrap_err();
    assert_eq!(e.field.as_deref(), Some("atmosphere.profile"), "{e}");
    assert!(e.message.contains("values, `altitude_m`"), "{e}");
}

/// A laser swapped in by values is the scene of its description resolved afresh.
#[test]
fn with_laser_is_the_scene_of_the_laser_written_in_the_description() {
    let text = BASE.replacen("pulse_energy_j = 0.1\n", "", 1)
        + "[laser]\npulse_energy_j = 0.05\nrepetition_rate_hz = 50.0\nline_shape = \"gaussian\"\nlinewidth_fwhm_mhz = 20.0\n";
    let scene = Scene::from_toml(Path::new("l.toml"), &text).unwrap();
    let mut laser = scene.laser.clone();
    laser.frequency_offset_mhz[0] += 15.0;
    let swapped = scene.with_laser(laser).unwrap();
    let fresh = swapped.as_description().resolve(Path::new(".")).unwrap();
    // Debug text: the unused impurity wavenumbers are NaN, which equals nothing.
    assert_eq!(format!("{:?}", swapped.laser), format!("{:?}", fresh.laser));
    assert_eq!(swapped.channels, fresh.channels);
    assert_ne!(swapped.channels, scene.channels);
}
