//! The file read back by the `netcdf3` crate's reader (its own parser of the format, apart
//! from the writer this module drives), against the values put in. The test that a real
//! client (netCDF4-python, xarray) reads the same numbers as the CSV files is
//! `tests/netcdf.rs`.

use std::io::Cursor;
use std::time::{Duration, UNIX_EPOCH};

use netcdf3::{FileReader, NC_FILL_F64, Version};

use super::*;
use crate::retrieval::Method;
use crate::returns::{Order, Source};

fn attributes() -> RunAttributes {
    RunAttributes {
        title: "test".into(),
        history: "2026-01-01T00:00:00Z: lidarsim run".into(),
        scene_file: "scene.toml".into(),
        scene_text: "[lidar]\naltitude_m = 1 # µ\n".into(),
        seed: u64::MAX,
        photons: 1_000_000_000_000,
        batches: 100,
    }
}

fn gates() -> Gates {
    Gates {
        start_m: 100.0,
        width_m: 30.0,
        count: 3,
    }
}

/// Monte Carlo returns (orders total, 1, 2+) and analytic ones (order 1) on one grid, each
/// bin's energy a distinct number that names it.
fn returns() -> (Returns, Returns) {
    let channels = vec!["on".to_string(), "off, \"ref\"".to_string()];
    let fov = vec![0.1, 2.0];
    let range: Vec<f64> = (0..3).map(|g| gates().centre_m(g)).collect();
    let mut mc = Returns::zeros(
        Source::MonteCarlo,
        channels.clone(),
        fov.clone(),
        range.clone(),
        vec![Order::Total, Order::Exactly(1), Order::AtLeast(2)],
    );
    for (i, (e, s)) in mc.energy_j.iter_mut().zip(&mut mc.stderr_j).enumerate() {
        *e = 1e-12 * (i as f64 + 1.0) / 3.0;
        *s = 1e-15 * (i as f64 + 1.0);
    }
    mc.stderr_j[5] = f64::NAN;
    let mut analytic = Returns::zeros(
        Source::Analytic,
        channels,
        fov,
        range,
        vec![Order::Exactly(1)],
    );
    for (i, e) in analytic.energy_j.iter_mut().enumerate() {
        *e = -(i as f64) - 0.5;
    }
    (mc, analytic)
}

fn product(quantity: Quantity, retrieved: f64) -> Product {
    Product {
        method: Method::Dial,
        quantity,
        source: Source::MonteCarlo,
        order: Order::Total,
        channel_pair: "on/off".into(),
        fov_full_angle_mrad: 2.0,
        range_m: (115.0, 145.0),
        altitude_m: (0.0, 30.0),
        truth: 420.0,
        retrieved,
        mc_stderr: 0.1,
        mc_stderr_independent: 1.0,
        random_error_per_shot_pair: 5.0,
        random_error_averaged: 0.5,
        simulated_error_per_shot_pair: f64::NAN,
        simulated_error_averaged: 0.4,
        simulated_mean_averaged: 420.25,
        simulated_first_averaged: 419.0,
        shots_averaged: 1 << 40,
    }
}

fn write(products: &[Product]) -> Vec<u8> {
    let (mc, analytic) = returns();
    let lines = [Line {
        name: "on".into(),
        wavenumber_cm1: 6360.04,
    }];
    run_file(&RunFile {
        returns: &[&mc, &analytic],
        lidar_constant_j_m2: None,
        gates: &gates(),
        lidar_altitude_m: 0.0,
        mu: 1.0,
        lines: &lines,
        polarised: &[],
        signals: &[],
        products,
        gas: Some("CO2"),
        jacobians: None,
        attributes: &attributes(),
    })
    .unwrap()
}

fn read(bytes: Vec<u8>) -> FileReader {
    FileReader::open_seek_read("run.nc", Box::new(Cursor::new(bytes))).unwrap()
}

/// Text rows of a char variable, NULs stripped.
fn texts(r: &mut FileReader, name: &str) -> Vec<String> {
    let n = r.data_set().get_var(name).unwrap().get_dims()[1].size();
    r.read_var_u8(name)
        .unwrap()
        .chunks(n)
        .map(|c| String::from_utf8(c.iter().copied().take_while(|b| *b != 0).collect()).unwrap())
        .collect()
}

