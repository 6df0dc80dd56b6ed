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
