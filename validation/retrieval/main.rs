//! Retrieval validation (validation/retrieval/README.md):
//!
//! 1. noise-free, particle-free retrievals against the truth (IPDA from space, DIAL from an
//!    aircraft), analytic and Monte Carlo, and how little Monte Carlo noise the shared photon
//!    paths leave in the on/off ratio;
//! 2. the path-length bias multiple scattering puts into space-borne IPDA XCO2 through a thin
//!    cirrus and through a dense dust layer, for each field of view;
//! 3. the default scene's figures (truth, retrieved, bias, random errors analytic and
//!    simulated) and its run time.
//!
//! `cargo run --release --example retrieval_validation -- [PHOTONS]` (default 10⁷).

use std::path::Path;
use std::time::Instant;

use lidarsim::pipeline::{self, RunOutput};
use lidarsim::retrieval::{Method, Quantity};
use lidarsim::returns::{Order, Source};
use lidarsim::scene::{DEFAULT_SCENE_TOML, Scene};

fn run(text: &str, photons: u64) -> (Scene, RunOutput, f64) {
    let mut scene = Scene::from_toml(Path::new("validation.toml"), text).expect("scene");
    // Photons asked for are traced, also through clear sky (as `--photons N` does).
    scene.simulation.multiple_scattering = lidarsim::scene::MultipleScattering::Always;
    scene.simulation.photons = photons;
    let t = Instant::now();
    let out = pipeline::run(&scene).expect("run");
    (scene, out, t.elapsed().as_secs_f64())
}

/// The default scene without its laser's imperfections and without particles.
fn ideal_space() -> String {
    DEFAULT_SCENE_TOML
        .replacen("frequency_jitter_rms_mhz = 0.3\n", "", 1)
        .replacen("spectral_purity = 0.999\n", "", 1)
        .replacen("impurity_wavenumber_cm1 = [6360.055, 6360.625]\n", "", 1)
        .replacen(
            "[[layer]]\nname = \"boundary-layer aerosol\"\nbase_m = 0.0\ntop_m = 1500.0\nextinction_per_km = 0.05\nsingle_scattering_albedo = 0.95\nphase = { kind = \"henyey_greenstein\", g = 0.7 }\n",
            "",
            1,
        )
}

