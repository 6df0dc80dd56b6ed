//! Benchmarks (criterion); see README "Benchmarks" and docs/particles.md.
//!
//! * `mie/efficiencies/x=…`: one sphere (m = 1.33 + 1e-8 i), Qext, Qsca, Qback, g.
//! * `mie/amplitudes_181/x=…`: the same plus S1, S2 at 181 angles (0°, 1°, …, 180°).
//! * `bulk/c1_1064nm_phase_1391`: Deirmendjian C.1 at 1064 nm, converged size integration and
//!   the phase function on the default 1391-angle grid.
use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use lidarsim::particles::distribution::{BulkOptions, SizeDistribution, bulk_optics};
use lidarsim::particles::mie::{MieCoefficients, mie};
use num_complex::Complex64;

fn benches(c: &mut Criterion) {
    let m = Complex64::new(1.33, 1e-8);
    let mu: Vec<f64> = (0..=180).map(|t| (t as f64).to_radians().cos()).collect();
    let mut g = c.benchmark_group("mie");
    for x in [10.0, 100.0, 1000.0, 10000.0] {
        g.bench_function(format!("efficiencies/x={x}"), |b| {
            b.iter(|| mie(black_box(m), black_box(x)).unwrap())
        });
        g.bench_function(format!("amplitudes_181/x={x}"), |b| {
            b.iter(|| {
                let k = MieCoefficients::compute(black_box(m), black_box(x)).unwrap();
                (k.efficiencies(), k.amplitudes(&mu).unwrap())
            })
        });
    }
    g.finish();
    let mut g = c.benchmark_group("bulk");
    g.sample_size(10);
    let c1 = SizeDistribution::deirmendjian_c1();
    let m = Complex64::new(1.3205, 1.28e-6);
    g.bench_function("c1_1064nm_phase_1391", |b| {
        b.iter(|| bulk_optics(&c1, m, 1064e-9, &BulkOptions::default()).unwrap())
    });
    g.finish();
}

criterion_group!(group, benches);
criterion_main!(group);
