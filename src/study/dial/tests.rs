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
    assert!(profiles_dataset(&[], "t", "h").is_err());
    assert!(summary_dataset(&[], "t", "h").is_err());
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
