//! Every kind of malformed scene gives its documented error, naming the file, the line and the
//! key (README, "Scene errors"), and the shipped scenes parse.

use std::path::Path;

use lidarsim::input::InputError;
use lidarsim::scene::Scene;

use crate::util::project_root;

/// A valid scene; each case below breaks one thing in it (here and in `scene_lifecycle`). Line
/// numbers are 1-based.
pub(crate) const BASE: &str = r#"description = "test"
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

fn parse(text: &str) -> Result<Scene, InputError> {
    Scene::from_toml(Path::new("bad.toml"), text)
}

/// (what, replace this, with this, expected line, expected field, words in the message)
const CASES: &[(&str, &str, &str, usize, &str, &str)] = &[
    (
        "TOML syntax",
        "pulse_energy_j = 0.1",
        "pulse_energy_j = = 0.1",
        5,
        "pulse_energy_j",
        "",
    ),
    (
        "unknown key",
        "optical_efficiency = 0.5",
        "optical_efficiency = 0.5\npulse_energy = 1",
        9,
        "pulse_energy",
        "unknown field",
    ),
    (
        "unknown section",
        "[simulation]",
        "[simulations]",
        32,
        "simulations",
        "unknown field",
    ),
    (
        "missing key",
        "pulse_energy_j = 0.1\n",
        "",
        2,
        "lidar.pulse_energy_j",
        "missing: the lidar needs `pulse_energy_j`",
    ),
    (
        "wrong type",
        "telescope_diameter_m = 0.3",
        "telescope_diameter_m = \"0.3\"",
        7,
        "telescope_diameter_m",
        "invalid type",
    ),
    (
        "negative energy",
        "pulse_energy_j = 0.1",
        "pulse_energy_j = -0.1",
        5,
        "lidar.pulse_energy_j",
        "must lie in [1e-15, 1000]",
    ),
    (
        "zenith out of range",
        "zenith_angle_deg = 0.0",
        "zenith_angle_deg = 190.0",
        4,
        "lidar.zenith_angle_deg",
        "must lie in [0, 180]",
    ),
    (
        "both altitude keys",
        "altitude_m = 0.0\nzenith",
        "altitude_m = 0.0\naltitude_km = 0.0\nzenith",
        4,
        "lidar.altitude_km",
        "not both",
    ),
    (
        "no wavelength",
        "wavelength_nm = 1572.0\n",
        "",
        10,
        "channel",
        "needs `wavelength_nm` or `wavenumber_cm1`",
    ),
    (
        "duplicate channel",
        "name = \"off\"",
        "name = \"on\"",
        14,
        "channel.name",
        "given twice",
    ),
    (
        "duplicate FOV",
        "[0.5, 1.0]",
        "[0.5, 0.5]",
        9,
        "lidar.fov_full_angle_mrad",
        "given twice",
    ),
    (
        "per-channel list length",
        "[0.1, 0.1]",
        "[0.1, 0.1, 0.1]",
        26,
        "layer.extinction_per_km",
        "one per channel (2)",
    ),
    (
        "albedo above 1",
        "albedo = 0.2",
        "albedo = 1.2",
        31,
        "surface.albedo",
        "must lie in [0, 1]",
    ),
    (
        "gates not whole",
        "end_m = 5000.0",
        "end_m = 5005.0",
        18,
        "gates.end_m",
        "whole number",
    ),
    (
        "gates start at 0",
        "start_m = 100.0",
        "start_m = 0.0",
        17,
        "gates.start_m",
        "must lie in (0,",
    ),
    (
        "layer upside down",
        "top_m = 1500.0",
        "top_m = -5.0",
        25,
        "layer.top_m",
        "above `base_m`",
    ),
    (
        "unknown atmosphere",
        "standard = \"us_standard\"",
        "standard = \"martian\"",
        21,
        "atmosphere.standard",
        "unknown standard atmosphere",
    ),
    (
        "HG g out of range",
        "g = 0.7",
        "g = 1.0",
        28,
        "layer.phase",
        "-1 < g < 1",
    ),
    (
        "unknown phase kind",
        "kind = \"henyey_greenstein\", g = 0.7",
        "kind = \"mie\"",
        28,
        "phase",
        "unknown variant `mie`",
    ),
    (
        "missing table file",
        "kind = \"henyey_greenstein\", g = 0.7",
        "kind = \"table\", file = \"nope.txt\"",
        28,
        "layer.phase",
        "nope.txt",
    ),
    (
        "surface above lidar",
        "altitude_m = 0.0\nalbedo",
        "altitude_m = 10.0\nalbedo",
        30,
        "surface.altitude_m",
        "below the surface",
    ),
    (
        "layer without particles or absorption",
        "extinction_per_km = [0.1, 0.1]\nsingle_scattering_albedo = 0.95\nphase = { kind = \"henyey_greenstein\", g = 0.7 }\n",
        "",
        22,
        "layer",
        "needs particles",
    ),
    (
        "too few photons",
        "photons = 1000",
        "photons = 10",
        33,
        "simulation.photons",
        "at least the number of batches",
    ),
];

