//! What beyond-Voigt spectroscopy means for a CO2 IPDA.
//!
//! `cargo run --release --example beyond_voigt_lidar -- SHARED_DATA_DIR [OUT.csv]`
//! (SHARED_DATA_DIR = `../shared/data`, with `nist_30012/` and `hitran/`).
//!
//! US standard atmosphere, CO2 at 420 ppm, nadir from 60 km to the surface, monochromatic
//! laser; off-line 6360.574 cm⁻¹, on-line at R(16)e's centre shifted to 1 atm and 0.02, 0.04,
//! 0.06 cm⁻¹ above it. The truth: the 51 lines of the 30012←00001 band with NIST's
//! speed-dependent Nelkin-Ghatak parameters and first-order line mixing (Hartmann-Tran with
//! η = 0), plus every other CO2 626 line of HITRAN2016 (Voigt). Two retrievals assume (a) the
//! Voigt profile with the NIST parameters, (b) the Voigt profile with HITRAN2016 for every
//! line. For a monochromatic IPDA the retrieval scales its reference CO2 so that its one-way
//! DAOD equals the measured one, so its bias is X (D_truth/D_assumed − 1) (the reference
//! state being the true profile: only the spectroscopy differs).

use std::path::{Path, PathBuf};

use lidarsim::atmosphere::StandardAtmosphere;
use lidarsim::output::write_file;
use lidarsim::retrieval::LayerColumns;
use lidarsim::spectroscopy::{
    LblOptions, LineFilter, LineList, LineShapeModel, layer_optical_depths_at,
};

const OFF_CM1: f64 = 6360.574;
const R16E_CM1: f64 = 6359.967248;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let Some(data) = args.get(1).map(PathBuf::from) else {
        return Err("usage: beyond_voigt_lidar SHARED_DATA_DIR [OUT.csv]".into());
    };
    let out = args
        .get(2)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("beyond_voigt_lidar.csv"));
    let nist = data.join("nist_30012/CO2_30012_NIST_SDNGP_LM.csv");
    let hitran = data.join("hitran/CO2_626_6000-6400_HITRAN2016.par");
    for f in [&nist, &hitran] {
        if !f.is_file() {
            return Err(format!("{} is absent (tests-only data of ../shared)", f.display()).into());
        }
    }
    let window = LineFilter::window(6330.0, 6390.0);
    let band = LineList::read(&nist, &window)?;
    let all = LineList::read_par(&hitran, &window)?;
    // HITRAN2016 without the band's lines (its global quanta, matched to NIST's within
    // 0.01 cm⁻¹).
    let collapse = |s: &str| s.split_whitespace().collect::<Vec<_>>().join(" ");
    let rest = LineList {
        source: format!("{} without the 30012 band", all.source),
        lines: all
            .lines
            .iter()
            .filter(|l| {
                !(l.iso_id == 1
                    && collapse(l.global_upper_quanta()) == "3 0 0 12"
                    && collapse(l.global_lower_quanta()) == "0 0 0 01"
                    && band
                        .lines
                        .iter()
                        .any(|b| (b.nu_cm1 - l.nu_cm1).abs() < 0.01))
            })
            .cloned()
            .collect(),
    };
    let removed = all.len() - rest.len();
    if removed != band.len() {
        return Err(format!(
            "removed {removed} HITRAN lines for the {} band lines",
            band.len()
        )
        .into());
    }

    let mut profile = StandardAtmosphere::UsStandard.profile();
    profile.rescale_gas("CO2", 420e-6)?;
    let edges: Vec<f64> = (0..=240).map(|i| i as f64 * 250.0).collect();
    let cols = LayerColumns::new(&profile, &edges, "CO2")?;
    let x_true =
        cols.gas_per_m2.iter().sum::<f64>() / cols.dry_air_per_m2.iter().sum::<f64>() * 1e6;

    // The on-lines: R(16)e's centre shifted to 1 atm (the NIST shift), then above it.
    let shift = band
        .lines
        .iter()
        .find(|l| (l.nu_cm1 - R16E_CM1).abs() < 1e-4)
        .and_then(|l| l.shape.as_ref().map(|s| s.air.delta0))
        .ok_or("R(16)e is not in the NIST list")?;
    let offsets = [0.0, 0.02, 0.04, 0.06];
    let mut nus: Vec<f64> = offsets.iter().map(|o| R16E_CM1 + shift + o).collect();
    nus.push(OFF_CM1);
    // Column optical depth of a line list with options, at every wavenumber.
    let column =
        |lines: &LineList, opts: &LblOptions| -> Result<Vec<f64>, Box<dyn std::error::Error>> {
            let t = layer_optical_depths_at(&profile, lines, &edges, &nus, opts)?;
            Ok((0..nus.len())
                .map(|k| t.iter().map(|r| r[k]).sum())
                .collect())
        };
    let voigt = LblOptions::default();
    let ht = LblOptions {
        line_shape: LineShapeModel::HartmannTran,
        line_mixing: true,
        ..Default::default()
    };
    let rest_tau = column(&rest, &voigt)?;
    let add = |a: Vec<f64>| -> Vec<f64> { a.iter().zip(&rest_tau).map(|(x, y)| x + y).collect() };
    let truth = add(column(&band, &ht)?);
    let voigt_nist = add(column(&band, &voigt)?);
    let voigt_hitran = column(&all, &voigt)?;
    let off = nus.len() - 1;
    let daod = |t: &[f64], k: usize| t[k] - t[off];

    let mut csv = String::from(
        "on_offset_cm1,nu_on_cm1,daod_ht_lm,daod_voigt_nist,daod_voigt_hitran2016,xco2_bias_voigt_nist_ppm,xco2_bias_voigt_hitran2016_ppm\n",
    );
    println!(
        "US standard, 420 ppm (column {x_true:.3} ppm), nadir 60 km → surface; off-line {OFF_CM1} cm⁻¹; truth: NIST SDNGP + line mixing for the 30012 band, HITRAN2016 Voigt for the rest"
    );
    println!(
        "{:>9} {:>12} {:>10} {:>10} {:>10} {:>12} {:>12}",
        "offset", "ν_on cm⁻¹", "DAOD HT", "Voigt NIST", "Voigt H16", "bias (a) ppm", "bias (b) ppm"
    );
    for (k, o) in offsets.iter().enumerate() {
        let (d, da, db) = (
            daod(&truth, k),
            daod(&voigt_nist, k),
            daod(&voigt_hitran, k),
        );
        let (ba, bb) = (x_true * (d / da - 1.0), x_true * (d / db - 1.0));
        println!(
            "{:>9.2} {:>12.5} {:>10.5} {:>10.5} {:>10.5} {:>12.3} {:>12.3}",
            o, nus[k], d, da, db, ba, bb
        );
        csv.push_str(&format!("{o},{},{d},{da},{db},{ba},{bb}\n", nus[k]));
    }
    write_file(Path::new(&out), csv.as_bytes())?;
    println!("wrote {}", out.display());
    Ok(())
}
