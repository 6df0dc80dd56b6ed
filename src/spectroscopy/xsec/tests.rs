use super::*;

/// Synthetic lines (air-broadened widths, spacing and strengths like the CO2 band).
fn synthetic(n: usize, start: f64, spacing: f64) -> LineList {
    let rec = " 21 6359.967244 1.779E-23 7.543e-03.07470.102  106.12970.67-.005510       3 0 0 12       0 0 0 01                    R 16e     4788762029 6 5 6 8    35.0   33.0";
    let base = LineList::parse_par("r16", rec, &Default::default()).unwrap();
    let mut lines = Vec::new();
    for i in 0..n {
        let mut l = base.lines[0].clone();
        l.nu_cm1 = start + i as f64 * spacing + 0.1234 * ((i * 7) % 5) as f64;
        l.sw_cm_per_molecule *= 1.0 + 0.5 * ((i * 3) % 4) as f64;
        l.elower_cm1 = 100.0 * (i % 9) as f64;
        lines.push(l);
    }
    lines.sort_by(|a, b| a.nu_cm1.total_cmp(&b.nu_cm1));
    LineList {
        source: "synthetic".into(),
        lines,
    }
}

#[test]
fn multigrid_equals_direct_exact_at_all_pressures() {
    // 30 lines over 60 cm⁻¹; windows cut inside and outside the grid; three pressures from
    // the surface (Lorentz wings) to 1 hPa (Doppler cores).
    let lines = synthetic(30, 6320.0, 2.0);
    let grid = WavenumberGrid::new(6340.0, 6350.0, 0.001).unwrap();
    for (p_pa, centre) in [
        (101_325.0, WingCentre::Unshifted),
        (20_000.0, WingCentre::Shifted),
        (100.0, WingCentre::Unshifted),
    ] {
        let state = GasState {
            pressure_pa: p_pa,
            temperature_k: 250.0,
            self_vmr: 0.0004,
        };
        let opts = LblOptions {
            wing_centre: centre,
            ..Default::default()
        };
        let mg = cross_section(&lines, 2, &state, &grid, &opts).unwrap();
        let exact_opts = LblOptions {
            voigt: VoigtMethod::Exact,
            multigrid: false,
            ..opts
        };
        let ex = cross_section(&lines, 2, &state, &grid, &exact_opts).unwrap();
        let worst = mg
            .iter()
            .zip(&ex)
            .map(|(a, b)| ((a - b) / b).abs())
            .fold(0.0, f64::max);
        // Budget 1e-5 (the brief); the method's own bound is ~1e-6.
        assert!(worst < 2e-6, "p = {p_pa} Pa: max relative error {worst:e}");
    }
}

#[test]
fn multigrid_is_identical_at_any_thread_count() {
    let lines = synthetic(400, 6300.0, 0.25);
    let grid = WavenumberGrid::new(6330.0, 6340.0, 0.002).unwrap();
    let state = GasState {
        pressure_pa: 50_000.0,
        temperature_k: 270.0,
        self_vmr: 0.0,
    };
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| cross_section(&lines, 2, &state, &grid, &LblOptions::default()).unwrap())
    };
    assert_eq!(run(1), run(3));
}

#[test]
fn a_line_at_296_k_integrates_to_its_catalogue_intensity() {
    // HITRAN's S is the integrated intensity at 296 K, so ∫σ dν over the window is S times
    // the Lorentz mass inside it, (arctan((W − d)/γ) + arctan((W + d)/γ))/π for a centre
    // shifted by d from the window's (the Voigt's Gaussian core moves that by ~(γ_D/W)² of
    // the ~2e-4 outside). At 500 cm⁻¹ the stimulated-emission factors 1 − e^{−c₂ν/T} are
    // 0.91, at 6360 cm⁻¹ 1 − 4e-14: both cancel exactly at 296 K.
    let mut lines = synthetic(1, 6360.0, 1.0);
    let (wing, p_atm) = (25.0, 0.1);
    let opts = LblOptions {
        wing_cm1: wing,
        voigt: VoigtMethod::Exact,
        ..Default::default()
    };
    let state = GasState {
        pressure_pa: p_atm * constants::STANDARD_ATMOSPHERE_PA,
        temperature_k: 296.0,
        self_vmr: 0.0,
    };
    for nu0 in [500.0, 6360.0] {
        lines.lines[0].nu_cm1 = nu0;
        let l = &lines.lines[0];
        let n = 200_000;
        let h = 2.0 * wing / n as f64;
        let nus: Vec<f64> = (0..n).map(|i| nu0 - wing + (i as f64 + 0.5) * h).collect();
        let integral: f64 = cross_section_at(&lines, 2, &state, &nus, &opts)
            .unwrap()
            .iter()
            .sum::<f64>()
            * h;
        let (gamma, d) = (
            l.gamma_air_cm1_per_atm * p_atm,
            l.delta_air_cm1_per_atm * p_atm,
        );
        let inside =
            (((wing - d) / gamma).atan() + ((wing + d) / gamma).atan()) / std::f64::consts::PI;
        let want = l.sw_cm_per_molecule * inside;
        assert!(
            (integral / want - 1.0).abs() < 1e-7,
            "{nu0} cm⁻¹: ∫σ dν = {integral:e}, S × Lorentz mass in the window = {want:e}"
        );
    }
}