#[test]
fn returns_land_in_their_bins_and_missing_bins_are_fill() {
    let bytes = write(&[]);
    // NUG "File Format Specification": magic 'C' 'D' 'F' then version 2 (64-bit offset).
    assert_eq!(&bytes[..4], b"CDF\x02");
    let mut r = read(bytes);
    assert_eq!(r.version(), Version::Offset64Bit);
    let ds = r.data_set();
    for (dim, len) in [
        ("source", 2),
        ("channel", 2),
        ("fov_full_angle_mrad", 2),
        ("range_m", 3),
        ("order", 3),
        ("nv", 2),
    ] {
        assert_eq!(ds.dim_size(dim), Some(len), "{dim}");
    }
    assert_eq!(texts(&mut r, "source"), ["mc", "analytic"]);
    assert_eq!(texts(&mut r, "channel"), ["on", "off, \"ref\""]);
    assert_eq!(texts(&mut r, "order"), ["total", "1st", "2nd+"]);
    assert_eq!(r.read_var_f64("range_m").unwrap(), [115.0, 145.0, 175.0]);
    assert_eq!(
        r.read_var_f64("range_m_bounds").unwrap(),
        [100.0, 130.0, 130.0, 160.0, 160.0, 190.0]
    );
    assert_eq!(r.read_var_f64("fov_full_angle_mrad").unwrap(), [0.1, 2.0]);
    assert_eq!(
        r.read_var_f64("channel_wavenumber_cm1").unwrap(),
        [6360.04, NC_FILL_F64]
    );

    let (mc, analytic) = returns();
    let energy = r.read_var_f64("energy_j").unwrap();
    let stderr = r.read_var_f64("stderr_j").unwrap();
    assert_eq!(energy.len(), 2 * 2 * 2 * 3 * 3);
    // Dimensions (source, channel, fov, range, order), the last fastest.
    let at =
        |s: usize, c: usize, f: usize, g: usize, o: usize| (((s * 2 + c) * 2 + f) * 3 + g) * 3 + o;
    for c in 0..2 {
        for f in 0..2 {
            for g in 0..3 {
                for o in 0..3 {
                    let i = mc.index(c, f, g, o);
                    assert_eq!(energy[at(0, c, f, g, o)], mc.energy_j[i]);
                    let want = if mc.stderr_j[i].is_nan() {
                        NC_FILL_F64
                    } else {
                        mc.stderr_j[i]
                    };
                    assert_eq!(stderr[at(0, c, f, g, o)], want);
                }
                // Analytic: order 1 only (index 1 of the union), the rest fill.
                assert_eq!(
                    energy[at(1, c, f, g, 1)],
                    analytic.energy_j[analytic.index(c, f, g, 0)]
                );
                assert_eq!(stderr[at(1, c, f, g, 1)], 0.0);
                for o in [0, 2] {
                    assert_eq!(energy[at(1, c, f, g, o)], NC_FILL_F64);
                    assert_eq!(stderr[at(1, c, f, g, o)], NC_FILL_F64);
                }
            }
        }
    }
    let ds = r.data_set();
    assert_eq!(
        ds.get_var_attr_f64("energy_j", "_FillValue"),
        Some(&[NC_FILL_F64][..])
    );
    assert_eq!(
        ds.get_var_attr_as_string("energy_j", "ancillary_variables")
            .as_deref(),
        Some("stderr_j")
    );
    assert_eq!(
        ds.get_var_attr_as_string("range_m", "bounds").as_deref(),
        Some("range_m_bounds")
    );
    assert_eq!(
        ds.get_var_attr_as_string("channel_wavenumber_cm1", "units")
            .as_deref(),
        Some("cm-1")
    );
}

