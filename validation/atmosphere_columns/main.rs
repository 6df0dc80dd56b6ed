//! Atmospheric state against independent numbers: prints the AFGL columns against
//! `afgl_column_checks.csv`, the hydrostatic altitudes of the US standard against its table, the
//! shared profile sets' class counts and columns, and the spread of a generated ensemble against
//! the covariance it was drawn from. See README.md beside this file.
//!
//! Run: `cargo run --release --example atmosphere_columns [SHARED_DIR]` (default `../shared`).

use std::path::PathBuf;

use lidarsim::atmosphere::covariance::ErrorModel;
use lidarsim::atmosphere::hydrostatic::{hydrostatic_altitudes_m, normal_gravity_surface_m_per_s2};
use lidarsim::atmosphere::native::{read_ecmwf52, read_ecmwf83, read_rfmip};
use lidarsim::atmosphere::{
    EnsembleConfig, LatitudeClass, ProfileSet, StandardAtmosphere, generate_ensemble,
};
use lidarsim::constants::{
    AVOGADRO_PER_MOL, DOBSON_UNIT_PER_M2, MOLAR_MASS_DRY_AIR_KG_PER_MOL,
    MOLAR_MASS_WATER_KG_PER_MOL,
};

fn main() -> anyhow::Result<()> {
    let shared = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("../shared"));
    let data = shared.join("data");

    println!("## AFGL columns vs afgl_column_checks.csv (relative deviation)");
    let checks = std::fs::read_to_string(data.join("afgl/afgl_column_checks.csv"))?;
    println!("| atmosphere | air column [cm-2] | dev | PW [cm] | dev | O3 [DU] | dev |");
    println!("|---|---|---|---|---|---|---|");
    for a in StandardAtmosphere::ALL {
        let key = if a == StandardAtmosphere::UsStandard {
            "us_standard_ussa76fix"
        } else {
            a.name()
        };
        let row: Vec<f64> = checks
            .lines()
            .find(|l| l.split(',').next() == Some(key))
            .expect("row")
            .split(',')
            .skip(1)
            .map(|v| v.parse().unwrap())
            .collect();
        let p = a.profile();
        let air = p.air_column_per_m2() * 1e-4;
        let pw = p.precipitable_water_kg_per_m2()? / 10.0;
        let du = p.gas_column_per_m2("O3")? / DOBSON_UNIT_PER_M2;
        println!(
            "| {} | {air:.4e} | {:+.2e} | {pw:.3} | {:+.2e} | {du:.1} | {:+.2e} |",
            a.name(),
            air / row[1] - 1.0,
            pw / row[3] - 1.0,
            du / row[4] - 1.0
        );
    }

    println!("\n## US standard: hydrostatic altitude − table altitude (45°N, WGS 84 gravity)");
    let p = StandardAtmosphere::UsStandard.profile();
    let z = hydrostatic_altitudes_m(&p.pressure_pa, &p.temperature_k, p.gas("H2O"), 0.0, 45.0)?;
    for (zk, t) in z.iter().zip(&p.altitude_m) {
        if *t > 0.0 && (t % 10e3 == 0.0 || *t > 80e3) {
            println!(
                "{:>5.0} km: {:+8.1} m ({:+.2e})",
                t / 1e3,
                zk - t,
                (zk - t) / t
            );
        }
    }

    let (mut worst_abs, mut worst_rel) = (0.0f64, 0.0f64);
    for (zk, t) in z.iter().zip(&p.altitude_m).skip(1) {
        if *t <= 100e3 {
            worst_abs = worst_abs.max((zk - t).abs());
            worst_rel = worst_rel.max(((zk - t) / t).abs());
        }
    }
    println!("up to 100 km: worst {worst_abs:.1} m, worst relative {worst_rel:.2e}");

    println!("\n## Profile sets: counts per class and hydrostatic air column");
    let sets: Vec<ProfileSet> = vec![
        read_ecmwf83(
            &data.join("profiles/ecmwf83_matricardi2008_101L.csv"),
            &data.join("profiles/ecmwf83_matricardi2008_meta.csv"),
        )?,
        read_ecmwf52(
            &data.join("profiles/ecmwf52_chevallier_101L.csv"),
            &data.join("profiles/ecmwf52_chevallier_meta.csv"),
        )?,
        read_rfmip(
            &data.join("profiles/rfmip_era_interim_100sites_layers.csv"),
            &data.join("profiles/rfmip_era_interim_100sites_meta.csv"),
        )?,
    ];
    for s in &sets {
        let [t, m, h] = s.class_counts();
        let mut worst: f64 = 0.0;
        for mem in &s.members {
            let pr = &mem.profile;
            let nw =
                pr.precipitable_water_kg_per_m2()? / MOLAR_MASS_WATER_KG_PER_MOL * AVOGADRO_PER_MOL;
            let g = normal_gravity_surface_m_per_s2(mem.meta.latitude_deg);
            let expect = pr.surface_pressure_pa()
                / (g * MOLAR_MASS_DRY_AIR_KG_PER_MOL / AVOGADRO_PER_MOL)
                + nw * (1.0 - MOLAR_MASS_WATER_KG_PER_MOL / MOLAR_MASS_DRY_AIR_KG_PER_MOL);
            worst = worst.max((pr.air_column_per_m2() / expect - 1.0).abs());
        }
        let pw: Vec<f64> = s
            .members
            .iter()
            .map(|m| m.profile.precipitable_water_kg_per_m2().unwrap())
            .collect();
        println!(
            "{}: {} profiles ({t} tropical, {m} mid, {h} high); air column vs p_s/(g m_d) + water: worst {:.2e}; PW {:.1}–{:.1} mm",
            s.name,
            s.len(),
            worst,
            pw.iter().cloned().fold(f64::INFINITY, f64::min),
            pw.iter().cloned().fold(0.0, f64::max)
        );
        for c in LatitudeClass::ALL {
            let sub = s.class(c);
            if let Ok(mean) = sub.mean_member() {
                println!(
                    "    {c:>8} mean: p_s {:.1} hPa, T_s {:.1} K, PW {:.1} mm",
                    mean.profile.surface_pressure_pa() / 100.0,
                    mean.profile.temperature_k[0],
                    mean.profile.precipitable_water_kg_per_m2()?
                );
            }
        }
    }

    println!("\n## Ensemble: 20000 tropical members, sample std of T and ln q vs the covariance");
    let mean = StandardAtmosphere::Tropical.member();
    let cov = ErrorModel::representative()
        .scaled_for_class(LatitudeClass::Tropical)
        .covariance(&mean.profile)?;
    let n = 20_000;
    let t0 = std::time::Instant::now();
    let (set, report) = generate_ensemble(&mean, &cov, &EnsembleConfig::new(n, 1))?;
    let secs = t0.elapsed().as_secs_f64();
    let nl = mean.profile.len();
    for k in [0, 2, 5, 10, 15, 20, 30] {
        let dt: Vec<f64> = set
            .members
            .iter()
            .map(|m| m.profile.temperature_k[k] - mean.profile.temperature_k[k])
            .collect();
        let sd = (dt.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
        let sigma = cov.matrix[(k, k)].sqrt();
        println!(
            "level {k:>2} ({:>7.2} hPa): σ_T {sigma:.3} K, sample {sd:.3} K (ratio {:.4}, standard error of the ratio {:.4}); σ_lnq {:.3}",
            mean.profile.pressure_pa[k] / 100.0,
            sd / sigma,
            1.0 / (2.0 * n as f64).sqrt(),
            cov.matrix[(nl + k, nl + k)].sqrt()
        );
    }
    println!(
        "capped at 100 % RH: {} of {} values; repair: {:?}; {n} members in {secs:.2} s",
        report.capped_values,
        report.total_values,
        report.repair.map(|r| r.to_string())
    );
    Ok(())
}
