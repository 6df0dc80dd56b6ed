//! Mie solver and size distributions against independent codes and published values.
//!
//! Truth: `../shared/reference/mie_reference.csv` (miepython 3.3.0, Wiscombe's MIEV0 test
//! values, Bohren & Huffman's BHMIE output, scattnlay; PyMieScatt rows for x < 100 — the file
//! flags PyMieScatt as wrong for x ≥ 100 and those rows are skipped) and
//! `../shared/reference/c1_summary.csv` (Deirmendjian C.1 by miepython).

use std::path::Path;

use lidarsim::input::CsvTable;
use lidarsim::particles::distribution::{BulkOptions, SizeDistribution, bulk_optics};
use lidarsim::particles::mie::{MieCoefficients, MieResult};
use lidarsim::particles::table::PhaseTable;
use num_complex::Complex64;

use crate::util::shared_file;

pub(crate) struct Row {
    pub(crate) case: String,
    pub(crate) source: String,
    pub(crate) m: Complex64,
    pub(crate) x: f64,
    pub(crate) quantity: String,
    pub(crate) theta_deg: Option<f64>,
    pub(crate) re_text: String,
    pub(crate) value: Complex64,
}

pub(crate) fn read_reference(path: &Path) -> Vec<Row> {
    let t = CsvTable::read(path).unwrap();
    let col = |n: &str| t.column(n).unwrap();
    let (c_case, c_src, c_mr, c_mi, c_x, c_q, c_th, c_vr, c_vi) = (
        col("case"),
        col("source"),
        col("m_real"),
        col("m_imag"),
        col("x"),
        col("quantity"),
        col("theta_deg"),
        col("value_real"),
        col("value_imag"),
    );
    t.rows()
        .map(|(_, f)| {
            let num = |s: &str| -> f64 {
                if s.is_empty() {
                    0.0
                } else {
                    s.parse().unwrap()
                }
            };
            Row {
                case: f[c_case].clone(),
                source: f[c_src].clone(),
                m: Complex64::new(num(&f[c_mr]), num(&f[c_mi])),
                x: num(&f[c_x]),
                quantity: f[c_q].clone(),
                theta_deg: if f[c_th].is_empty() {
                    None
                } else {
                    Some(num(&f[c_th]))
                },
                re_text: f[c_vr].clone(),
                value: Complex64::new(num(&f[c_vr]), num(&f[c_vi])),
            }
        })
        .collect()
}

/// Half a unit in the last significant digit printed (`digits` significant digits, or as many as
/// the text shows once trailing zeros are dropped when `digits` is None).
pub(crate) fn half_unit(text: &str, digits: Option<i32>) -> f64 {
    let v: f64 = text.parse().unwrap();
    if v == 0.0 {
        return 0.0;
    }
    let e = v.abs().log10().floor() as i32;
    let d = digits.unwrap_or_else(|| {
        let mant = text.split(['e', 'E']).next().unwrap();
        let digits: String = mant.chars().filter(|c| c.is_ascii_digit()).collect();
        let t = digits.trim_start_matches('0').trim_end_matches('0');
        t.len().max(1) as i32
    });
    0.5 * 10f64.powi(e - d + 1)
}

pub(crate) fn coefficients(m: Complex64, x: f64) -> MieCoefficients {
    if m.re == 0.0 && m.im == 0.0 {
        // m = 0 marks MIEV0's perfectly conducting sphere in the reference file.
        MieCoefficients::perfect_conductor(x).unwrap()
    } else {
        MieCoefficients::compute(m, x).unwrap()
    }
}