/// With lidar constants (2 and 4 J m² for the two channels): the lidar constant by channel,
/// and β′ = E r₁ r₂/(C Δr) and E r_c² in every bin the energy is in, worked by hand from the
/// gates [100 + 30 g, 130 + 30 g] m (not from the module's factor); errors scaled alike, an
/// unknown error fill; the bins without an energy fill; CF units and ancillary variables.
/// Constants that do not match the channels are refused.
#[test]
fn backscatter_variables_are_the_energies_times_the_lidar_equation_factors() {
    let (mc, analytic) = returns();
    let lines = [Line {
        name: "on".into(),
        wavenumber_cm1: 6360.04,
    }];
    let constants = [2.0, 4.0];
    let file = |constants: &[f64]| {
        run_file(&RunFile {
            returns: &[&mc, &analytic],
            lidar_constant_j_m2: Some(constants),
            gates: &gates(),
            lidar_altitude_m: 0.0,
            mu: 1.0,
            lines: &lines,
            polarised: &[],
            signals: &[],
            products: &[],
            gas: None,
            jacobians: None,
            attributes: &attributes(),
        })
    };
    let mut r = read(file(&constants).unwrap());
    assert_eq!(r.read_var_f64("lidar_constant_j_m2").unwrap(), constants);
    let beta = r.read_var_f64("attenuated_backscatter_per_m_sr").unwrap();
    let beta_se = r
        .read_var_f64("attenuated_backscatter_stderr_per_m_sr")
        .unwrap();
    let rcs = r.read_var_f64("range_corrected_signal_j_m2").unwrap();
    let rcs_se = r
        .read_var_f64("range_corrected_signal_stderr_j_m2")
        .unwrap();
    let at =
        |s: usize, c: usize, f: usize, g: usize, o: usize| (((s * 2 + c) * 2 + f) * 3 + g) * 3 + o;
    let close = |a: f64, b: f64| a == b || (a / b - 1.0).abs() < 1e-15;
    for c in 0..2 {
        for f in 0..2 {
            for g in 0..3 {
                let (r1, r2) = (100.0 + 30.0 * g as f64, 130.0 + 30.0 * g as f64);
                let factor = r1 * r2 / (30.0 * constants[c]);
                let rc2 = (0.5 * (r1 + r2)) * (0.5 * (r1 + r2));
                for o in 0..3 {
                    let i = mc.index(c, f, g, o);
                    let j = at(0, c, f, g, o);
                    assert!(close(beta[j], factor * mc.energy_j[i]), "{j}");
                    assert!(close(rcs[j], rc2 * mc.energy_j[i]), "{j}");
                    if mc.stderr_j[i].is_nan() {
                        assert_eq!((beta_se[j], rcs_se[j]), (NC_FILL_F64, NC_FILL_F64));
                    } else {
                        assert!(close(beta_se[j], factor * mc.stderr_j[i]), "{j}");
                        assert!(close(rcs_se[j], rc2 * mc.stderr_j[i]), "{j}");
                    }
                }
                let e = analytic.energy_j[analytic.index(c, f, g, 0)];
                assert!(close(beta[at(1, c, f, g, 1)], factor * e));
                assert_eq!(beta_se[at(1, c, f, g, 1)], 0.0);
                for o in [0, 2] {
                    assert_eq!(beta[at(1, c, f, g, o)], NC_FILL_F64);
                    assert_eq!(rcs[at(1, c, f, g, o)], NC_FILL_F64);
                }
            }
        }
    }
    let ds = r.data_set();
    let attr = |v: &str, k: &str| ds.get_var_attr_as_string(v, k);
    assert_eq!(
        attr("attenuated_backscatter_per_m_sr", "units").as_deref(),
        Some("m-1 sr-1")
    );
    assert_eq!(
        attr("attenuated_backscatter_per_m_sr", "ancillary_variables").as_deref(),
        Some("attenuated_backscatter_stderr_per_m_sr")
    );
    assert_eq!(
        attr("range_corrected_signal_j_m2", "units").as_deref(),
        Some("J m2")
    );
    assert_eq!(
        attr("lidar_constant_j_m2", "units").as_deref(),
        Some("J m2")
    );
    let e = file(&constants[..1]).unwrap_err();
    assert!(
        e.to_string().contains("1 lidar constants for 2 channels"),
        "{e}"
    );
}

