//! Transport benchmarks (criterion); see README "Benchmarks".
//!
//! * `phase/sample/…` and `phase/eval/…`: ns per sampled scattering angle and per phase-function
//!   evaluation toward the receiver, for each kind of phase function (a specialised analytic
//!   sampler beside the general tabulated one).
//! * `transport/c1_1mrad_20k_photons/threads=N`: a whole C.1 run (scattering events per second
//!   are printed by `lidarsim bench`, which also gives the figure of merit).
use std::hint::black_box;

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use lidarsim::optics::OpticalAtmosphere;
use lidarsim::particles::builtin_table;
use lidarsim::particles::phase::{HenyeyGreenstein, PhaseFunction, RayleighPhase, TabulatedPhase};
use lidarsim::scene::Scene;
use lidarsim::transport::{self, TallyLayout};
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

fn phase(c: &mut Criterion) {
    let c1 = builtin_table("bissonnette_c1_1064nm").unwrap();
    let cases = [
        (
            "rayleigh",
            PhaseFunction::Rayleigh(RayleighPhase::from_depolarisation(0.0279).unwrap()),
        ),
        (
            "hg_0.85",
            PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(0.85).unwrap()),
        ),
        (
            "double_hg",
            PhaseFunction::double_hg(0.9, 0.8, -0.4).unwrap(),
        ),
        (
            "table_c1_1391",
            PhaseFunction::Tabulated(Box::new(TabulatedPhase::from_table(&c1).unwrap())),
        ),
    ];
    const N: usize = 1024;
    let mut g = c.benchmark_group("phase");
    g.throughput(Throughput::Elements(N as u64));
    for (name, pf) in &cases {
        g.bench_function(format!("sample/{name}"), |b| {
            b.iter_batched(
                || {
                    let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
                    (0..N).map(|_| rng.random::<f64>()).collect::<Vec<f64>>()
                },
                |us| us.iter().map(|u| pf.sample(black_box(*u))).sum::<f64>(),
                BatchSize::SmallInput,
            )
        });
        g.bench_function(format!("eval/{name}"), |b| {
            b.iter_batched(
                || {
                    let mut rng = Xoshiro256PlusPlus::seed_from_u64(2);
                    (0..N)
                        .map(|_| 2.0 * rng.random::<f64>() - 1.0)
                        .collect::<Vec<f64>>()
                },
                |mus| mus.iter().map(|m| pf.eval(black_box(*m))).sum::<f64>(),
                BatchSize::SmallInput,
            )
        });
    }
    g.finish();
}

fn whole_scene(c: &mut Criterion) {
    let text = include_str!("../scenes/bissonnette_c1.toml").replace(
        r#"file = "../phase_functions/bissonnette_c1_1064nm.txt""#,
        r#"builtin = "bissonnette_c1_1064nm""#,
    );
    let mut scene = Scene::from_toml(std::path::Path::new("c1.toml"), &text).unwrap();
    scene.lidar.fov_full_angle_mrad = vec![1.0];
    let atm = OpticalAtmosphere::build(&scene).unwrap();
    let mut g = c.benchmark_group("transport");
    g.sample_size(10);
    let photons = 20_000u64;
    g.throughput(Throughput::Elements(photons));
    for threads in [1, 2] {
        let mut s = scene.clone();
        s.simulation.photons = photons;
        s.simulation.threads = threads;
        g.bench_function(format!("c1_1mrad_20k_photons/threads={threads}"), |b| {
            b.iter(|| transport::run(&s, &atm, &TallyLayout::default()).unwrap())
        });
    }
    g.finish();
}

criterion_group! {
    name = group;
    config = Criterion::default().without_plots();
    targets = phase, whole_scene
}
criterion_main!(group);