/// Every reference value not flagged as wrong: efficiencies and g to 1e-6 relative (or half a
/// unit of the last digit the source printed, when that is coarser: MIEV0 tables give 7
/// significant digits, the older MIEV0 and BH values 4–6), amplitudes to 1e-5 of the case's
/// largest amplitude |S1(0°)| (or the printed precision).
#[test]
fn mie_agrees_with_reference_codes() {
    let Some(path) = shared_file("reference/mie_reference.csv") else {
        return;
    };
    let rows = read_reference(&path);
    let mut checked = 0;
    let mut worst_eff: f64 = 0.0;
    let mut worst_amp: f64 = 0.0;
    let mut worst_full_precision: f64 = 0.0;
    let mut failures = Vec::new();
    for r in &rows {
        let pymie = r.source.starts_with("PyMieScatt");
        if pymie && r.x >= 100.0 {
            continue; // flagged as wrong in the file header
        }
        let miev0_table = r.source.starts_with("Wiscombe MIEV0 MVTstNew.f tabulated");
        let digits = if miev0_table && !r.source.contains("via miepython") {
            Some(7)
        } else if r.source.starts_with("miepython 3.3.0")
            || r.source.starts_with("scattnlay")
            || pymie
        {
            Some(16)
        } else {
            None
        };
        // BH Appendix A prints the size parameter rounded to 5.213; its numbers are for
        // x = 2π·0.525/0.6328 = 5.212819669 (the same sphere as case BH_m1.55).
        let x = if r.case == "BH_appendixA" {
            2.0 * std::f64::consts::PI * 0.525 / 0.6328
        } else {
            r.x
        };
        let k = coefficients(r.m, x);
        let e: MieResult = k.efficiencies();
        let (s1_0, _) = k.amplitudes(&[1.0]).unwrap();
        let s_max = s1_0[0].norm();
        let mu = r.theta_deg.map(|t| t.to_radians().cos());
        let scalar = |ours: f64, extra_tol: f64| -> (f64, f64) {
            let tol = (1e-6 * r.value.re.abs()).max(half_unit(&r.re_text, digits)) + extra_tol;
            (ours, tol)
        };
        let (ours, tol, is_amp) = match r.quantity.as_str() {
            "Qext" | "4ReS(0)/x^2" => {
                let (o, t) = scalar(e.qext, 0.0);
                (Complex64::new(o, 0.0), t, false)
            }
            "Qsca" => {
                let (o, t) = scalar(e.qsca, 0.0);
                (Complex64::new(o, 0.0), t, false)
            }
            "Qback" | "4|S1(180)|^2/x^2" => {
                let (o, t) = scalar(e.qback, 0.0);
                (Complex64::new(o, 0.0), t, false)
            }
            "ssa" => {
                let (o, t) = scalar(e.ssa, 0.0);
                (Complex64::new(o, 0.0), t, false)
            }
            "g*Qsca" => {
                let (o, t) = scalar(e.g * e.qsca, 0.0);
                (Complex64::new(o, 0.0), t, false)
            }
            "g" => {
                let mut extra = 0.0;
                if r.note_derived() {
                    // g = GQSC/QSCA from two 7-digit values: propagate their rounding.
                    extra = r.value.re.abs()
                        * (5e-7 / (e.g * e.qsca).abs()
                            * 10f64.powf((e.g * e.qsca).abs().log10().floor())
                            + 5e-7 / e.qsca * 10f64.powf(e.qsca.log10().floor()));
                }
                let (o, t) = scalar(e.g, extra);
                (Complex64::new(o, 0.0), t, false)
            }
            "S1" | "S2" => {
                let (s1, s2) = k.amplitudes(&[mu.unwrap()]).unwrap();
                let mut s = if r.quantity == "S1" { s1[0] } else { s2[0] };
                if pymie {
                    s = s.conj(); // BHMIE/PyMieScatt amplitudes are the conjugates
                }
                let printed = half_unit(&r.re_text, digits);
                (s, (1e-5 * s_max).max(2.0 * printed), true)
            }
            "|S1(180)|^2" => {
                let (s1, _) = k.amplitudes(&[-1.0]).unwrap();
                let (o, t) = scalar(s1[0].norm_sqr(), 0.0);
                (Complex64::new(o, 0.0), t, false)
            }
            "P11_4pi" => {
                let (s1, s2) = k.amplitudes(&[mu.unwrap()]).unwrap();
                let p = 2.0 * (s1[0].norm_sqr() + s2[0].norm_sqr()) / (r.x * r.x * e.qsca);
                // P is quadratic in S: 1e-5 of the largest amplitude → 2e-5 |S| s_max relative.
                let p_max = 4.0 * s_max * s_max / (r.x * r.x * e.qsca);
                (
                    Complex64::new(p, 0.0),
                    (2e-5 * p_max.sqrt() * p.sqrt()).max(1e-6 * p),
                    true,
                )
            }
            "S11/S11(0)" | "POL=-S12/S11" | "S33/S11" | "S34/S11" => {
                // BH's Mueller elements from BH amplitudes (conjugates of ours), BH Eq. 4.77.
                let (s1, s2) = k.amplitudes(&[mu.unwrap(), 1.0]).unwrap();
                let (a1, a2) = (s1[0].conj(), s2[0].conj());
                let s11 = 0.5 * (a2.norm_sqr() + a1.norm_sqr());
                let s11_0 = 0.5 * (s2[1].norm_sqr() + s1[1].norm_sqr());
                let v = match r.quantity.as_str() {
                    "S11/S11(0)" => s11 / s11_0,
                    "POL=-S12/S11" => -0.5 * (a2.norm_sqr() - a1.norm_sqr()) / s11,
                    "S33/S11" => (a2 * a1.conj()).re / s11,
                    _ => (a2 * a1.conj()).im / s11,
                };
                (
                    Complex64::new(v, 0.0),
                    half_unit(&r.re_text, None).max(1e-6 * v.abs()),
                    false,
                )
            }
            q => panic!("unknown quantity {q}"),
        };
        // Rows computed by Wiscombe's small-particle approximation rather than the series
        // (MIEV0 for a perfect conductor at x < 0.1; MIEV0 and miepython for |m|x < 0.1) carry
        // that approximation's error, which the exact series at 50 digits (mpmath, see
        // validation/mie_reference/mp_small_x.py) exposes: 5.2e-5 in Qsca (case 1) and 1.4e-6 in
        // g (cases 5, 6). Those rows are held to that error; our values are checked against
        // the 50-digit series in `mie_small_x_matches_50_digit_series`.
        let small_particle_rows = (r.case == "MIEV0_case1")
            || ((r.case == "MIEV0_case5" || r.case == "MIEV0_case6")
                && (r.quantity == "g" || r.quantity == "g*Qsca"));
        let tol = if small_particle_rows {
            tol.max(6e-5 * r.value.re.abs())
        } else {
            tol
        };
        let err = (ours - r.value).norm();
        if is_amp {
            worst_amp = worst_amp.max(err / s_max);
        } else if r.value.re != 0.0 {
            worst_eff = worst_eff.max(err / r.value.re.abs());
            // miepython's own small-sphere approximation is used for |m|x < 0.1.
            if digits == Some(16) && !small_particle_rows && r.m.norm() * r.x >= 0.1 {
                worst_full_precision = worst_full_precision.max(err / r.value.re.abs());
            }
        }
        if err > tol || err.is_nan() {
            failures.push(format!(
                "{} [{}] {} θ={:?}: ours {} ref {} |diff| {:.3e} > tol {:.3e}",
                r.case, r.source, r.quantity, r.theta_deg, ours, r.value, err, tol
            ));
        }
        checked += 1;
    }
    println!(
        "checked {checked} reference values; worst relative efficiency/g difference {worst_eff:.2e} (full-precision series values, |m|x ≥ 0.1: {worst_full_precision:.2e}), worst amplitude difference {worst_amp:.2e} of |S1(0)|"
    );
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures.join("\n")
    );
    assert!(checked > 900);
}