#[test]
fn global_attributes_record_the_run() {
    let r = read(write(&[]));
    let ds = r.data_set();
    let text = |k: &str| ds.get_global_attr_as_string(k).unwrap();
    assert_eq!(text("Conventions"), "CF-1.8");
    assert_eq!(
        text("source"),
        format!("lidarsim {}", env!("CARGO_PKG_VERSION"))
    );
    assert_eq!(text("scene"), attributes().scene_text);
    assert_eq!(text("scene_file"), "scene.toml");
    assert_eq!(text("history"), attributes().history);
    assert_eq!(text("seed"), "18446744073709551615");
    assert_eq!(ds.get_global_attr_f64("photons"), Some(&[1e12][..]));
    assert_eq!(ds.get_global_attr_f64("batches"), Some(&[100.0][..]));
}

#[test]
fn products_are_one_table_per_quantity_with_fill_for_what_was_not_computed() {
    let mut ipda = product(Quantity::MixingRatio, 421.5);
    ipda.method = Method::Ipda;
    let rows = [
        ipda,
        product(Quantity::NumberDensity, 1e22),
        product(Quantity::MixingRatio, f64::NAN),
    ];
    let mut r = read(write(&rows));
    let ds = r.data_set();
    assert_eq!(ds.dim_size("mixing_ratio_product"), Some(2));
    assert_eq!(ds.dim_size("number_density_product"), Some(1));
    assert!(!ds.has_dim("slant_column_product"));
    assert_eq!(
        ds.get_var_attr_as_string("mixing_ratio_truth", "units")
            .as_deref(),
        Some("1e-6")
    );
    assert_eq!(
        ds.get_var_attr_as_string("mixing_ratio_retrieved", "standard_name")
            .as_deref(),
        Some("dry_atmosphere_mole_fraction_of_carbon_dioxide")
    );
    assert_eq!(
        ds.get_var_attr_as_string("number_density_truth", "units")
            .as_deref(),
        Some("m-3")
    );
    assert!(
        ds.get_var_attr("number_density_truth", "standard_name")
            .is_none()
    );
    assert_eq!(texts(&mut r, "mixing_ratio_method"), ["ipda", "dial"]);
    assert_eq!(
        texts(&mut r, "mixing_ratio_channel_pair"),
        ["on/off", "on/off"]
    );
    assert_eq!(
        r.read_var_f64("mixing_ratio_retrieved").unwrap(),
        [421.5, NC_FILL_F64]
    );
    assert_eq!(
        r.read_var_f64("mixing_ratio_bias").unwrap(),
        [421.5 - 420.0, NC_FILL_F64]
    );
    assert_eq!(
        r.read_var_f64("mixing_ratio_simulated_bias_averaged")
            .unwrap(),
        [0.25, 0.25]
    );
    assert_eq!(
        r.read_var_f64("mixing_ratio_simulated_error_per_shot_pair")
            .unwrap(),
        [NC_FILL_F64; 2]
    );
    assert_eq!(
        r.read_var_f64("mixing_ratio_shots_averaged").unwrap(),
        [(1u64 << 40) as f64; 2]
    );
    assert_eq!(r.read_var_f64("number_density_retrieved").unwrap(), [1e22]);
    assert_eq!(
        r.read_var_f64("number_density_range_end_m").unwrap(),
        [145.0]
    );
}

#[test]
fn returns_on_different_grids_are_refused() {
    let (mc, mut analytic) = returns();
    analytic.range_m[1] += 1.0;
    let e = run_file(&RunFile {
        returns: &[&mc, &analytic],
        lidar_constant_j_m2: None,
        gates: &gates(),
        lidar_altitude_m: 0.0,
        mu: 1.0,
        lines: &[],
        polarised: &[],
        signals: &[],
        products: &[],
        gas: None,
        jacobians: None,
        attributes: &attributes(),
    })
    .unwrap_err();
    assert!(e.to_string().contains("not on the grid"), "{e}");
}

#[test]
fn timestamps_are_iso_8601_utc() {
    let t = |s: u64| utc_timestamp(UNIX_EPOCH + Duration::from_secs(s));
    assert_eq!(t(0), "1970-01-01T00:00:00Z");
    // 2000-02-29 (a leap day of a century leap year) and 2100-03-01 (after a non-leap 28 Feb).
    assert_eq!(t(951_782_400 + 3661), "2000-02-29T01:01:01Z");
    assert_eq!(t(4_107_542_400 - 1), "2100-02-28T23:59:59Z");
    assert_eq!(t(4_107_542_400), "2100-03-01T00:00:00Z");
}

