//! Fit the compact CO2 30012←00001 band model to the HITRAN2016 lines of the band.
//!
//! `cargo run --release --example co2_band_model_fit` (reads ../shared/data/hitran, or
//! $LIDARSIM_SHARED/data/hitran). Writes `data/co2_band_model/co2_30012_band.toml` (the constants
//! the library embeds) and `validation/co2_band_model/fit_report.md`. Model and formulas:
//! `src/spectroscopy/band_model.rs`.

use std::fmt::Write as _;
use std::path::PathBuf;

use nalgebra::{DMatrix, DVector};

use lidarsim::spectroscopy::band_model::Co2BandModel;
use lidarsim::spectroscopy::xsec::GasState;
use lidarsim::spectroscopy::{LblOptions, LineFilter, LineList, WavenumberGrid, cross_section};

/// Lines used in the fit: |m| ≤ FIT_M (the model is generated up to the same |m|).
const FIT_M: i32 = 60;
/// The brief's accuracy range.
const CHECK_M: i32 = 40;

struct BandLine {
    m: i32,
    nu: f64,
    sw: f64,
    elower: f64,
    gamma_air: f64,
    gamma_self: f64,
    n_air: f64,
    delta_air: f64,
}

/// Weighted least squares: minimise Σ w_i² (A x − b)_i² by SVD.
fn lsq(rows: &[Vec<f64>], b: &[f64], w: &[f64]) -> Vec<f64> {
    let n = rows.len();
    let k = rows[0].len();
    let a = DMatrix::from_fn(n, k, |i, j| rows[i][j] * w[i]);
    let bb = DVector::from_fn(n, |i, _| b[i] * w[i]);
    // Scale columns for conditioning.
    let scale: Vec<f64> = (0..k).map(|j| a.column(j).norm().max(1e-300)).collect();
    let a_s = DMatrix::from_fn(n, k, |i, j| a[(i, j)] / scale[j]);
    let x = a_s
        .svd(true, true)
        .solve(&bb, 1e-15)
        .expect("SVD solve succeeds");
    (0..k).map(|j| x[j] / scale[j]).collect()
}

fn poly_fit(x: &[f64], y: &[f64], degree: usize) -> Vec<f64> {
    let rows: Vec<Vec<f64>> = x
        .iter()
        .map(|&xi| (0..=degree).map(|d| xi.powi(d as i32)).collect())
        .collect();
    lsq(&rows, y, &vec![1.0; x.len()])
}

fn poly(c: &[f64], x: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, &a| acc * x + a)
}