/// The exact series at 50 significant digits (mpmath; `validation/mie_reference/mp_small_x.py`)
/// for the small-x reference cases: ours must agree to 1e-12 relative.
#[test]
fn mie_small_x_matches_50_digit_series() {
    let cases = [
        (None, 0.099, 3.20950856452935e-4, -0.397369081473419),
        (None, 0.101, 3.47716034170673e-4, -0.397262081329665),
        (Some(0.75), 0.099, 7.41785911491223e-6, 0.00144823098825353),
        (Some(0.75), 0.101, 8.0335381485571e-6, 0.00150742992618113),
    ];
    for (m, x, qsca, g) in cases {
        let k = match m {
            None => MieCoefficients::perfect_conductor(x).unwrap(),
            Some(m) => MieCoefficients::compute(Complex64::new(m, 0.0), x).unwrap(),
        };
        let e = k.efficiencies();
        assert!(
            ((e.qsca - qsca) / qsca).abs() < 1e-12,
            "{m:?} {x}: {} vs {qsca}",
            e.qsca
        );
        assert!(((e.g - g) / g).abs() < 1e-12, "{m:?} {x}: {} vs {g}", e.g);
    }
}

impl Row {
    fn note_derived(&self) -> bool {
        self.case.starts_with("MIEV0_case") && self.source.starts_with("Wiscombe")
    }
}