fn main() {
    let photons: u64 = std::env::args()
        .nth(1)
        .map(|a| a.parse().expect("photons"))
        .unwrap_or(10_000_000);
    println!("# Retrieval validation, {photons} photons per Monte Carlo run\n");

    // 1a. IPDA from space, no particles, ideal laser.
    let text = ideal_space();
    assert_ne!(text, DEFAULT_SCENE_TOML);
    let (_, out, wall) = run(&text, photons);
    println!("## 1. Noise-free, particle-free retrievals ({wall:.1} s)\n");
    println!("IPDA from 450 km (default scene without aerosol, jitter or impurity):\n");
    println!(
        "| FOV [mrad] | returns | truth [ppm] | retrieved [ppm] | bias [ppm] | MC error [ppm] | MC error if on/off traced apart [ppm] |"
    );
    println!("|---|---|---|---|---|---|---|");
    for fov in [0.2, 0.5] {
        for (src, order, name) in [
            (Source::Analytic, Order::Exactly(1), "analytic"),
            (Source::MonteCarlo, Order::Exactly(1), "MC order 1"),
            (Source::MonteCarlo, Order::Total, "MC all orders"),
        ] {
            let p = out.products_of(Method::Ipda, Quantity::MixingRatio, src, order, fov)[0];
            println!(
                "| {fov} | {name} | {:.4} | {:.4} | {:+.1e} | {:.1e} | {:.1e} |",
                p.truth,
                p.retrieved,
                p.bias(),
                p.mc_stderr,
                p.mc_stderr_independent
            );
        }
    }
    // 1b. DIAL from an aircraft, no particles.
    let airborne = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/airborne_co2_dial.toml"),
    )
    .expect("airborne scene")
    .replacen(
        "[[layer]]\nname = \"boundary-layer aerosol\"\nbase_m = 0.0\ntop_m = 1500.0\nextinction_per_km = 0.08\nsingle_scattering_albedo = 0.95\nphase = { kind = \"henyey_greenstein\", g = 0.7 }\n",
        "",
        1,
    );
    let (_, out, wall) = run(&airborne, photons);
    println!(
        "\nDIAL from 8 km (scenes/airborne_co2_dial.toml without aerosol), 500 m cells, FOV 0.2 mrad ({wall:.1} s):\n"
    );
    println!(
        "| cell altitude [m] | truth [ppm] | analytic bias [ppm] | MC all orders − analytic [ppm] | MC error [ppm] | MC error if traced apart [ppm] |"
    );
    println!("|---|---|---|---|---|---|");
    let an = out.products_of(
        Method::Dial,
        Quantity::MixingRatio,
        Source::Analytic,
        Order::Exactly(1),
        0.2,
    );
    let mc = out.products_of(
        Method::Dial,
        Quantity::MixingRatio,
        Source::MonteCarlo,
        Order::Total,
        0.2,
    );
    let (mut max_bias, mut max_z, mut ratio) = (0.0f64, 0.0f64, 0.0f64);
    for (a, m) in an.iter().zip(&mc) {
        println!(
            "| {:.0}–{:.0} | {:.3} | {:+.1e} | {:+.1e} | {:.1e} | {:.1e} |",
            a.altitude_m.0,
            a.altitude_m.1,
            a.truth,
            a.bias(),
            m.retrieved - a.retrieved,
            m.mc_stderr,
            m.mc_stderr_independent
        );
        max_bias = max_bias.max(a.bias().abs());
        max_z = max_z.max(((m.retrieved - a.retrieved) / m.mc_stderr).abs());
        ratio = ratio.max(m.mc_stderr / m.mc_stderr_independent);
    }
    println!(
        "\nlargest |analytic bias| {max_bias:.1e} ppm; largest |MC − analytic|/MC error {max_z:.2}; MC error with shared paths ≤ {ratio:.1e} × that of independent paths"
    );

    // 2. Multiple scattering in space-borne IPDA.
    println!("\n## 2. Multiple scattering in IPDA from 450 km\n");
    let fovs = "fov_full_angle_mrad = [0.1, 0.2, 0.5, 1.0, 2.0]";
    for (name, layer) in [
        (
            "thin cirrus, 9–10 km, τ = 0.3, double Henyey-Greenstein (f = 0.95, g₁ = 0.96, g₂ = −0.3)",
            "[[layer]]\nname = \"cirrus\"\nbase_m = 9000.0\ntop_m = 10000.0\nextinction_per_km = 0.3\nsingle_scattering_albedo = 1.0\nphase = { kind = \"double_henyey_greenstein\", f = 0.95, g1 = 0.96, g2 = -0.3 }\n",
        ),
        (
            "dense dust, 2–4 km, τ = 0.6, double Henyey-Greenstein (f = 0.95, g₁ = 0.8, g₂ = −0.4)",
            "[[layer]]\nname = \"dust\"\nbase_m = 2000.0\ntop_m = 4000.0\nextinction_per_km = 0.3\nsingle_scattering_albedo = 0.97\nphase = { kind = \"double_henyey_greenstein\", f = 0.95, g1 = 0.8, g2 = -0.4 }\n",
        ),
    ] {
        let text = ideal_space()
            .replacen("fov_full_angle_mrad = [0.2, 0.5]", fovs, 1)
            .replacen("[surface]", &format!("{layer}[surface]"), 1);
        let (scene, out, wall) = run(&text, photons);
        println!("{name} ({wall:.1} s):\n");
        println!(
            "| FOV [mrad] | surface echo from multiple scattering | XCO2 bias, single scattering [ppm] | XCO2 bias, all orders [ppm] |"
        );
        println!("|---|---|---|---|");
        let target = scene
            .retrieval
            .as_ref()
            .unwrap()
            .target
            .as_ref()
            .unwrap()
            .gates
            .start;
        let lines = out.mc_lines.as_ref().unwrap();
        for (f, fov) in scene.lidar.fov_full_angle_mrad.iter().enumerate() {
            let single = out.products_of(
                Method::Ipda,
                Quantity::MixingRatio,
                Source::MonteCarlo,
                Order::Exactly(1),
                *fov,
            )[0];
            let all = out.products_of(
                Method::Ipda,
                Quantity::MixingRatio,
                Source::MonteCarlo,
                Order::Total,
                *fov,
            )[0];
            let e1 = lines.mean.energy(1, f, target, Order::Exactly(1)).unwrap();
            let et = lines.mean.energy(1, f, target, Order::Total).unwrap();
            println!(
                "| {fov} | {:.1} % | {:+.4} ± {:.4} | {:+.4} ± {:.4} |",
                100.0 * (1.0 - e1 / et),
                single.bias(),
                single.mc_stderr,
                all.bias(),
                all.mc_stderr
            );
        }
        println!();
    }

    // 3. The default scene.
    let (_, out, wall) = run(DEFAULT_SCENE_TOML, 200_000);
    let r = out.retrieval.as_ref().unwrap();
    println!(
        "## 3. The default scene ({} , 2×10⁵ photons, {wall:.2} s)\n",
        r.config.averaging_label
    );
    println!(
        "| FOV [mrad] | returns | truth [ppm] | retrieved [ppm] | bias [ppm] | random per shot pair: analytic / simulated [ppm] | random averaged: analytic / simulated [ppm] |"
    );
    println!("|---|---|---|---|---|---|---|");
    for p in out.products.iter().filter(|p| p.method == Method::Ipda) {
        println!(
            "| {} | {} {} | {:.3} | {:.3} | {:+.3} | {:.2} / {:.2} | {:.3} / {:.3} |",
            p.fov_full_angle_mrad,
            p.source.label(),
            p.order.label(),
            p.truth,
            p.retrieved,
            p.bias(),
            p.random_error_per_shot_pair,
            p.simulated_error_per_shot_pair,
            p.random_error_averaged,
            p.simulated_error_averaged
        );
    }
}
