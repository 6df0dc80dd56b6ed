//! lidarsim side of `validation/mie_timing/miepython_timing.py`: ms per particle for one sphere
//! (m = 1.33 + 1e-8 i), efficiencies only and with S1, S2 at 181 angles, one thread.
use std::hint::black_box;
use std::time::Instant;

use lidarsim::particles::mie::MieCoefficients;
use num_complex::Complex64;

fn best_ms(f: &mut dyn FnMut(), n: usize) -> f64 {
    f();
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let t = Instant::now();
        for _ in 0..n {
            f();
        }
        best = best.min(t.elapsed().as_secs_f64() / n as f64 * 1e3);
    }
    best
}

fn main() {
    let m = Complex64::new(1.33, 1e-8);
    let mu: Vec<f64> = (0..=180).map(|t| (t as f64).to_radians().cos()).collect();
    println!("x,lidarsim_eff_ms,lidarsim_s1s2_181_ms");
    for x in [10.0, 100.0, 1000.0, 10000.0] {
        let n = (30000.0f64 / x).max(3.0) as usize;
        let e = best_ms(
            &mut || {
                black_box(
                    MieCoefficients::compute(black_box(m), black_box(x))
                        .unwrap()
                        .efficiencies(),
                );
            },
            n,
        );
        let s = best_ms(
            &mut || {
                let k = MieCoefficients::compute(black_box(m), black_box(x)).unwrap();
                black_box((k.efficiencies(), k.amplitudes(&mu).unwrap()));
            },
            (n / 10).max(2),
        );
        println!("{x},{e:.4},{s:.4}");
    }
}