/// Stability across the whole range: x from 1e-3 (Rayleigh limit) to 2e4, absorbing and not.
/// Truth: the Rayleigh-limit formulas (BH Eqs. 5.8, 5.9: Qsca = (8/3) x⁴ |(m²−1)/(m²+2)|²,
/// Qabs = 4x Im((m²−1)/(m²+2)), Qback = 4x⁴|(m²−1)/(m²+2)|², g → 0) at x = 1e-3, where the
/// next terms are O(x²) = 1e-6 relative; and for large x, the extinction paradox Qext → 2
/// (van de Hulst 1957 §12.3: Qext = 2 + O(x^(−2/3)) — within 1 % at x = 2e4) and energy
/// conservation Qsca ≤ Qext, 0 ≤ g ≤ 1, all finite.
#[test]
fn mie_is_stable_from_1e_3_to_2e4() {
    for m in [
        Complex64::new(1.33, 0.0),
        Complex64::new(1.5, 0.01),
        Complex64::new(1.75, 0.44),
    ] {
        let x = 1e-3;
        let r = lidarsim::particles::mie::mie(m, x).unwrap();
        let l = (m * m - 1.0) / (m * m + 2.0);
        let qsca = 8.0 / 3.0 * x.powi(4) * l.norm_sqr();
        let qabs = 4.0 * x * l.im;
        assert!(
            ((r.qsca - qsca) / qsca).abs() < 1e-5,
            "{m}: {} vs {qsca}",
            r.qsca
        );
        assert!(((r.qext - (qsca + qabs)) / (qsca + qabs)).abs() < 1e-5);
        assert!(((r.qback - 4.0 * x.powi(4) * l.norm_sqr()) / r.qback).abs() < 1e-5);
        assert!(r.g.abs() < 1e-5);
        for x in [0.1, 1.0, 10.0, 100.0, 1000.0, 5000.0, 20000.0] {
            let r = lidarsim::particles::mie::mie(m, x).unwrap();
            assert!(
                r.qext.is_finite() && r.qsca.is_finite() && r.qback.is_finite() && r.g.is_finite()
            );
            assert!(
                r.qsca <= r.qext * (1.0 + 1e-12) && r.qsca > 0.0,
                "{m} {x}: {r:?}"
            );
            assert!(r.g > -1.0 && r.g < 1.0);
            if x >= 20000.0 {
                assert!((r.qext - 2.0).abs() < 0.02, "{m} {x}: {}", r.qext);
            }
        }
    }
}

/// Deirmendjian C.1 at 1064 nm (m = 1.3205 + 1.28e-6 i): lidar ratio 19.59 sr and g 0.8371
/// (miepython, converged, `c1_summary.csv`) within 0.5 % (the issue's requirement); extinction
/// per droplet 172.3447 µm² and single-scattering albedo 0.9999076 within 0.1 %; the table's
/// phase function against `c1_phase_1064.csv` within 2 % at every angle (narrow resonances
/// leave ~0.5 % scatter in the backward hemisphere even when converged).
#[test]
fn c1_bulk_optics_match_miepython() {
    let Some(summary) = shared_file("reference/c1_summary.csv") else {
        return;
    };
    let t = CsvTable::read(&summary).unwrap();
    let lam = t.f64_column("lambda_nm").unwrap();
    let row = lam.iter().position(|&l| l == 1064.0).unwrap();
    let get = |c: &str| t.f64_column(c).unwrap()[row];
    let m = Complex64::new(get("m_real"), get("m_imag"));
    let c1 = SizeDistribution::deirmendjian_c1();
    let ref_phase = shared_file("reference/c1_phase_1064.csv").map(|p| CsvTable::read(&p).unwrap());
    let opts = BulkOptions {
        angles_deg: ref_phase
            .as_ref()
            .map(|t| t.f64_column("theta_deg").unwrap()),
        ..BulkOptions::default()
    };
    let b = bulk_optics(&c1, m, 1064e-9, &opts).unwrap();
    let rel = |a: f64, b: f64| ((a - b) / b).abs();
    println!(
        "C.1 1064 nm: Cext {:.4} um2, ssa {:.7}, g {:.5}, S {:.3} sr; {:?}",
        b.extinction_cross_section_m2 * 1e12,
        b.single_scattering_albedo,
        b.asymmetry,
        b.lidar_ratio_sr,
        b.convergence
    );
    assert!(rel(b.lidar_ratio_sr, get("lidar_ratio_sr")) < 5e-3);
    assert!(rel(b.asymmetry, get("g")) < 5e-3);
    assert!(rel(b.extinction_cross_section_m2 * 1e12, get("mean_Cext_um2")) < 1e-3);
    assert!(rel(b.single_scattering_albedo, get("ssa")) < 1e-3);
    assert!(b.convergence.iter().all(|c| c.converged));
    if let Some(rt) = ref_phase {
        let p_ref = rt.f64_column("P11_4pi").unwrap();
        let worst = b
            .phase
            .phase_4pi
            .iter()
            .zip(&p_ref)
            .map(|(a, r)| rel(*a, *r))
            .fold(0.0, f64::max);
        println!("C.1 1064 nm phase function: max relative difference {worst:.2e}");
        assert!(worst < 2e-2);
    }
    // The table round-trips through the file format and is normalised.
    let back = PhaseTable::parse(Path::new("c1.txt"), &b.phase.to_text()).unwrap();
    assert!((back.normalisation() - 1.0).abs() < 1e-3);
}