#[test]
fn base_scene_is_valid() {
    let s = parse(BASE).expect("base scene");
    assert_eq!(s.channels.len(), 2);
    assert!((s.channels[1].wavenumber_cm1 - 6361.0).abs() < 1e-12);
    assert_eq!(s.gates.count, 490);
}

#[test]
fn each_malformed_scene_gives_its_documented_error() {
    let mut failures = Vec::new();
    for (what, from, to, line, field, words) in CASES {
        assert!(
            BASE.contains(from),
            "{what}: `{from}` not in the base scene"
        );
        let text = BASE.replacen(from, to, 1);
        match parse(&text) {
            Ok(_) => failures.push(format!("{what}: accepted")),
            Err(e) => {
                let shown = e.to_string();
                let ok = e.path == Path::new("bad.toml")
                    && e.line == Some(*line)
                    && e.field.as_deref() == Some(*field)
                    && shown.contains(words)
                    && !shown.contains('\n')
                    && shown.starts_with(&format!("bad.toml:{line}: `{field}`"));
                if !ok {
                    failures.push(format!(
                        "{what}: got `{shown}` (line {:?}, field {:?})",
                        e.line, e.field
                    ));
                }
            }
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

#[test]
fn malformed_phase_table_names_the_table_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let table = "# wavelength_nm = 1064\n# refractive_index = none\n# distribution = none\ntheta_deg,phase_4pi\n0,1\n90,x\n180,1\n";
    std::fs::write(dir.path().join("t.txt"), table).unwrap();
    let scene = BASE.replacen(
        "kind = \"henyey_greenstein\", g = 0.7",
        "kind = \"table\", file = \"t.txt\"",
        1,
    );
    let path = dir.path().join("s.toml");
    std::fs::write(&path, &scene).unwrap();
    let e = Scene::read(&path).unwrap_err();
    let shown = e.to_string();
    assert_eq!(e.line, Some(28), "{shown}");
    assert!(
        shown.contains("t.txt:6: `phase_4pi`: `x` is not a number"),
        "{shown}"
    );
}

#[test]
fn shipped_scenes_and_the_default_scene_parse() {
    Scene::default_scene().expect("embedded default scene");
    for entry in std::fs::read_dir(project_root().join("scenes")).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "toml") {
            Scene::read(&p).unwrap_or_else(|e| panic!("{e}"));
        }
    }
}

/// A scene can name one profile of a profile-set file and rescale its CO2; Rayleigh scattering
/// then comes from that profile: the molecular column optical depth equals the Bucholtz
/// cross-section times the profile's air column (log-linear in altitude, integrated here).
#[test]
fn scene_takes_its_atmosphere_from_a_profile_set() {
    use lidarsim::atmosphere::{ProfileSet, StandardAtmosphere};
    use lidarsim::optics::OpticalAtmosphere;
    let dir = tempfile::tempdir().unwrap();
    let mut trop = StandardAtmosphere::Tropical.member();
    trop.meta.id = "trop".into();
    let mut sub = StandardAtmosphere::SubarcticWinter.member();
    sub.meta.id = "saw".into();
    let set = ProfileSet {
        name: "two".into(),
        members: vec![trop, sub],
        notes: vec![],
    };
    set.write(&dir.path().join("set.csv")).unwrap();
    let text = BASE.replacen(
        "standard = \"us_standard\"",
        "profile_file = \"set.csv\"\nprofile_id = \"saw\"\nco2_ppm = 420.0",
        1,
    );
    let path = dir.path().join("s.toml");
    std::fs::write(&path, &text).unwrap();
    let scene = Scene::read(&path).unwrap();
    let profile = &scene.atmosphere.as_ref().unwrap().profile;
    let xco2 = profile.column_average_dry_vmr("CO2").unwrap();
    assert!((xco2 / 420e-6 - 1.0).abs() < 1e-9, "{xco2}");
    // Subarctic winter, not the tropical profile: surface temperature 257.2 K.
    assert!(
        (profile.temperature_k[0] - 257.2).abs() < 0.5,
        "{}",
        profile.temperature_k[0]
    );

    // Molecular optical depth from the optics (minus the aerosol layer) against σ N_col.
    let atm = OpticalAtmosphere::build(&scene).unwrap();
    let (tau_s, _) = atm.cumulative_tau(1e9, 0);
    let tau_mol = tau_s - 0.1e-3 * 0.95 * 1500.0;
    let n = profile.air_number_density_per_m3();
    let z = &profile.altitude_m;
    let mut column = 0.0;
    for i in 0..z.len() - 1 {
        let (a, b) = (n[i], n[i + 1]);
        column += (z[i + 1] - z[i]) * (a - b) / (a / b).ln();
    }
    let sigma = lidarsim::particles::rayleigh::cross_section_m2(1572.0).unwrap();
    assert!(
        (tau_mol / (sigma * column) - 1.0).abs() < 1e-6,
        "{tau_mol} vs {}",
        sigma * column
    );

    // Asking for a profile the set does not have names the file, line and key.
    let bad = text.replace("profile_id = \"saw\"", "profile_id = \"x\"");
    std::fs::write(&path, &bad).unwrap();
    let e = Scene::read(&path).unwrap_err();
    assert_eq!(e.field.as_deref(), Some("atmosphere.profile_id"), "{e}");
    assert!(e.to_string().contains("no profile `x`"), "{e}");
}