fn main() -> anyhow::Result<()> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let shared = std::env::var_os("LIDARSIM_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("../shared"));
    let par = shared.join("data/hitran/CO2_626_6000-6400_HITRAN2016.par");
    let all = LineList::read_par(&par, &LineFilter::default())?;

    // The band's lines: 30012 ← 00001 of 626.
    let mut band = Vec::new();
    for l in &all.lines {
        if l.iso_id != 1
            || l.global_upper_quanta().trim() != "3 0 0 12"
            || l.global_lower_quanta().trim() != "0 0 0 01"
        {
            continue;
        }
        let q = l.local_lower_quanta().trim().to_string();
        let branch = q.chars().next().unwrap_or('?');
        let j: i32 = q[1..].trim().trim_end_matches(['e', 'f']).trim().parse()?;
        let m = match branch {
            'P' => -j,
            'R' => j + 1,
            _ => continue,
        };
        band.push(BandLine {
            m,
            nu: l.nu_cm1,
            sw: l.sw_cm_per_molecule,
            elower: l.elower_cm1,
            gamma_air: l.gamma_air_cm1_per_atm,
            gamma_self: l.gamma_self_cm1_per_atm,
            n_air: l.n_air,
            delta_air: l.delta_air_cm1_per_atm,
        });
    }
    band.sort_by_key(|b| b.m);
    let n_band = band.len();
    let fit: Vec<&BandLine> = band.iter().filter(|b| b.m.abs() <= FIT_M).collect();

    // 1. Ground state from HITRAN's E″: E″ = B″x − D″x² + H″x³, x = J″(J″+1).
    let jl = |m: i32| Co2BandModel::j_of_m(m).0 as f64;
    let ju = |m: i32| Co2BandModel::j_of_m(m).1 as f64;
    let rows: Vec<Vec<f64>> = fit
        .iter()
        .map(|b| {
            let x = jl(b.m) * (jl(b.m) + 1.0);
            vec![x, -x * x, x * x * x]
        })
        .collect();
    let e_l: Vec<f64> = fit.iter().map(|b| b.elower).collect();
    let g = lsq(&rows, &e_l, &vec![1.0; fit.len()]);
    // 2. Upper state from E′ = ν + E″: E′ = G′ + B′x − D′x² + H′x³, x = J′(J′+1).
    let rows: Vec<Vec<f64>> = fit
        .iter()
        .map(|b| {
            let x = ju(b.m) * (ju(b.m) + 1.0);
            vec![1.0, x, -x * x, x * x * x]
        })
        .collect();
    let e_u: Vec<f64> = fit.iter().map(|b| b.nu + b.elower).collect();
    let u = lsq(&rows, &e_u, &vec![1.0; fit.len()]);

    let mut model = Co2BandModel {
        source: format!(
            "fit to {} HITRAN2016 lines of 626 30012<-00001 with |m| <= {FIT_M} (validation/co2_band_model)",
            fit.len()
        ),
        band_origin_cm1: u[0],
        b_upper_cm1: u[1],
        d_upper_cm1: u[2],
        h_upper_cm1: u[3],
        b_lower_cm1: g[0],
        d_lower_cm1: g[1],
        h_lower_cm1: g[2],
        strength_cm_per_molecule: 1.0,
        herman_wallis: vec![0.0, 0.0, 0.0],
        gamma_air_poly: vec![],
        gamma_self_poly: vec![],
        n_air_poly: vec![],
        delta_air_poly: vec![],
    };
    // 3. Strengths: S_hitran / S_model(S₀ = 1, F = 1) = S₀ (1 + A₁m + A₂m² + A₃m³)²; fit the
    //    square root with relative weights.
    let ratio: Vec<f64> = fit.iter().map(|b| b.sw / model.strength_296(b.m)).collect();
    let rows: Vec<Vec<f64>> = fit
        .iter()
        .map(|b| {
            let m = b.m as f64;
            vec![1.0, m, m * m, m * m * m]
        })
        .collect();
    let sq: Vec<f64> = ratio.iter().map(|r| r.sqrt()).collect();
    let wts: Vec<f64> = sq.iter().map(|s| 1.0 / s).collect();
    let s = lsq(&rows, &sq, &wts);
    model.strength_cm_per_molecule = s[0] * s[0];
    model.herman_wallis = vec![s[1] / s[0], s[2] / s[0], s[3] / s[0]];
    // 4. Broadening and shift.
    let am: Vec<f64> = fit.iter().map(|b| b.m.abs() as f64).collect();
    let ms: Vec<f64> = fit.iter().map(|b| b.m as f64).collect();
    let col = |f: fn(&BandLine) -> f64| fit.iter().map(|b| f(b)).collect::<Vec<f64>>();
    model.gamma_air_poly = poly_fit(&am, &col(|b| b.gamma_air), 4);
    model.gamma_self_poly = poly_fit(&am, &col(|b| b.gamma_self), 4);
    model.n_air_poly = poly_fit(&am, &col(|b| b.n_air), 3);
    model.delta_air_poly = poly_fit(&ms, &col(|b| b.delta_air), 4);

    // Residuals.
    let mut rep = String::new();
    writeln!(rep, "# CO2 30012←00001 band model: fit report\n")?;
    writeln!(
        rep,
        "Generated by `cargo run --release --example co2_band_model_fit` from `{}` ({} lines of the band; \
         {} with |m| ≤ {FIT_M} used in the fit). Constants: `data/co2_band_model/co2_30012_band.toml`.\n",
        par.strip_prefix(&root).unwrap_or(&par).display(),
        n_band,
        fit.len()
    )?;
    writeln!(
        rep,
        "## Constants\n\n```toml\n{}```\n",
        toml::to_string(&model)?
    )?;
    writeln!(
        rep,
        "## Line parameters against HITRAN2016\n\n| quantity | range | max abs error | max rel error | rms |\n|---|---|---|---|---|"
    )?;
    for (range_name, lim) in [("|m| ≤ 40", CHECK_M), ("|m| ≤ 60", FIT_M)] {
        let sel: Vec<&&BandLine> = fit.iter().filter(|b| b.m.abs() <= lim).collect();
        let dnu: Vec<f64> = sel.iter().map(|b| model.position_cm1(b.m) - b.nu).collect();
        let ds: Vec<f64> = sel
            .iter()
            .map(|b| model.strength_296(b.m) / b.sw - 1.0)
            .collect();
        let de: Vec<f64> = sel
            .iter()
            .map(|b| model.lower_energy_cm1(Co2BandModel::j_of_m(b.m).0) - b.elower)
            .collect();
        let stat = |v: &[f64]| {
            let max = v.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            let rms = (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
            (max, rms)
        };
        let (mx, rms) = stat(&dnu);
        writeln!(
            rep,
            "| line centre ν [cm⁻¹] | {range_name} | {mx:.2e} | | {rms:.2e} |"
        )?;
        let (mx, rms) = stat(&de);
        writeln!(rep, "| E″ [cm⁻¹] | {range_name} | {mx:.2e} | | {rms:.2e} |")?;
        let (mx, rms) = stat(&ds);
        writeln!(
            rep,
            "| intensity S₂₉₆ | {range_name} | | {:.3} % | {:.3} % |",
            mx * 100.0,
            rms * 100.0
        )?;
        for (name, f, c) in [
            (
                "γ_air [cm⁻¹/atm]",
                (|b: &BandLine| b.gamma_air) as fn(&BandLine) -> f64,
                &model.gamma_air_poly,
            ),
            (
                "γ_self [cm⁻¹/atm]",
                |b: &BandLine| b.gamma_self,
                &model.gamma_self_poly,
            ),
            ("n_air", |b: &BandLine| b.n_air, &model.n_air_poly),
        ] {
            let r: Vec<f64> = sel
                .iter()
                .map(|b| poly(c, b.m.abs() as f64) - f(b))
                .collect();
            let rr: Vec<f64> = sel
                .iter()
                .map(|b| poly(c, b.m.abs() as f64) / f(b) - 1.0)
                .collect();
            let ((mx, rms), (mr, _)) = (stat(&r), stat(&rr));
            writeln!(
                rep,
                "| {name} | {range_name} | {mx:.2e} | {:.2} % | {rms:.2e} |",
                mr * 100.0
            )?;
        }
        let r: Vec<f64> = sel
            .iter()
            .map(|b| poly(&model.delta_air_poly, b.m as f64) - b.delta_air)
            .collect();
        let (mx, rms) = stat(&r);
        writeln!(
            rep,
            "| δ_air [cm⁻¹/atm] | {range_name} | {mx:.2e} | | {rms:.2e} |"
        )?;
        if lim == CHECK_M {
            let (mxn, _) = stat(&dnu);
            let (mxs, _) = stat(&ds);
            println!(
                "|m| <= 40: max |dnu| = {mxn:.2e} cm-1, max |dS/S| = {:.3} %",
                mxs * 100.0
            );
            anyhow::ensure!(mxn < 0.002, "line centres miss the 0.002 cm-1 target");
            anyhow::ensure!(mxs < 0.01, "intensities miss the 1 % target");
        }
    }

    // Cross-sections near R(16)e: band model against all HITRAN CO2 626 lines and against the
    // HITRAN lines of this band only (to separate the model's error from the missing bands).
    let model_lines = model.line_list(FIT_M as u32);
    let band_only = LineList {
        source: "HITRAN band lines".into(),
        lines: all
            .lines
            .iter()
            .filter(|l| {
                l.iso_id == 1
                    && l.global_upper_quanta().trim() == "3 0 0 12"
                    && l.global_lower_quanta().trim() == "0 0 0 01"
            })
            .cloned()
            .collect(),
    };
    let grid = WavenumberGrid::new(6358.0, 6362.0, 0.0005)?;
    writeln!(
        rep,
        "\n## Cross-sections near R(16)e (6358–6362 cm⁻¹, 0.0005 cm⁻¹ grid, air-broadened, 25 cm⁻¹ wing)\n\n\
         On-line = the R(16)e peak; off-line = 6361.20 cm⁻¹ (between R16 and R18). Δσ = σ_on − σ_off is what \
         a DIAL measures.\n\n| case | model vs | σ_on rel. diff | σ_off rel. diff | Δσ rel. diff | max rel. diff where σ > 10 % of peak |\n|---|---|---|---|---|---|"
    )?;
    for (case, p_atm, t_k) in [("1 atm, 296 K", 1.0, 296.0), ("0.5 atm, 250 K", 0.5, 250.0)] {
        let state = GasState {
            pressure_pa: p_atm * 101_325.0,
            temperature_k: t_k,
            self_vmr: 0.0,
        };
        let opts = LblOptions::default();
        let sm = cross_section(&model_lines, 2, &state, &grid, &opts)?;
        for (name, ref_lines) in [
            ("all HITRAN 626 lines", &all),
            ("HITRAN lines of this band", &band_only),
        ] {
            let sh = cross_section(ref_lines, 2, &state, &grid, &opts)?;
            let ipk = (0..grid.len)
                .max_by(|&a, &b| sh[a].total_cmp(&sh[b]))
                .unwrap_or(0);
            let ioff = ((6361.2 - grid.start_cm1) / grid.step_cm1).round() as usize;
            let rel = |a: f64, b: f64| (a / b - 1.0) * 100.0;
            let peak = sh[ipk];
            let max_core = (0..grid.len)
                .filter(|&i| sh[i] > 0.1 * peak)
                .map(|i| rel(sm[i], sh[i]).abs())
                .fold(0.0, f64::max);
            writeln!(
                rep,
                "| {case} | {name} | {:+.3} % | {:+.3} % | {:+.3} % | {:.3} % |",
                rel(sm[ipk], sh[ipk]),
                rel(sm[ioff], sh[ioff]),
                rel(sm[ipk] - sm[ioff], sh[ipk] - sh[ioff]),
                max_core
            )?;
        }
    }
    writeln!(
        rep,
        "\nThe model is approximate: it has one band of one isotopologue. Against all HITRAN lines it lacks \
         the hot bands and weak lines under R(16)e, which matter most off-line; use a HITRAN file for \
         retrieval-grade work."
    )?;

    // The constants and their report change together or not at all.
    let mut files = lidarsim::output::OutputSet::new();
    files.write(
        root.join("data/co2_band_model/co2_30012_band.toml"),
        format!(
            "# CO2 30012<-00001 band model constants (lidarsim); written by\n# `cargo run --release --example co2_band_model_fit`; formulas in src/spectroscopy/band_model.rs\n{}",
            toml::to_string(&model)?
        ),
    )?;
    files.write(root.join("validation/co2_band_model/fit_report.md"), &rep)?;
    files.commit()?;
    println!("{rep}");
    Ok(())
}