/// Item 6: `lidarsim mie --refractive-index 1.33+0.0i --size-parameter X` prints JSON with qext,
/// qsca, qback, g (truth: miepython 3.3 values for m = 1.33, x = 10 in mie_reference.csv,
/// 1e-9 relative); a negative imaginary part and a malformed index are refused with exit code 2.
#[test]
fn cli_mie_single_sphere_json() {
    let stdout = crate::util::lidarsim_ok([
        "mie",
        "--refractive-index",
        "1.33+0.0i",
        "--size-parameter",
        "10",
    ]);
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    for (k, want) in [
        ("qext", 2.206548710184618),
        ("qsca", 2.206548710184618),
        ("qback", 5.611794296163873e-01),
        ("g", 7.124592696732813e-01),
    ] {
        let got = v[k].as_f64().unwrap();
        assert!(((got - want) / want).abs() < 1e-9, "{k}: {got} vs {want}");
    }
    for bad in ["1.33-0.1i", "1.33+xi"] {
        let out =
            crate::util::lidarsim(["mie", "--refractive-index", bad, "--size-parameter", "10"]);
        assert_eq!(out.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&out.stderr).contains("refractive"));
    }
}

/// OPAC's own optical properties of single dry components (OPAC files inso00, ssam00, sscm00 as
/// copied in USEPA/CMAQ; `validation/mie_opac/opac_optics_00.csv`), for 1 particle cm⁻³ of the
/// log-normal truncated to OPAC's [r_min, r_max]: extinction within 1 %, single-scattering
/// albedo within 1e-3 and g within 0.006. OPAC prints 4 digits (ext, ssa) and 3 (g) and used a
/// coarse size and angle integration: its extinction ripples by a few 0.1 % from one wavelength
/// to the next, and its g is up to 0.005 above the exact Mie g for the coarse components at
/// 0.5 µm (see validation/mie_opac/README.md; worst here: 0.50 %, 5e-4, 0.0052; over all 19
/// wavelengths 0.25–2.5 µm: 0.50 %, 8.4e-4, 0.0075 at 0.25 µm). Coarse sea
/// salt is checked at λ ≥ 1 µm only: below, its backscatter (which the integrator also
/// converges) needs 0.6–1.9e5 radii and several seconds; `validation/mie_opac` covers all 19
/// wavelengths.
#[test]
fn opac_components_match_opac_tables() {
    use lidarsim::particles::opac::OpacComponent;
    let path = crate::util::project_root().join("validation/mie_opac/opac_optics_00.csv");
    let t = CsvTable::read(&path).unwrap();
    let c = t.column("component").unwrap();
    let (w, ext, ssa, g) = (
        t.f64_column("wavelength_um").unwrap(),
        t.f64_column("ext_per_km").unwrap(),
        t.f64_column("ssa").unwrap(),
        t.f64_column("g").unwrap(),
    );
    let opts = BulkOptions {
        angles_deg: Some(Vec::new()),
        ..BulkOptions::default()
    };
    let mut checked = 0;
    for (i, (_, f)) in t.rows().enumerate() {
        let comp = OpacComponent::from_name(&f[c]).unwrap();
        let wanted: &[f64] = if comp == OpacComponent::Sscm {
            &[1.0, 1.25, 1.5]
        } else {
            &[0.5, 0.55, 1.0, 1.25, 1.5]
        };
        if !wanted.contains(&w[i]) {
            continue;
        }
        let b = comp.bulk_optics(1.0, w[i] * 1e-6, &opts).unwrap();
        // Per particle [m²] × 1 cm⁻³ = 1e6 m⁻³ → 1/m; × 1e3 → 1/km.
        let e = b.extinction_cross_section_m2 * 1e9;
        let de = e / ext[i] - 1.0;
        let ds = b.single_scattering_albedo - ssa[i];
        let dg = b.asymmetry - g[i];
        println!(
            "{} {} um: ext {e:.4e} vs {:.3e} ({:+.2} %), ssa {:+.1e}, g {:+.4}",
            f[c],
            w[i],
            ext[i],
            100.0 * de,
            ds,
            dg
        );
        assert!(
            de.abs() < 1e-2,
            "{} {} um: extinction {de:+.3e}",
            f[c],
            w[i]
        );
        assert!(ds.abs() < 1e-3, "{} {} um: ssa {ds:+.3e}", f[c], w[i]);
        assert!(dg.abs() < 6e-3, "{} {} um: g {dg:+.4}", f[c], w[i]);
        checked += 1;
    }
    assert_eq!(checked, 13);
}