/// A particle layer given by size distribution and refractive index gets its optics from Mie
/// theory: the Deirmendjian C.1 cloud at 1064 nm has single-scattering albedo 0.9999076 and
/// lidar ratio 19.59 sr (shared/reference/c1_summary.csv, miepython), here through the scene's
/// extinction, albedo and phase function at 180°.
#[test]
fn mie_layer_from_size_distribution_matches_reference_c1() {
    use lidarsim::optics::OpticalAtmosphere;
    let scene_text = r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.0
telescope_diameter_m = 1.0
optical_efficiency = 1.0
fov_full_angle_mrad = 1.0
[[channel]]
name = "1064"
wavelength_nm = 1064.0
[gates]
start_m = 1000.0
end_m = 1400.0
width_m = 10.0
[[layer]]
name = "C.1"
base_m = 1000.0
top_m = 1300.0
extinction_per_km = 17.23
particles = { distribution = "modified_gamma", alpha = 6.0, b = 1.5, gamma = 1.0, refractive_index = "1.3205+1.28e-6i" }
"#;
    let scene = crate::util::scene_from_toml(Path::new("c1.toml"), scene_text).unwrap();
    let layer = &scene.layers[0];
    assert!((layer.extinction_per_m[0] - 17.23e-3).abs() < 1e-12);
    assert!((layer.single_scattering_albedo[0] / 0.9999076 - 1.0).abs() < 1e-6);
    let atm = OpticalAtmosphere::build(&scene).unwrap();
    let p180 = layer.phase[0].backscatter();
    let lidar_ratio = 4.0 * std::f64::consts::PI / (layer.single_scattering_albedo[0] * p180);
    assert!(
        (lidar_ratio / 19.590 - 1.0).abs() < 5e-3,
        "lidar ratio {lidar_ratio}"
    );
    assert!((layer.phase[0].asymmetry() / 0.837121 - 1.0).abs() < 5e-3);
    assert!(atm.grey_scattering);

    // Without an amount the layer is refused, naming the key.
    let e = Scene::from_toml(
        Path::new("c1.toml"),
        &scene_text.replace("extinction_per_km = 17.23\n", ""),
    )
    .unwrap_err();
    assert_eq!(e.field.as_deref(), Some("layer.particles"), "{e}");
}

/// An OPAC aerosol type named in a scene: its extinction is the layer's total number density
/// times the mixture's mean extinction cross-section, with the single-scattering albedo and
/// asymmetry of the shipped table for the same type and wavelength (written by `lidarsim mie`
/// and checked against OPAC's own component optics in tests/particles.rs). The table was made
/// with the uniform size grid that the panel refinement replaced: the two agree to 1.7e-5 in
/// extinction, 1.1e-5 in single-scattering albedo and 6e-6 in g (both converge to 1e-3).
#[test]
fn opac_aerosol_layer_in_a_scene() {
    let text = BASE
        .replacen("extinction_per_km = [0.1, 0.1]\nsingle_scattering_albedo = 0.95\nphase = { kind = \"henyey_greenstein\", g = 0.7 }", "number_density_per_cm3 = 15300.4\nparticles = { distribution = \"opac\", aerosol_type = \"continental_average\" }", 1)
        .replacen("wavenumber_cm1 = 6361.0", "wavelength_nm = 1572.0", 1);
    let scene = crate::util::scene_from_toml(Path::new("opac.toml"), &text).unwrap();
    let table = lidarsim::particles::builtin_table("continental_average_1572nm").unwrap();
    let meta = |k: &str| table.meta(k).unwrap().parse::<f64>().unwrap();
    let l = &scene.layers[0];
    let ext = 15300.4e6 * meta("extinction_cross_section_um2") * 1e-12;
    for k in 0..2 {
        assert!(
            (l.extinction_per_m[k] / ext - 1.0).abs() < 1e-4,
            "{} vs {ext}",
            l.extinction_per_m[k]
        );
        assert!((l.single_scattering_albedo[k] - meta("single_scattering_albedo")).abs() < 5e-5);
        assert!((l.phase[k].asymmetry() - meta("asymmetry")).abs() < 1e-4);
    }
    let e = Scene::from_toml(
        Path::new("opac.toml"),
        &text.replace("continental_average", "volcanic"),
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("unknown OPAC aerosol type `volcanic`"),
        "{e}"
    );
}
