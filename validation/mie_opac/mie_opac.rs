//! OPAC components and aerosol types: lidarsim's Mie bulk optics against OPAC's own tables.
//!
//! Prints the Markdown tables of `validation/mie_opac/README.md`:
//! `cargo run --release --example mie_opac [-- --quick]`.

use std::f64::consts::PI;
use std::path::Path;
use std::time::Instant;

use lidarsim::input::CsvTable;
use lidarsim::particles::distribution::BulkOptions;
use lidarsim::particles::opac::{OpacComponent, OpacType};

/// OPAC's tabulated optics (validation/mie_opac/opac_optics_00.csv): component, λ [µm], ext
/// [1/km for 1 cm⁻³], ssa, g.
fn opac_optics() -> Vec<(String, f64, f64, f64, f64)> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("validation/mie_opac/opac_optics_00.csv");
    let t = CsvTable::read(&p).expect("opac_optics_00.csv");
    let c = t.column("component").unwrap();
    let (w, e, s, g) = (
        t.f64_column("wavelength_um").unwrap(),
        t.f64_column("ext_per_km").unwrap(),
        t.f64_column("ssa").unwrap(),
        t.f64_column("g").unwrap(),
    );
    t.rows()
        .enumerate()
        .map(|(i, (_, f))| (f[c].clone(), w[i], e[i], s[i], g[i]))
        .collect()
}

/// OPAC sscm00's volume phase function at 178° and 180° [1/(km sr) for 1 cm⁻³], first 19
/// wavelengths (0.25…2.5 µm), as in USEPA/CMAQ UTIL/inline_phot_preproc/water_clouds/sscm00.
const SSCM_BETA_178: [f64; 19] = [
    1.043e-2, 1.050e-2, 1.065e-2, 9.413e-3, 8.899e-3, 8.917e-3, 8.190e-3, 7.086e-3, 7.030e-3,
    6.756e-3, 6.378e-3, 5.687e-3, 5.364e-3, 4.736e-3, 3.972e-3, 3.134e-3, 3.074e-3, 2.652e-3,
    1.701e-3,
];
const SSCM_BETA_180: [f64; 19] = [
    4.384e-3, 4.197e-3, 4.223e-3, 4.054e-3, 4.271e-3, 4.339e-3, 3.953e-3, 3.926e-3, 4.069e-3,
    4.117e-3, 4.139e-3, 4.003e-3, 4.151e-3, 4.141e-3, 3.863e-3, 3.253e-3, 3.461e-3, 2.934e-3,
    1.912e-3,
];

/// The scattering-angle grid of OPAC's phase-function tables (sscm00): 0–2° by 0.1°, 3–6° by
/// 1°, 8–180° by 2°.
fn opac_angle_grid() -> Vec<f64> {
    let mut v: Vec<f64> = (0..=20).map(|i| i as f64 * 0.1).collect();
    v.extend([3.0, 4.0, 5.0, 6.0]);
    v.extend((4..=90).map(|i| 2.0 * i as f64));
    v
}

/// g from a phase function tabulated at `theta_deg`, trapezoid rule in θ (weights sin θ).
fn g_trapezoid_theta(theta_deg: &[f64], p: &[f64]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for i in 1..theta_deg.len() {
        let (a, b) = (theta_deg[i - 1].to_radians(), theta_deg[i].to_radians());
        let h = 0.5 * (b - a);
        let (fa, fb) = (p[i - 1] * a.sin(), p[i] * b.sin());
        den += h * (fa + fb);
        num += h * (fa * a.cos() + fb * b.cos());
    }
    num / den
}