#[test]
fn a_table_with_columns_of_different_lengths_is_refused() {
    let column = |name, values| Column {
        name,
        long_name: "x",
        units: Some("1"),
        values,
    };
    let e = table_file(
        "row",
        &[
            column("a", ColumnValues::Number(vec![1.0, 2.0])),
            column("b", ColumnValues::Text(vec!["x".into()])),
        ],
        "t",
        "h",
    )
    .unwrap_err();
    assert!(e.to_string().contains("column b has 1 rows, not 2"), "{e}");
    let bytes = table_file(
        "row",
        &[
            column("a", ColumnValues::Number(vec![1.5, f64::NAN])),
            column("b", ColumnValues::Text(vec!["x".into(), "yz".into()])),
        ],
        "t",
        "h",
    )
    .unwrap();
    let mut r = read(bytes);
    assert_eq!(r.read_var_f64("a").unwrap(), [1.5, NC_FILL_F64]);
    assert_eq!(texts(&mut r, "b"), ["x", "yz"]);
    assert_eq!(
        r.data_set()
            .get_var_attr_as_string("a", "coordinates")
            .as_deref(),
        Some("b")
    );
}

/// No file holds NaN or inf: values of a variable with `_FillValue` become the fill, and a
/// non-finite value anywhere else (a coordinate, bounds, an attribute) refuses the file.
#[test]
fn non_finite_values_are_fill_or_refused() {
    let mut nc = Dataset::default();
    nc.dim("x", 3);
    nc.f64("v", &["x"], vec![1.0, f64::INFINITY, f64::NAN])
        .attrs([("long_name", "v")])
        .fill();
    let mut r = read(nc.encode().unwrap());
    assert_eq!(
        r.read_var_f64("v").unwrap(),
        [1.0, NC_FILL_F64, NC_FILL_F64]
    );
    let mut nc = Dataset::default();
    nc.dim("x", 2);
    nc.f64("x", &["x"], vec![0.0, f64::NEG_INFINITY]);
    let e = nc.encode().unwrap_err().to_string();
    assert!(
        e.contains("the variable `x`") && e.contains("not finite"),
        "{e}"
    );
    let mut nc = Dataset::default();
    nc.global("g", Attr::F64(vec![f64::NAN]));
    let e = nc.encode().unwrap_err().to_string();
    assert!(e.contains("the global attribute `g`"), "{e}");
}

