//! lidarsim's side of the HAPI benchmark (issue item 8): all CO2 lines of the shared HITRAN file
//! within 6300–6400 cm⁻¹ on a 0.001 cm⁻¹ grid, 25 cm⁻¹ wing, 1 atm, 296 K (air-broadened, HAPI's
//! conventions so that the numbers compare with HAPI's).
//!
//! `cargo run --release --example hapi_benchmark -- [--out sigma.bin] [--repeat N] [--no-exact]`
//! prints one JSON object: best and median wall times of the fast multigrid path with 1 and 2
//! threads, the time of the exact reference (lidarsim's exact-Faddeeva brute force, every line at
//! every point: errorfunctions = scipy wofz), and the maximum relative error of the fast path
//! against it. `run.py` in this folder runs it beside HAPI in one go.

use std::path::PathBuf;
use std::time::Instant;

use lidarsim::spectroscopy::xsec::GasState;
use lidarsim::spectroscopy::{
    LblOptions, LineFilter, LineList, VoigtMethod, WavenumberGrid, cross_section,
};

fn main() -> anyhow::Result<()> {
    let mut out: Option<PathBuf> = None;
    let mut repeat = 7usize;
    let mut exact = true;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--out" => out = args.next().map(PathBuf::from),
            "--repeat" => repeat = args.next().unwrap_or_default().parse()?,
            "--no-exact" => exact = false,
            other => anyhow::bail!("unknown argument {other}"),
        }
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let shared = std::env::var_os("LIDARSIM_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("../shared"));
    let par = shared.join("data/hitran/CO2_626_6000-6400_HITRAN2016.par");

    let t_read = Instant::now();
    let lines = LineList::read_par(&par, &LineFilter::window(6300.0, 6400.0))?;
    let read_s = t_read.elapsed().as_secs_f64();
    let grid = WavenumberGrid::new(6300.0, 6400.0, 0.001)?;
    let state = GasState {
        pressure_pa: 101_325.0,
        temperature_k: 296.0,
        self_vmr: 0.0,
    };
    let fast = LblOptions {
        voigt: VoigtMethod::Fast,
        ..LblOptions::hapi_reference()
    };

    let time_with = |threads: usize| -> anyhow::Result<(Vec<f64>, Vec<f64>)> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()?;
        let mut times = Vec::new();
        let mut sigma = Vec::new();
        for _ in 0..repeat {
            let t0 = Instant::now();
            sigma = pool.install(|| cross_section(&lines, 2, &state, &grid, &fast))?;
            times.push(t0.elapsed().as_secs_f64());
        }
        times.sort_by(f64::total_cmp);
        Ok((times, sigma))
    };
    let (t1, sigma1) = time_with(1)?;
    let (t2, sigma2) = time_with(2)?;
    anyhow::ensure!(sigma1 == sigma2, "results differ between 1 and 2 threads");

    let (exact_s, max_rel) = if exact {
        let opts = LblOptions {
            multigrid: false,
            ..LblOptions::hapi_reference()
        };
        let t0 = Instant::now();
        let reference = cross_section(&lines, 2, &state, &grid, &opts)?;
        let s = t0.elapsed().as_secs_f64();
        let worst = sigma1
            .iter()
            .zip(&reference)
            .map(|(a, b)| ((a - b) / b).abs())
            .fold(0.0, f64::max);
        (s, worst)
    } else {
        (f64::NAN, f64::NAN)
    };
    if let Some(p) = out {
        let bytes: Vec<u8> = sigma1.iter().flat_map(|v| v.to_le_bytes()).collect();
        lidarsim::output::write_file(p, &bytes)?;
    }
    let med = |t: &[f64]| t[t.len() / 2];
    println!(
        "{}",
        serde_json::json!({
            "lines": lines.len(),
            "grid_points": grid.len,
            "read_s": read_s,
            "fast_1thread_best_s": t1[0],
            "fast_1thread_median_s": med(&t1),
            "fast_2threads_best_s": t2[0],
            "fast_2threads_median_s": med(&t2),
            "exact_reference_2threads_s": exact_s,
            "fast_vs_exact_max_rel_error": max_rel,
            "repeat": repeat,
        })
    );
    Ok(())
}