/// OPAC's normalisation: N counts the particles of the untruncated log-normal. Hess et al. (1998)
/// Table 1 gives the mass per particle M* = ρ (4π/3) ∫ r³ n dr (N = 1 cm⁻³, radii up to
/// 7.5 µm) to 3 digits; the shipped component distributions reproduce all five within 1 %
/// (rounding 0.2 % plus OPAC's own quadrature), while counting N only inside [r_min, r_max]
/// would miss waso by 4 % and soot by 12 %.
#[test]
fn opac_distributions_reproduce_table_1_mass() {
    use lidarsim::particles::opac::OpacComponent;
    use std::f64::consts::PI;
    // (component, density g/cm³, M* µg m⁻³ per particle cm⁻³) — Hess et al. (1998), Table 1.
    for (comp, rho, m_table) in [
        (OpacComponent::Inso, 2.0, 23.7),
        (OpacComponent::Waso, 1.8, 1.34e-3),
        (OpacComponent::Soot, 1.0, 5.99e-5),
        (OpacComponent::Ssam, 2.2, 0.802),
        (OpacComponent::Sscm, 2.2, 224.0),
    ] {
        let p = comp.lognormal();
        let d = comp.size_distribution(1.0).unwrap();
        // Midpoint rule in ln r (dr = r d ln r), 1e5 steps: quadrature error ≪ 1e-6.
        let integral = |lo: f64, hi: f64, k: i32| -> f64 {
            let (a, b, n) = (lo.ln(), hi.ln(), 100_000);
            let h = (b - a) / n as f64;
            (0..n)
                .map(|i| {
                    let r = (a + (i as f64 + 0.5) * h).exp();
                    d.density(r) * r.powi(k + 1) * h
                })
                .sum()
        };
        let v = 4.0 / 3.0 * PI * integral(p.r_min_um, p.r_max_um.min(7.5), 3);
        // µm³ per particle → µg m⁻³ per particle cm⁻³: × 1e6 (cm⁻³ → m⁻³) × 1e-12 (µm³ → cm³)
        // × ρ × 1e6 (g → µg).
        let m = v * rho;
        let inside = integral(p.r_min_um, p.r_max_um, 0);
        println!(
            "{}: M* {m:.4e} (Table 1: {m_table:.3e}); N inside [r_min, r_max] = {inside:.4}",
            comp.name()
        );
        assert!((m / m_table - 1.0).abs() < 1e-2, "{}", comp.name());
        if matches!(comp, OpacComponent::Waso | OpacComponent::Soot) {
            assert!((m / inside / m_table - 1.0).abs() > 3e-2);
        }
    }
}

/// The shipped OPAC tables (`phase_functions/{continental_average,maritime_clean}_*nm.txt`) are
/// valid tables that resolve their phase function: g by quadrature over the table (linear in
/// cos θ between nodes) within 2e-4 of the exact g in their metadata (found ≤ 1e-5), P(180°)
/// equal to the backscatter of the metadata (4π/(ssa·S)) within 1e-6 (the metadata carry 9
/// digits), and dry (relative_humidity_percent = 0).
#[test]
fn shipped_opac_tables_are_consistent() {
    for name in ["continental_average", "maritime_clean"] {
        for nm in [532, 1064, 1572] {
            let path =
                crate::util::project_root().join(format!("phase_functions/{name}_{nm}nm.txt"));
            let t = PhaseTable::read(&path).unwrap();
            let meta = |k: &str| -> f64 { t.meta(k).unwrap().parse().unwrap() };
            assert_eq!(meta("wavelength_nm"), nm as f64);
            assert_eq!(t.meta("relative_humidity_percent"), Some("0"));
            let (ssa, g, s) = (
                meta("single_scattering_albedo"),
                meta("asymmetry"),
                meta("lidar_ratio_sr"),
            );
            // ∫ P cos θ dΩ / 4π with P linear in μ = cos θ between nodes (exact for that rule).
            let mu: Vec<f64> = t.theta_deg.iter().map(|d| d.to_radians().cos()).collect();
            let (mut num, mut den) = (0.0, 0.0);
            for i in 1..mu.len() {
                let (a, b) = (mu[i - 1], mu[i]);
                let (pa, pb) = (t.phase_4pi[i - 1], t.phase_4pi[i]);
                let h = a - b;
                den += 0.5 * h * (pa + pb);
                // ∫ μ P dμ over [b, a] for linear P: h/6 (2a pa + a pb + b pa + 2b pb).
                num += h / 6.0 * (2.0 * a * pa + a * pb + b * pa + 2.0 * b * pb);
            }
            let g_quad = num / den;
            let p180 = *t.phase_4pi.last().unwrap();
            let p180_meta = 4.0 * std::f64::consts::PI / (ssa * s);
            println!(
                "{name} {nm} nm: g {g:.5} vs quadrature {g_quad:.5}; P(180) {p180:.6} vs {p180_meta:.6}"
            );
            assert!((g_quad - g).abs() < 2e-4, "{name} {nm}");
            assert!((p180 / p180_meta - 1.0).abs() < 1e-6, "{name} {nm}");
        }
    }
}