/// With polarised light: co and cross of each bin on the last dimension, at the bin of
/// `energy_j`'s grid their source and order name; δ = cross/co with the propagated error where
/// co > 0 (Monte Carlo, with the covariance) or 0 (analytic), fill where co is 0 or absent.
#[test]
fn polarised_returns_land_in_their_bins_with_the_depolarisation_ratio() {
    let (mc, analytic) = returns();
    let scaled = |r: &Returns, f: f64| {
        let mut r = r.clone();
        r.energy_j.iter_mut().for_each(|e| *e *= f);
        r.stderr_j.iter_mut().for_each(|s| *s *= f);
        r
    };
    let (mc_co, mc_cross) = (scaled(&mc, 0.75), scaled(&mc, 0.25));
    let mut an_co = scaled(&analytic, -1.0);
    an_co.energy_j[0] = 0.0; // no co-polarised return: no ratio
    let an_cross = scaled(&analytic, -0.5);
    // Correlation ½ between co and cross, each with the relative error r of its bin: then
    // σ²_δ/δ² = r² + r² − 2·½r² = r², so σ_δ = δ r.
    let cov: Vec<f64> = (0..mc.energy_j.len())
        .map(|i| 0.5 * mc_co.stderr_j[i] * mc_cross.stderr_j[i])
        .collect();
    let polarised = [
        PolarisedSet {
            co: &mc_co,
            cross: &mc_cross,
            cov_j2: Some(&cov),
        },
        PolarisedSet {
            co: &an_co,
            cross: &an_cross,
            cov_j2: None,
        },
    ];
    let ds = run_dataset(&RunFile {
        returns: &[&mc, &analytic],
        lidar_constant_j_m2: None,
        gates: &gates(),
        lidar_altitude_m: 0.0,
        mu: 1.0,
        lines: &[],
        polarised: &polarised,
        signals: &[],
        products: &[],
        gas: None,
        jacobians: None,
        attributes: &attributes(),
    })
    .unwrap();
    let var = |name: &str| ds.vars.iter().find(|v| v.name == name).unwrap();
    let f64s = |name: &str| match &var(name).values {
        Values::F64(x) => x.clone(),
        Values::Char(_) => panic!("{name} is text"),
    };
    assert_eq!(
        var("polarised_energy_j").dims.last().unwrap(),
        "polarisation"
    );
    let (energy, stderr, delta, delta_se) = (
        f64s("polarised_energy_j"),
        f64s("polarised_stderr_j"),
        f64s("depolarisation_ratio"),
        f64s("depolarisation_ratio_stderr"),
    );
    // Grid: source × channel (2) × fov (2) × gate (3) × order (total, 1, 2+).
    let j =
        |s: usize, c: usize, f: usize, g: usize, o: usize| (((s * 2 + c) * 2 + f) * 3 + g) * 3 + o;
    for c in 0..2 {
        for f in 0..2 {
            for g in 0..3 {
                for o in 0..3 {
                    let (i, k) = (mc.index(c, f, g, o), j(0, c, f, g, o));
                    assert_eq!(energy[2 * k], mc_co.energy_j[i]);
                    assert_eq!(energy[2 * k + 1], mc_cross.energy_j[i]);
                    let se = mc_cross.stderr_j[i];
                    assert_eq!(
                        stderr[2 * k + 1],
                        if se.is_nan() { NC_FILL_F64 } else { se }
                    );
                    let want =
                        crate::returns::depolarisation_ratio(&mc_co, &mc_cross, Some(&cov), i);
                    assert!((delta[k] - 1.0 / 3.0).abs() < 1e-15);
                    assert_eq!(delta[k], want.0);
                    if want.1.is_finite() {
                        assert_eq!(delta_se[k], want.1);
                        let r = mc.stderr_j[i] / mc.energy_j[i];
                        assert!((delta_se[k] / (r / 3.0) - 1.0).abs() < 1e-12);
                    } else {
                        assert_eq!(delta_se[k], NC_FILL_F64);
                    }
                }
                // Analytic: order 1 only (index 1 of the grid's orders), error 0.
                let (i, k) = (analytic.index(c, f, g, 0), j(1, c, f, g, 1));
                assert_eq!(energy[2 * k], an_co.energy_j[i]);
                assert_eq!(energy[2 * k + 1], an_cross.energy_j[i]);
                if i == 0 {
                    assert_eq!((delta[k], delta_se[k]), (NC_FILL_F64, NC_FILL_F64));
                } else {
                    assert_eq!((delta[k], delta_se[k]), (0.5, 0.0));
                }
                for o in [0, 2] {
                    assert_eq!(energy[2 * j(1, c, f, g, o)], NC_FILL_F64);
                    assert_eq!(delta[j(1, c, f, g, o)], NC_FILL_F64);
                }
            }
        }
    }
}

/// Jacobians on the returns' grid: channels named as the grid's but listed in another order,
/// and a combination that is no line (a jittered line's slope), two layers (the lower without
/// particles, the upper without molecules), each derivative a distinct number.
fn jacobians() -> Jacobians {
    let (mc, _) = returns();
    let channels = vec![
        "off, \"ref\"".to_string(),
        "on:d_dnu_per_mhz".to_string(),
        "on".to_string(),
    ];
    let (nl, nq) = (2, JacobianQuantity::ALL.len());
    let n = channels.len() * mc.fov_full_angle_mrad.len() * mc.range_m.len() * 3 * nl * nq;
    let mut defined = vec![true; nl * nq * channels.len()];
    for k in 0..channels.len() {
        // Layer 0: no particles; layer 1: no molecules.
        for q in [2, 3] {
            defined[q * channels.len() + k] = false;
        }
        defined[(nq + 1) * channels.len() + k] = false;
    }
    Jacobians {
        channels,
        fov_full_angle_mrad: mc.fov_full_angle_mrad.clone(),
        range_m: mc.range_m.clone(),
        orders: vec![Order::Total, Order::Exactly(1), Order::AtLeast(2)],
        first_layer: 0,
        layer_bottom_m: vec![0.0, 150.5],
        layer_top_m: vec![150.5, 1000.0],
        value: (0..n).map(|i| -1e-9 * (i as f64 + 1.0) / 7.0).collect(),
        stderr: (0..n).map(|i| 1e-12 * (i as f64 + 1.0) / 3.0).collect(),
        defined,
    }
}

