use super::member::peak_pressure_hpa;
use super::*;

#[test]
fn band_model_lines_are_found_and_labelled() {
    let band = band_lines(&LineList::co2_30012_band_model());
    assert_eq!(band.len(), 60);
    let r16 = band.iter().find(|b| b.label == "R16e").unwrap();
    assert_eq!(r16.j_lower, 16);
    assert!((r16.nu_cm1 - 6359.967).abs() < 0.002);
    let pos = scan_positions(&band, 40, &[-1.0, 0.0, 2.0]);
    // P2..P40 (20) and R0..R40 (21), three offsets each.
    assert_eq!(pos.len(), 41 * 3);
    let lab = label_positions(&band, &[r16.nu_cm1 + 2.0 / GHZ_PER_CM1, 6000.0]);
    assert_eq!(lab[0].line.as_deref(), Some("R16e"));
    assert!((lab[0].offset_ghz - 2.0).abs() < 1e-9);
    assert!(lab[1].line.is_none() && lab[1].offset_ghz.is_nan());
}

#[test]
fn edges_reach_the_top_and_reject_bad_input() {
    let e = layer_edges(100.0, 1100.0, 250.0).unwrap();
    assert_eq!(e, vec![100.0, 350.0, 600.0, 850.0, 1100.0]);
    let e = layer_edges(0.0, 1001.0, 250.0).unwrap();
    assert_eq!(e.last(), Some(&1001.0));
    assert_eq!(e.len(), 5);
    assert!(layer_edges(0.0, 100.0, 250.0).is_err());
    assert!(layer_edges(0.0, 1000.0, 0.0).is_err());
}

#[test]
fn parabola_finds_the_vertex() {
    // y = −(x − 0.3)² sampled at −1, 0, 1, 2: the vertex 0.3 exactly.
    let x = [-1.0, 0.0, 1.0, 2.0];
    let y: Vec<f64> = x.iter().map(|v: &f64| -(v - 0.3).powi(2)).collect();
    assert!((peak_pressure_hpa(&x, &y) - 0.3f64.exp() / 100.0).abs() < 1e-15);
}

#[test]
fn co2_is_set_where_absent() {
    let mut p = crate::atmosphere::StandardAtmosphere::Tropical.profile();
    p.gases.retain(|g| g.name != "CO2");
    set_co2_column_average(&mut p, 400.0).unwrap();
    let x = p.column_average_dry_vmr("CO2").unwrap();
    assert!((x / 400e-6 - 1.0).abs() < 1e-9, "{x}");
    assert!(set_co2_column_average(&mut p, -1.0).is_err());
}