/// Every table in phase_functions/ is compiled in as a built-in (so scenes can name it without a
/// path) and parses.
#[test]
fn every_shipped_table_is_a_builtin() {
    let dir = crate::util::project_root().join("phase_functions");
    let mut on_disk: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| {
            let p = e.unwrap().path();
            (p.extension()? == "txt").then(|| p.file_stem().unwrap().to_string_lossy().into_owned())
        })
        .collect();
    on_disk.sort();
    let mut builtin: Vec<String> = lidarsim::particles::builtin_table_names()
        .iter()
        .map(|s| s.to_string())
        .collect();
    builtin.sort();
    assert_eq!(on_disk, builtin);
    for name in &builtin {
        lidarsim::particles::builtin_table(name).unwrap();
    }
}

/// Every Mie computation the project ships or validates with is at least a hundredfold below
/// the limits of Mie work and angle-table size (README, "Limits"): the C.1 tables and the
/// polarisation scenes' C.1 at 532 nm (`validation/mie_c1`, `validation/polarisation`), the
/// OPAC type tables (`validation/mie_opac`, maritime clean at 532 nm the largest), and the
/// OPAC component validation at OPAC's 19 wavelengths, coarse sea salt with OPAC's 111-angle
/// grid. The bound is milliseconds of arithmetic, so all of them are checked.
#[test]
fn shipped_mie_work_is_a_hundredfold_below_the_limits() {
    use lidarsim::limits::{MAX_MIE_ANGLE_TABLE_VALUES, MAX_MIE_WORK};
    use lidarsim::particles::distribution::{Component, MieWork, mie_work};
    use lidarsim::particles::opac::{OpacComponent, OpacType};
    let defaults = BulkOptions::default();
    let no_phase = BulkOptions {
        angles_deg: Some(Vec::new()),
        ..BulkOptions::default()
    };
    let mut opac_grid: Vec<f64> = (0..=20).map(|i| i as f64 * 0.1).collect();
    opac_grid.extend([3.0, 4.0, 5.0, 6.0]);
    opac_grid.extend((4..=90).map(|i| 2.0 * i as f64));
    let opac_grid = BulkOptions {
        angles_deg: Some(opac_grid),
        ..BulkOptions::default()
    };
    let mut cases: Vec<(String, MieWork)> = Vec::new();
    let c1 = |m: Complex64| Component {
        name: "c1".into(),
        distribution: SizeDistribution::deirmendjian_c1(),
        refractive_index: m,
    };
    for (w, m) in [
        (532.0, Complex64::new(1.3371, 1.8e-9)),
        (532.0, Complex64::new(1.334, 1.5e-9)),
        (1064.0, Complex64::new(1.3205, 1.28e-6)),
        (1572.0, Complex64::new(1.3103, 1.13e-4)),
    ] {
        let work = mie_work(&[c1(m)], w * 1e-9, &defaults).unwrap();
        cases.push((format!("C.1 {w} nm"), work));
    }
    for t in [OpacType::ContinentalAverage, OpacType::MaritimeClean] {
        for w in [532.0, 550.0, 1064.0, 1572.0] {
            let comps = t.components(w * 1e-9).unwrap();
            let work = mie_work(&comps, w * 1e-9, &defaults).unwrap();
            cases.push((format!("{} {w} nm", t.name()), work));
        }
    }
    let t =
        CsvTable::read(&crate::util::project_root().join("validation/mie_opac/opac_optics_00.csv"))
            .unwrap();
    let wavelengths_um = t.f64_column("wavelength_um").unwrap();
    for c in [
        OpacComponent::Inso,
        OpacComponent::Ssam,
        OpacComponent::Sscm,
    ] {
        for w in &wavelengths_um {
            let opts = if c == OpacComponent::Sscm {
                &opac_grid
            } else {
                &no_phase
            };
            let comp = c.component(1.0, w * 1e-6).unwrap();
            let work = mie_work(&[comp], w * 1e-6, opts).unwrap();
            cases.push((format!("{} {w} um", c.name()), work));
        }
    }
    let (name, largest) = cases
        .iter()
        .max_by(|a, b| a.1.work.total_cmp(&b.1.work))
        .unwrap();
    assert_eq!(name, "maritime-clean 532 nm", "{largest:?}");
    for (name, w) in &cases {
        assert!(w.work * 100.0 <= MAX_MIE_WORK, "{name}: {w:?}");
        assert!(
            w.angle_table_values * 100 <= MAX_MIE_ANGLE_TABLE_VALUES,
            "{name}: {w:?}"
        );
    }
}

