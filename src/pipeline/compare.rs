//! What skipping the Monte Carlo saves on a whole run (`lidarsim bench --scenes FILE…`): a benchmark
//! of the pipeline, so it lives above it rather than in [`crate::skip`].

use std::time::Instant;

use super::skip::Decision;
use super::{RunError, RunOutput, run};
use crate::optics::OpticalAtmosphere;
use crate::scene::{MultipleScattering, Scene};

/// Wall-clock times of one scene's whole run ([`run`]) as the scene asks for it and with
/// the Monte Carlo forced on: what skipping saves.
#[derive(Debug, Clone)]
pub struct Comparison {
    /// The decision of the run as asked for.
    pub decision: Decision,
    /// Building the optical atmosphere (line by line included) \[s\], fastest of the repeats.
    pub optics_s: f64,
    /// The whole run as asked for \[s\], fastest of the repeats.
    pub auto_s: f64,
    /// The whole run with the Monte Carlo forced on \[s\], fastest of the repeats.
    pub forced_s: f64,
    /// Photons of the forced run.
    pub forced_photons: u64,
    /// The transport's share of the forced run \[s\].
    pub forced_transport_s: f64,
}

/// Time `scene` as asked for and with the Monte Carlo forced on (`forced_photons` when the
/// scene asks for none), on `threads` threads, the fastest of `repeat` runs each (the least
/// disturbed by other load).
pub fn compare_skip(
    scene: &Scene,
    forced_photons: u64,
    threads: usize,
    repeat: usize,
) -> Result<Comparison, RunError> {
    let mut asked = scene.clone();
    asked.simulation.threads = threads;
    let mut forced = asked.clone();
    forced.simulation.multiple_scattering = MultipleScattering::Always;
    if forced.simulation.photons == 0 {
        forced.simulation.photons = forced_photons;
    }
    let fastest = |s: &Scene| -> Result<(f64, RunOutput), RunError> {
        let mut best: Option<(f64, RunOutput)> = None;
        for _ in 0..repeat.max(1) {
            let t = Instant::now();
            let out = run(s)?;
            let dt = t.elapsed().as_secs_f64();
            if best.as_ref().is_none_or(|(b, _)| dt < *b) {
                best = Some((dt, out));
            }
        }
        best.ok_or_else(unreachable_run)
    };
    let mut optics_s = f64::INFINITY;
    for _ in 0..repeat.max(1) {
        let t = Instant::now();
        OpticalAtmosphere::build(scene)?;
        optics_s = optics_s.min(t.elapsed().as_secs_f64());
    }
    let (auto_s, auto_out) = fastest(&asked)?;
    let (forced_s, forced_out) = fastest(&forced)?;
    Ok(Comparison {
        decision: auto_out.monte_carlo,
        optics_s,
        auto_s,
        forced_s,
        forced_photons: forced.simulation.photons,
        forced_transport_s: forced_out.mc.as_ref().map_or(0.0, |m| m.wall_s),
    })
}

/// `repeat.max(1)` ≥ 1 runs always leave a best one; this only keeps the types honest.
fn unreachable_run() -> RunError {
    RunError::Transport(crate::transport::TransportError::Options(
        "no run was timed".into(),
    ))
}
