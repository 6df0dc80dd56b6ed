use super::*;

/// profiles.csv's budget columns (and profiles.nc's variables) are the labels with `_ppm`,
/// each named once.
#[test]
fn budget_columns_are_the_labels_in_ppm() {
    for s in Source::ALL {
        assert_eq!(s.column(), format!("{}_ppm", s.label()));
        assert!(!s.long_name().is_empty());
    }
    let mut names: Vec<&str> = Source::ALL.iter().map(|s| s.long_name()).collect();
    names.sort();
    names.dedup();
    assert_eq!(names.len(), N_SOURCES);
}

/// No rows, no file: the callers skip it.
#[test]
fn empty_tables_are_refused() {
    assert!(profiles_dataset(&[]).is_err());
    assert!(summary_dataset(&[]).is_err());
}

/// The budget's steps are held to the ranges of `lidarsim dial`'s options (the humidity and
/// line-width steps as fractions), each end as the option has it; an error names the step.
#[test]
fn budget_steps_are_held_to_the_options_ranges() {
    let ok = BudgetSteps::default();
    assert!(ok.check().is_ok());
    let with = |f: fn(&mut BudgetSteps)| {
        let mut s = ok;
        f(&mut s);
        s.check()
    };
    for edge in [
        with(|s| s.temperature_k = -100.0),
        with(|s| s.temperature_k = 100.0),
        with(|s| s.humidity_fraction = -0.5),
        with(|s| s.humidity_fraction = 10.0),
        with(|s| s.surface_pressure_hpa = 100.0),
        with(|s| s.frequency_offset_mhz = -1e5),
        with(|s| s.linewidth_fraction = 10.0),
        with(|s| s.linewidth_fraction = -0.999),
    ] {
        assert!(edge.is_ok(), "{edge:?}");
    }
    for (bad, name) in [
        (with(|s| s.temperature_k = 100.1), "temperature_k"),
        (with(|s| s.temperature_k = -100.1), "temperature_k"),
        (with(|s| s.humidity_fraction = -0.51), "humidity_fraction"),
        (with(|s| s.humidity_fraction = 10.01), "humidity_fraction"),
        (
            with(|s| s.surface_pressure_hpa = -100.1),
            "surface_pressure_hpa",
        ),
        (
            with(|s| s.frequency_offset_mhz = 1.1e5),
            "frequency_offset_mhz",
        ),
        (with(|s| s.linewidth_fraction = -1.0), "linewidth_fraction"),
        (
            with(|s| s.linewidth_fraction = f64::NAN),
            "linewidth_fraction",
        ),
    ] {
        assert!(
            bad.as_ref().is_err_and(|m| m.contains(name)),
            "{name}: {bad:?}"
        );
    }
}

/// A scene with the channels of another laser appended gives, channel by channel, the optical
/// depths and analytic returns of each laser's own scene bit for bit (what the study's truths
/// share): the study scene with its on-lines offset by 1 MHz and its line 10 % wider.
#[test]
fn extra_channels_return_what_their_own_scene_returns() {
    let text = include_str!("../../../scenes/study_co2_ipda.toml");
    let base = Scene::from_toml(std::path::Path::new("study.toml"), text).unwrap();
    let mut offset = base.laser.clone();
    offset.frequency_offset_mhz[0] += 1.0;
    let wider = Laser {
        line_shape: LineShape::Gaussian { fwhm_mhz: 33.0 },
        ..base.laser.clone()
    };
    let others: Vec<Scene> = [offset, wider]
        .into_iter()
        .map(|l| base.with_laser(l).unwrap())
        .collect();
    let extra: Vec<SampledChannel> = others
        .iter()
        .flat_map(|s| s.sampling.channels.iter().cloned())
        .collect();
    let union = base.with_extra_channels(&extra).unwrap();
    let mut memo = LayerDepthMemo::new();
    let u_atm = OpticalAtmosphere::build_with(&union, &mut memo).unwrap();
    let u = lidar_eq::single_scatter(&union, &u_atm);
    let bins = u.bins_per_channel();
    let mut first = 0;
    for s in std::iter::once(&base).chain(&others) {
        let atm = OpticalAtmosphere::build(s).unwrap();
        let own = lidar_eq::single_scatter(s, &atm);
        let n = s.channels.len();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(
            bits(&own.energy_j),
            bits(&u.energy_j[first * bins..(first + n) * bins])
        );
        let nch = u_atm.n_channels;
        for l in 0..atm.n_layers() {
            let got = &u_atm.sigma_a_per_m[l * nch + first..l * nch + first + n];
            assert_eq!(bits(&atm.sigma_a_per_m[l * n..(l + 1) * n]), bits(got));
        }
        first += n;
    }
}