#[test]
fn a_par_line_is_refused_any_shape_but_the_plain_voigt() {
    // A .par record has no speed dependence, Dicke narrowing, correlation or line mixing.
    let lines = synthetic(1, 6360.0, 1.0);
    let state = GasState {
        pressure_pa: 101_325.0,
        temperature_k: 296.0,
        self_vmr: 0.0,
    };
    for (line_shape, line_mixing, ok) in [
        (LineShapeModel::Voigt, false, true),
        (LineShapeModel::Voigt, true, false),
        (LineShapeModel::SdVoigt, false, false),
        (LineShapeModel::HartmannTran, false, false),
    ] {
        let opts = LblOptions {
            line_shape,
            line_mixing,
            ..Default::default()
        };
        let r = cross_section_at(&lines, 2, &state, &[6360.0], &opts);
        assert_eq!(
            r.is_ok(),
            ok,
            "{} line mixing {line_mixing}: {r:?}",
            line_shape.name()
        );
        if !ok {
            assert!(matches!(
                r,
                Err(SpectroscopyError::MissingParameters { .. })
            ));
        }
    }
}

#[test]
fn a_par_line_broadens_by_the_mole_fraction_weighted_widths() {
    // HITRAN's .par convention: γ = (296/T)^n_air (γ_air (p − p_self) + γ_self p_self). A
    // line at self mole fraction x is the line of air width (1 − x)γ_air + xγ_self at x = 0.
    let lines = synthetic(1, 6360.0, 1.0);
    let l = &lines.lines[0];
    let nus: Vec<f64> = (0..400).map(|i| 6359.0 + i as f64 * 0.005).collect();
    for x in [0.5, 1.0] {
        let state = GasState {
            pressure_pa: 80_000.0,
            temperature_k: 250.0,
            self_vmr: x,
        };
        let mut air_only = lines.clone();
        air_only.lines[0].gamma_air_cm1_per_atm =
            (1.0 - x) * l.gamma_air_cm1_per_atm + x * l.gamma_self_cm1_per_atm;
        let opts = LblOptions::default();
        let a = cross_section_at(&lines, 2, &state, &nus, &opts).unwrap();
        let b = cross_section_at(
            &air_only,
            2,
            &GasState {
                self_vmr: 0.0,
                ..state
            },
            &nus,
            &opts,
        )
        .unwrap();
        for (u, v) in a.iter().zip(&b) {
            assert!((u / v - 1.0).abs() < 1e-12, "x = {x}: {u:e} vs {v:e}");
        }
    }
}

#[test]
fn a_list_in_any_order_gives_the_same_cross_section() {
    // `LineList::lines` is public; the multigrid's searches need ν₀ order. Reversed (strictly
    // decreasing) and shuffled lists are the sorted one's lines, so the sums are the same.
    let sorted = synthetic(30, 6320.0, 2.0);
    let grid = WavenumberGrid::new(6340.0, 6350.0, 0.01).unwrap();
    let state = GasState {
        pressure_pa: 50_000.0,
        temperature_k: 250.0,
        self_vmr: 0.0004,
    };
    let want = cross_section(&sorted, 2, &state, &grid, &LblOptions::default()).unwrap();
    let mut reversed = sorted.clone();
    reversed.lines.reverse();
    let mut shuffled = sorted.clone();
    let n = shuffled.lines.len();
    for i in 0..n {
        shuffled.lines.swap(i, (i * 17 + 5) % n);
    }
    for list in [reversed, shuffled] {
        let got = cross_section(&list, 2, &state, &grid, &LblOptions::default()).unwrap();
        assert_eq!(got, want);
    }
}

#[test]
fn window_follows_hapi_convention() {
    // One line; grid points exactly at ν₀ ± W: ν₀ − W excluded, ν₀ + W included.
    let lines = synthetic(1, 6350.0, 1.0);
    let nu0 = lines.lines[0].nu_cm1;
    let opts = LblOptions {
        wing_cm1: 1.0,
        ..Default::default()
    };
    let st = GasState {
        pressure_pa: 101_325.0,
        temperature_k: 296.0,
        self_vmr: 0.0,
    };
    let s = cross_section_at(&lines, 2, &st, &[nu0 - 1.0, nu0 + 1.0], &opts).unwrap();
    assert_eq!(s[0], 0.0);
    assert!(s[1] > 0.0);
}

/// The direct sum at many wavenumbers at once, unsorted, repeated, some not finite, is each
/// wavenumber's sum on its own (every line in its window, in line order, from 0) bit for bit,
/// for plain Voigt lines on the fast and the exact path.
#[test]
fn direct_sum_of_many_wavenumbers_is_each_ones_own_sum() {
    let lines = synthetic(30, 6320.0, 2.0);
    let state = GasState {
        pressure_pa: 30_000.0,
        temperature_k: 230.0,
        self_vmr: 0.0004,
    };
    let mut nus: Vec<f64> = (0..300)
        .map(|i| 6300.0 + 0.37 * ((i * 97) % 300) as f64 + 1e-3 * i as f64)
        .collect();
    nus.extend([
        6340.5,
        6340.5,
        f64::NAN,
        f64::INFINITY,
        lines.lines[3].nu_cm1 + 25.0,
    ]);
    for opts in [
        LblOptions::default(),
        LblOptions {
            voigt: VoigtMethod::Exact,
            wing_centre: WingCentre::Shifted,
            ..Default::default()
        },
    ] {
        let prepared = prepare(&lines, 2, &state, &opts).unwrap();
        let together = direct_sum(&prepared, &nus, &opts);
        let exact = opts.voigt == VoigtMethod::Exact;
        for (nu, got) in nus.iter().zip(&together) {
            let mut want = 0.0;
            for p in &prepared {
                if p.in_window(*nu, opts.wing_cm1) {
                    want += p.eval(*nu, exact);
                }
            }
            assert_eq!(got.to_bits(), want.to_bits(), "ν {nu}: {got} vs {want}");
        }
    }
}
