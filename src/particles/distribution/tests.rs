use super::*;
use num_complex::Complex64;

#[test]
fn c1_number_density_moments_and_quantiles() {
    let c1 = SizeDistribution::deirmendjian_c1();
    // N = a Γ(7)/1.5⁷ = 2.373·720/17.0859375 = 99.998 cm⁻³ (Deirmendjian: 100).
    assert!((c1.number_density_per_cm3() - 2.373 * 720.0 / 1.5f64.powi(7)).abs() < 1e-9);
    // r_eff = Γ(10)/Γ(9)/1.5 = 9/1.5 = 6 µm.
    assert!((c1.effective_radius_um() - 6.0).abs() < 1e-12);
    let q = c1.area_quantile(0.5);
    assert!((c1.area_cdf(q) - 0.5).abs() < 1e-9);
}

#[test]
fn lognormal_moments_match_quadrature() {
    let d = SizeDistribution::lognormal(100.0, 0.1, 2.0).unwrap();
    // ∫ r² n dr by midpoint rule in ln r against the closed form.
    let (a, b, n) = ((1e-4f64).ln(), (1e2f64).ln(), 200_000);
    let h = (b - a) / n as f64;
    let mut s = 0.0;
    let mut s0 = 0.0;
    for i in 0..n {
        let r = (a + (i as f64 + 0.5) * h).exp();
        s += d.density(r) * r * r * r * h;
        s0 += d.density(r) * r * h;
    }
    assert!((s0 / 100.0 - 1.0).abs() < 1e-9);
    assert!((s / 100.0 / d.moment(2.0) - 1.0).abs() < 1e-9);
}

/// The work's radii are the grid the step halving reaches when it cannot converge (a
/// tolerance it never meets), radius for radius, and bound it when it converges sooner;
/// its Mie terms bound the sum of N(x) over those radii; the angles are the ones used.
#[test]
fn mie_work_bounds_the_grid_and_the_terms() {
    let m = Complex64::new(1.5, 0.01);
    let bimodal = SizeDistribution::sum(vec![
        SizeDistribution::lognormal(100.0, 0.05, 1.6).unwrap(),
        SizeDistribution::lognormal(1.0, 0.5, 1.4).unwrap(),
    ])
    .unwrap();
    let comps = |d: &SizeDistribution| {
        vec![Component {
            name: "p".into(),
            distribution: d.clone(),
            refractive_index: m,
        }]
    };
    let never = BulkOptions {
        rel_tol: 1e-15,
        angles_deg: Some(vec![]),
        ..BulkOptions::default()
    };
    let w = mie_work(&comps(&bimodal), 1064e-9, &never).unwrap();
    let b = bulk_optics(&bimodal, m, 1064e-9, &never).unwrap();
    assert_eq!(w.integrations, 2);
    assert!(b.convergence.iter().all(|c| !c.converged));
    let radii: usize = b.convergence.iter().map(|c| c.points).sum();
    assert_eq!(w.radii, radii as u64);
    // Σ N(x) over the final grids, directly.
    let k = 2.0 * PI / 1.064;
    let direct: f64 = b
        .convergence
        .iter()
        .map(|c| {
            let (x0, x1) = (k * c.r_range_um.0, k * c.r_range_um.1);
            (0..c.points)
                .map(|i| {
                    let x = x0 + (x1 - x0) * i as f64 / (c.points - 1) as f64;
                    x + 4.05 * x.cbrt() + 2.0
                })
                .sum::<f64>()
        })
        .sum();
    assert!(
        w.terms >= direct && w.terms < 1.05 * direct,
        "{} vs {direct}",
        w.terms
    );
    assert_eq!(w.angles, 0);
    assert_eq!(w.work, w.terms * 200.0);
    // Converging at the default tolerance: fewer radii than the bound; the default grid's
    // angles counted.
    let w = mie_work(&comps(&bimodal), 1064e-9, &BulkOptions::default()).unwrap();
    let b = bulk_optics(&bimodal, m, 1064e-9, &BulkOptions::default()).unwrap();
    let radii: usize = b.convergence.iter().map(|c| c.points).sum();
    assert!(w.radii >= radii as u64);
    assert_eq!(w.angles, b.phase.theta_deg.len() as u64);
    // The same inputs twice count once; two wavelengths twice.
    let c = comps(&bimodal);
    let sets = [(&c[..], 1064e-9), (&c[..], 1064e-9), (&c[..], 532e-9)];
    let all = mie_work_of(sets, &BulkOptions::default()).unwrap();
    assert_eq!(all.integrations, 4);
}