/// `jacobian_j_m` and its standard error read back over (channel, fov, gate, jacobian_order,
/// layer, jacobian_quantity): each bin holds the derivative of the channel of the same name,
/// `_FillValue` where the layer lacks the scatterer; the coordinates are the CSV's labels
/// and the layers' edges; a combination that is no line is left out.
#[test]
fn jacobians_land_in_their_bins_with_fill_where_undefined() {
    let (mc, analytic) = returns();
    let j = jacobians();
    let bytes = run_file(&RunFile {
        returns: &[&mc, &analytic],
        lidar_constant_j_m2: None,
        gates: &gates(),
        lidar_altitude_m: 0.0,
        mu: 1.0,
        lines: &[],
        polarised: &[],
        signals: &[],
        products: &[],
        gas: None,
        jacobians: Some(&j),
        attributes: &attributes(),
    })
    .unwrap();
    let mut r = read(bytes);
    let ds = r.data_set();
    for (dim, len) in [
        ("jacobian_order", 3),
        ("layer", 2),
        ("jacobian_quantity", 4),
    ] {
        assert_eq!(ds.dim_size(dim), Some(len), "{dim}");
    }
    let dims: Vec<String> = ds
        .get_var("jacobian_j_m")
        .unwrap()
        .get_dims()
        .iter()
        .map(|d| d.name())
        .collect();
    assert_eq!(
        dims,
        [
            "channel",
            "fov_full_angle_mrad",
            "range_m",
            "jacobian_order",
            "layer",
            "jacobian_quantity"
        ]
    );
    let attr = |var: &str, name: &str| ds.get_var_attr_as_string(var, name).unwrap_or_default();
    assert_eq!(attr("jacobian_j_m", "units"), "J m");
    assert_eq!(attr("jacobian_stderr_j_m", "units"), "J m");
    assert_eq!(
        attr("jacobian_j_m", "ancillary_variables"),
        "jacobian_stderr_j_m"
    );
    assert_eq!(
        attr("jacobian_j_m", "coordinates"),
        "altitude_m layer_bottom_m layer_top_m"
    );
    assert!(attr("jacobian_j_m", "long_name").contains("1/m"));
    assert_eq!(attr("layer_bottom_m", "units"), "m");
    assert_eq!(texts(&mut r, "jacobian_order"), ["total", "1st", "2nd+"]);
    assert_eq!(
        texts(&mut r, "jacobian_quantity"),
        [
            "absorption",
            "molecular_scattering",
            "particle_scattering",
            "particle_extinction"
        ]
    );
    assert_eq!(texts(&mut r, "channel"), ["on", "off, \"ref\""]);
    assert_eq!(r.read_var_f64("layer").unwrap(), [0.0, 1.0]);
    assert_eq!(r.read_var_f64("layer_bottom_m").unwrap(), [0.0, 150.5]);
    assert_eq!(r.read_var_f64("layer_top_m").unwrap(), [150.5, 1000.0]);
    let (value, stderr) = (
        r.read_var_f64("jacobian_j_m").unwrap(),
        r.read_var_f64("jacobian_stderr_j_m").unwrap(),
    );
    assert_eq!(value.len(), 2 * 2 * 3 * 3 * 2 * 4);
    let (mut defined, mut fill) = (0, 0);
    for (c, jc) in [(0, 2), (1, 0)] {
        for f in 0..2 {
            for g in 0..3 {
                for (o, order) in j.orders.iter().enumerate() {
                    for l in 0..2 {
                        // The four in J m (gas_amount, in J, is the CSV's only).
                        for (q, quantity) in JacobianQuantity::ALL[..4].iter().enumerate() {
                            let k = ((((c * 2 + f) * 3 + g) * 3 + o) * 2 + l) * 4 + q;
                            match j.get(jc, f, g, *order, l, *quantity) {
                                Some((v, s)) => {
                                    assert_eq!((value[k], stderr[k]), (v, s));
                                    defined += 1;
                                }
                                None => {
                                    assert_eq!((value[k], stderr[k]), (NC_FILL_F64, NC_FILL_F64));
                                    fill += 1;
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    // Per (channel, fov, gate, order): layer 0 absorption and molecular scattering, layer 1
    // absorption and both particle quantities.
    assert_eq!((defined, fill), (36 * 5, 36 * 3));
}

/// Without Jacobians the file has none of their dimensions or variables; Jacobians on
/// another grid, or of no channel of the returns, are refused.
#[test]
fn jacobians_are_absent_without_and_refused_off_the_grid() {
    let (mc, analytic) = returns();
    let file = |j: Option<&Jacobians>| {
        run_dataset(&RunFile {
            returns: &[&mc, &analytic],
            lidar_constant_j_m2: None,
            gates: &gates(),
            lidar_altitude_m: 0.0,
            mu: 1.0,
            lines: &[],
            polarised: &[],
            signals: &[],
            products: &[],
            gas: None,
            jacobians: j,
            attributes: &attributes(),
        })
    };
    let ds = file(None).unwrap();
    assert!(
        ds.dims
            .iter()
            .all(|(d, _)| !d.contains("jacobian") && d != "layer")
    );
    assert!(
        ds.vars
            .iter()
            .all(|v| !v.name.contains("jacobian") && !v.name.starts_with("layer"))
    );
    let mut off_grid = jacobians();
    off_grid.range_m[0] += 1.0;
    assert!(matches!(file(Some(&off_grid)), Err(NetcdfError::Layout(_))));
    let mut no_line = jacobians();
    no_line.channels = vec!["a".into(), "b".into(), "c".into()];
    assert!(matches!(file(Some(&no_line)), Err(NetcdfError::Layout(_))));
}

/// `altitude_m`, the gates' altitude along the line of sight: a nadir look from 2000 m over the
/// gates 100–130, 130–160, 160–190 m puts their centres at 1885, 1855, 1825 m and their edges
/// at 1900 … 1810 m; it is an auxiliary coordinate every variable over `range_m` names, with
/// CF's standard name, units and direction; a pointing that is not finite is refused.
#[test]
fn altitude_is_the_lidar_altitude_along_the_line_of_sight() {
    let (mc, analytic) = returns();
    let file = |alt: f64, mu: f64| {
        run_dataset(&RunFile {
            returns: &[&mc, &analytic],
            lidar_constant_j_m2: None,
            gates: &gates(),
            lidar_altitude_m: alt,
            mu,
            lines: &[],
            polarised: &[],
            signals: &[],
            products: &[],
            gas: None,
            jacobians: None,
            attributes: &attributes(),
        })
    };
    let ds = file(2000.0, -1.0).unwrap();
    let var = |name: &str| ds.vars.iter().find(|v| v.name == name).unwrap();
    let text = |v: &Var, k: &str| {
        v.attrs.iter().find(|(n, _)| n == k).map(|(_, a)| match a {
            Attr::Text(t) => t.clone(),
            Attr::F64(_) => panic!("{k} is a number"),
        })
    };
    let z = var("altitude_m");
    assert_eq!(z.dims, ["range_m"]);
    assert_eq!(z.values, Values::F64(vec![1885.0, 1855.0, 1825.0]));
    for (k, want) in [
        ("standard_name", "altitude"),
        ("units", "m"),
        ("positive", "up"),
        ("bounds", "altitude_m_bounds"),
    ] {
        assert_eq!(text(z, k).as_deref(), Some(want), "{k}");
    }
    assert_eq!(
        var("altitude_m_bounds").values,
        Values::F64(vec![1900.0, 1870.0, 1870.0, 1840.0, 1840.0, 1810.0])
    );
    for v in ["energy_j", "stderr_j"] {
        assert_eq!(text(var(v), "coordinates").as_deref(), Some("altitude_m"));
    }
    assert!(file(f64::NAN, 1.0).is_err());
}