/// A scene with a Mie layer (small absorbing spheres at 1064 nm: a second of Mie theory at
/// most), run without `--photons` work.
const MIE_CACHE_SCENE: &str = r#"description = "Mie cache"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 0.1
beam_divergence_full_angle_mrad = 0.1
telescope_diameter_m = 0.3
optical_efficiency = 0.5
fov_full_angle_mrad = 1.0
[[channel]]
name = "1064"
wavelength_nm = 1064.0
[gates]
start_m = 100.0
end_m = 2000.0
width_m = 10.0
[[layer]]
name = "aerosol"
base_m = 0.0
top_m = 1500.0
extinction_per_km = 0.1
particles = { distribution = "lognormal", median_radius_um = 0.2, sigma_g = 1.5, refractive_index = "1.45+0.001i" }
"#;

/// The Mie cache through the binary. With no `cache_dir` in the scene and no
/// `LIDARSIM_CACHE_DIR`, the first run writes one entry in `$XDG_CACHE_HOME/lidarsim`; the
/// second reads it (the entry is not rewritten: same inode, same modification time) and writes
/// the same returns byte for byte. A damaged entry is recomputed with a warning naming it, to
/// the same returns. `LIDARSIM_CACHE_DIR` moves the cache, `off` turns it off, and the scene's
/// `cache_dir` wins over both. (The other tests run with the cache off: tests/util.rs, `NO_MIE_CACHE`.)
#[test]
fn mie_cache_is_on_by_default_in_the_user_cache_directory() {
    use std::process::Command;
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.toml");
    std::fs::write(&scene, MIE_CACHE_SCENE).unwrap();
    let xdg = dir.path().join("xdg");
    let run = |out: &str, env: &[(&str, &Path)], off: bool| {
        let mut c = Command::new(crate::util::lidarsim_bin());
        c.args([
            "run",
            "--photons",
            "0",
            "--no-plots",
            "--no-netcdf",
            "--out",
        ])
        .arg(dir.path().join(out))
        .arg(&scene)
        .env_remove("LIDARSIM_CACHE_DIR")
        .env("XDG_CACHE_HOME", &xdg);
        for (k, v) in env {
            c.env(k, v);
        }
        if off {
            c.env("LIDARSIM_CACHE_DIR", "off");
        }
        let o = c.output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let returns = std::fs::read(dir.path().join(out).join("returns.csv")).unwrap();
        (returns, String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let entries = |d: &Path| -> Vec<std::path::PathBuf> {
        match std::fs::read_dir(d) {
            Ok(r) => r.map(|e| e.unwrap().path()).collect(),
            Err(_) => Vec::new(),
        }
    };
    let (first, _) = run("a", &[], false);
    let cache = xdg.join("lidarsim");
    let made = entries(&cache);
    assert_eq!(made.len(), 1, "{made:?}");
    let name = made[0].file_name().unwrap().to_string_lossy().into_owned();
    assert!(name.starts_with("mie-") && name.ends_with(".txt"), "{name}");
    let stamp = |p: &Path| {
        use std::os::unix::fs::MetadataExt;
        let m = std::fs::metadata(p).unwrap();
        (m.ino(), m.modified().unwrap())
    };
    let before = stamp(&made[0]);
    let (second, _) = run("b", &[], false);
    assert_eq!(first, second);
    assert_eq!(stamp(&made[0]), before, "the entry was rewritten, not read");
    // A damaged entry: a warning naming it, the same returns, a whole entry again.
    let whole = std::fs::read(&made[0]).unwrap();
    std::fs::write(&made[0], &whole[..whole.len() / 3]).unwrap();
    let (third, stderr) = run("c", &[], false);
    assert_eq!(first, third);
    assert!(
        stderr.contains("Mie cache entry")
            && stderr.contains(&name)
            && stderr.contains("recomputed"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(&made[0]).unwrap(), whole);
    // Moved by LIDARSIM_CACHE_DIR; off writes nothing.
    let moved = dir.path().join("moved");
    let (fourth, _) = run("d", &[("LIDARSIM_CACHE_DIR", &moved)], false);
    assert_eq!(first, fourth);
    assert_eq!(entries(&moved).len(), 1);
    std::fs::remove_dir_all(&cache).unwrap();
    run("e", &[], true);
    assert!(entries(&cache).is_empty());
    // The scene's cache_dir (relative to the scene) wins.
    let text = format!("{MIE_CACHE_SCENE}[simulation]\ncache_dir = \"mine\"\n");
    std::fs::write(&scene, text).unwrap();
    run("f", &[("LIDARSIM_CACHE_DIR", &moved)], false);
    assert_eq!(entries(&dir.path().join("mine")).len(), 1);
    assert!(entries(&cache).is_empty());
}