/// Beyond the limit, `bulk_optics` refuses before any work, naming the product and the
/// limit: 2 mm drops at 532 nm with a phase function.
#[test]
fn bulk_optics_refuses_work_beyond_the_limit() {
    let d = SizeDistribution::lognormal(1.0, 2000.0, 1.2).unwrap();
    let t = std::time::Instant::now();
    let e = bulk_optics(
        &d,
        Complex64::new(1.33, 0.0),
        532e-9,
        &BulkOptions::default(),
    )
    .unwrap_err();
    assert!(t.elapsed().as_secs_f64() < 1.0);
    let MieError::Work(msg) = e else {
        panic!("{e:?}")
    };
    assert!(
        msg.contains("term-angles") && msg.contains("limit of 4e13") && msg.contains("Limits"),
        "{msg}"
    );
}

#[test]
fn constructors_reject_bad_parameters() {
    assert!(SizeDistribution::lognormal(1.0, 0.1, 1.0).is_err());
    assert!(SizeDistribution::lognormal(-1.0, 0.1, 2.0).is_err());
    assert!(SizeDistribution::modified_gamma(1.0, -2.0, 1.0, 1.0).is_err());
    assert!(SizeDistribution::modified_gamma(1.0, 2.0, 0.0, 1.0).is_err());
    assert!(SizeDistribution::sum(vec![]).is_err());
    assert!(
        SizeDistribution::deirmendjian_c1()
            .truncated(5.0, 1.0)
            .is_err()
    );
}

/// The same numbers, bit for bit, on one thread and on four: the blocks of radii are reduced in
/// block order whatever thread computed them (a bimodal aerosol with its matrix, and the
/// progress the computation reports).
#[test]
fn bulk_optics_do_not_depend_on_the_thread_count() {
    let d = SizeDistribution::sum(vec![
        SizeDistribution::lognormal(100.0, 0.05, 1.6).unwrap(),
        SizeDistribution::lognormal(1.0, 1.0, 1.8).unwrap(),
    ])
    .unwrap();
    let comps = [Component {
        name: "p".into(),
        distribution: d,
        refractive_index: Complex64::new(1.45, 1e-4),
    }];
    let run = |threads: usize| {
        let radii = std::sync::Mutex::new(Vec::new());
        let b = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                bulk_optics_mixture_with_progress(&comps, 532e-9, &BulkOptions::default(), &|p| {
                    radii.lock().unwrap().push((p.integration, p.radii))
                })
                .unwrap()
            });
        (b, radii.into_inner().unwrap())
    };
    let (one, p1) = run(1);
    let (four, p4) = run(4);
    assert_eq!(one, four);
    assert_eq!(p1, p4);
    // Progress: integrations 1 then 2, radii increasing to the grids' total.
    let total: usize = one.convergence.iter().map(|c| c.points).sum();
    assert!(p1.windows(2).all(|w| w[0].1 < w[1].1 && w[0].0 <= w[1].0));
    assert_eq!(p1.last().unwrap().0, 2);
    // Each panel's first level counts its ends, which neighbouring panels share.
    let panels: usize = one.convergence.iter().map(|c| c.panels.len()).sum();
    assert_eq!(
        p1.last().unwrap().1 as usize,
        total + panels - one.convergence.len()
    );
}