/// Mass per particle M* [µg m⁻³ per particle cm⁻³] with OPAC's 7.5 µm cutoff: ρ (4π/3) ∫ r³ n
/// dr over [r_min, min(r_max, 7.5)] for N = 1 of the untruncated log-normal (`renormalise`:
/// N = 1 inside [r_min, r_max] instead).
fn mass_per_particle(c: OpacComponent, density_g_cm3: f64, renormalise: bool) -> f64 {
    let p = c.lognormal();
    let d = c.size_distribution(1.0).unwrap();
    let (a, b) = (p.r_min_um.ln(), p.r_max_um.min(7.5).ln());
    let (a_all, b_all) = (p.r_min_um.ln(), p.r_max_um.ln());
    let n = 200_000;
    let (mut v, mut count) = (0.0, 0.0);
    for i in 0..n {
        let r = (a + (i as f64 + 0.5) * (b - a) / n as f64).exp();
        v += d.density(r) * r.powi(4) * (b - a) / n as f64; // dr = r d ln r
        let r2 = (a_all + (i as f64 + 0.5) * (b_all - a_all) / n as f64).exp();
        count += d.density(r2) * r2 * (b_all - a_all) / n as f64;
    }
    let per_particle_um3 = 4.0 / 3.0 * PI * v / if renormalise { count } else { 1.0 };
    // 1 cm⁻³ = 1e6 m⁻³; 1 µm³ = 1e-12 cm³; g → µg: 1e6.
    per_particle_um3 * 1e6 * 1e-12 * density_g_cm3 * 1e6
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let no_phase = BulkOptions {
        angles_deg: Some(Vec::new()),
        ..BulkOptions::default()
    };
    let opac = opac_optics();
    let grid = opac_angle_grid();
    let opac_grid = BulkOptions {
        angles_deg: Some(grid.clone()),
        ..BulkOptions::default()
    };

    println!("## Single components against OPAC (dry, N = 1 cm^-3)\n");
    println!(
        "| component | λ [µm] | ext lidarsim [1/km] | ext OPAC | Δext | ssa lidarsim | ssa OPAC | g lidarsim | g OPAC | Δg | S lidarsim [sr] | radii | s |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut worst = [0.0f64; 3];
    let mut sscm_s = Vec::new();
    for (name, w, ext, ssa, g) in &opac {
        if quick && ![0.5, 0.55, 1.0, 1.25, 1.5].contains(w) {
            continue;
        }
        let c = OpacComponent::from_name(name).unwrap();
        let t0 = Instant::now();
        // Coarse sea salt: also the phase function on OPAC's grid, for P(178°)/P(180°).
        let opts = if c == OpacComponent::Sscm {
            &opac_grid
        } else {
            &no_phase
        };
        let b = c.bulk_optics(1.0, w * 1e-6, opts).unwrap();
        let e = b.extinction_cross_section_m2 * 1e6 * 1e3; // m² × 1e6 m⁻³ → 1/m → 1/km
        let de = e / ext - 1.0;
        let dg = b.asymmetry - g;
        worst[0] = worst[0].max(de.abs());
        worst[1] = worst[1].max((b.single_scattering_albedo - ssa).abs());
        worst[2] = worst[2].max(dg.abs());
        let conv = &b.convergence[0];
        println!(
            "| {name} | {w} | {e:.4e} | {ext:.3e} | {:+.2} % | {:.4} | {ssa:.4} | {:.4} | {g:.3} | {dg:+.4} | {:.2} | {}{} | {:.1} |",
            100.0 * de,
            b.single_scattering_albedo,
            b.asymmetry,
            b.lidar_ratio_sr,
            conv.points,
            if conv.converged {
                ""
            } else {
                " (backscatter not converged)"
            },
            t0.elapsed().as_secs_f64()
        );
        if name == "sscm" {
            let n = b.phase.phase_4pi.len();
            let p178_180 = b.phase.phase_4pi[n - 2] / b.phase.phase_4pi[n - 1];
            sscm_s.push((*w, b.lidar_ratio_sr, p178_180));
        }
    }
    println!(
        "\nWorst: |Δext| {:.2} %, |Δssa| {:.1e}, |Δg| {:.4}\n",
        100.0 * worst[0],
        worst[1],
        worst[2]
    );

    println!("## Coarse sea salt: lidar ratio against OPAC's tabulated β(180°)\n");
    println!(
        "| λ [µm] | S lidarsim [sr] | S OPAC = ext/β(180°) [sr] | P(178°)/P(180°) lidarsim | OPAC |"
    );
    println!("|---|---|---|---|---|");
    let wl: Vec<f64> = opac.iter().filter(|r| r.0 == "sscm").map(|r| r.1).collect();
    for (w, s, r) in &sscm_s {
        let i = wl.iter().position(|x| x == w).unwrap();
        let ext = opac.iter().find(|r| r.0 == "sscm" && r.1 == *w).unwrap().2;
        println!(
            "| {w} | {s:.2} | {:.2} | {r:.2} | {:.2} |",
            ext / SSCM_BETA_180[i],
            SSCM_BETA_178[i] / SSCM_BETA_180[i]
        );
    }

    println!("\n## g from the phase function on OPAC's angle grid (112 angles)\n");
    println!(
        "| component | λ [µm] | g exact (Mie coefficients) | g trapezoid on OPAC's grid | g OPAC |"
    );
    println!("|---|---|---|---|---|");
    let with_grid = BulkOptions {
        angles_deg: Some(grid.clone()),
        rel_tol: 1e-2,
        ..BulkOptions::default()
    };
    for (c, w) in [
        (OpacComponent::Inso, 0.5),
        (OpacComponent::Inso, 1.0),
        (OpacComponent::Sscm, 0.55),
        (OpacComponent::Sscm, 1.5),
        (OpacComponent::Ssam, 0.55),
    ] {
        let b = c.bulk_optics(1.0, w * 1e-6, &with_grid).unwrap();
        let g_grid = g_trapezoid_theta(&grid, &b.phase.phase_4pi);
        let g_opac = opac.iter().find(|r| r.0 == c.name() && r.1 == w).unwrap().4;
        println!(
            "| {} | {w} | {:.4} | {:.4} | {g_opac:.3} |",
            c.name(),
            b.asymmetry,
            g_grid
        );
    }

    println!("\n## Normalisation: mass per particle M* against Hess et al. (1998) Table 1\n");
    println!(
        "| component | ρ [g/cm³] | M* Table 1 | M* (N of the untruncated log-normal) | M* (N inside [r_min, r_max]) |"
    );
    println!("|---|---|---|---|---|");
    for (c, rho, m_table) in [
        (OpacComponent::Inso, 2.0, 23.7),
        (OpacComponent::Waso, 1.8, 1.34e-3),
        (OpacComponent::Soot, 1.0, 5.99e-5),
        (OpacComponent::Ssam, 2.2, 0.802),
        (OpacComponent::Sscm, 2.2, 224.0),
    ] {
        println!(
            "| {} | {rho} | {m_table:.3e} | {:.3e} | {:.3e} |",
            c.name(),
            mass_per_particle(c, rho, false),
            mass_per_particle(c, rho, true)
        );
    }

    println!("\n## Aerosol types (dry components)\n");
    println!(
        "| type | λ [nm] | N [cm^-3] | ⟨Cext⟩ [µm²] | ext [1/km] | ssa | g | S [sr] | ext share of components |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for t in [OpacType::ContinentalAverage, OpacType::MaritimeClean] {
        for w_nm in [532.0, 550.0, 1064.0, 1572.0] {
            let b = t.bulk_optics(w_nm * 1e-9, &no_phase).unwrap();
            let n = t.number_density_per_cm3();
            let shares = t
                .composition()
                .iter()
                .map(|(c, nc)| {
                    let bc = c.bulk_optics(*nc, w_nm * 1e-9, &no_phase).unwrap();
                    let ec = bc.extinction_cross_section_m2 * nc;
                    format!(
                        "{} {:.1} %",
                        c.name(),
                        100.0 * ec / (b.extinction_cross_section_m2 * n)
                    )
                })
                .collect::<Vec<_>>()
                .join(", ");
            println!(
                "| {} | {w_nm} | {n} | {:.4e} | {:.4e} | {:.4} | {:.4} | {:.2} | {shares} |",
                t.name(),
                b.extinction_cross_section_m2 * 1e12,
                b.extinction_cross_section_m2 * n * 1e6 * 1e3,
                b.single_scattering_albedo,
                b.asymmetry,
                b.lidar_ratio_sr
            );
        }
    }

    println!(
        "\n## Types at 550 nm with OPAC's own coefficients where OPAC's files were found (inso, ssam, sscm) and lidarsim's for waso and soot\n"
    );
    println!(
        "| type | ext [1/km] lidarsim | ext [1/km] hybrid | ssa lidarsim | ssa hybrid | g lidarsim | g hybrid |"
    );
    println!("|---|---|---|---|---|---|---|");
    for t in [OpacType::ContinentalAverage, OpacType::MaritimeClean] {
        let (mut e, mut s, mut gs) = (0.0, 0.0, 0.0);
        let (mut eh, mut sh, mut gsh) = (0.0, 0.0, 0.0);
        for (c, nc) in t.composition() {
            let b = c.bulk_optics(1.0, 550e-9, &no_phase).unwrap();
            let ec = b.extinction_cross_section_m2 * 1e9 * nc;
            let sc = ec * b.single_scattering_albedo;
            e += ec;
            s += sc;
            gs += sc * b.asymmetry;
            match opac.iter().find(|r| r.0 == c.name() && r.1 == 0.55) {
                Some((_, _, ext, ssa, g)) => {
                    eh += ext * nc;
                    sh += ext * nc * ssa;
                    gsh += ext * nc * ssa * g;
                }
                None => {
                    eh += ec;
                    sh += sc;
                    gsh += sc * b.asymmetry;
                }
            }
        }
        println!(
            "| {} | {e:.4e} | {eh:.4e} | {:.4} | {:.4} | {:.4} | {:.4} |",
            t.name(),
            s / e,
            sh / eh,
            gs / s,
            gsh / sh
        );
    }
}
