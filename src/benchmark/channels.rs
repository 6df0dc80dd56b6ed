//! The cost of a scattering event against the number of channels (`lidarsim bench
//! --channels`): the embedded default scene (a space-borne CO2 IPDA, 800 layers, two FOVs, an
//! aerosol layer, a surface) traced with its laser's spectral sampling taken apart, so that
//! the same photons carry 2, 4 or all 16 channels, side by side with C.1's one-channel walk
//! (the transport benchmark's workload) in one run on one thread.
//!
//! Every variant traces the same scene and seed: the scattering events are the same in number
//! (channel 0 draws the walk), only the per-channel work differs.

use std::path::Path;

use super::{BenchError, TransportWorkload, ensure, fastest};
use crate::optics::OpticalAtmosphere;
use crate::scene::{DEFAULT_SCENE_TOML, Scene, Simulation};

/// The laser keys whose removal takes the default scene's channels apart: without the first
/// three each line is one channel (no line-shape nodes nor jitter stencil); without the last
/// two there is no impurity channel.
const LINE_SHAPE_KEYS: [&str; 3] = [
    "line_shape",
    "linewidth_fwhm_mhz",
    "frequency_jitter_rms_mhz",
];
const IMPURITY_KEYS: [&str; 2] = ["spectral_purity", "impurity_wavenumber_cm1"];

/// One workload of the channel benchmark.
pub struct ChannelWorkload {
    /// What it is, for the table.
    pub name: String,
    /// The scene.
    pub scene: Scene,
    /// Its optical atmosphere.
    pub atm: OpticalAtmosphere,
}

/// The default scene without the `[laser]` keys `drop` (each must be present).
fn default_without(drop: &[&str]) -> Result<Scene, BenchError> {
    let mut text = String::new();
    let mut dropped = 0;
    for line in DEFAULT_SCENE_TOML.lines() {
        let key = line.split('=').next().unwrap_or("").trim();
        if drop.contains(&key) {
            dropped += 1;
        } else {
            text.push_str(line);
            text.push('\n');
        }
    }
    ensure!(
        dropped == drop.len(),
        "the default scene no longer has the laser keys {drop:?}"
    );
    Ok(Scene::from_toml(
        Path::new("<embedded default scene>"),
        &text,
    )?)
}

/// C.1 (the transport benchmark's scene) and the default scene at 2, 4 and 16 channels, each
/// with `photons` and `seed`.
pub fn workloads(photons: u64, seed: u64) -> Result<Vec<ChannelWorkload>, BenchError> {
    let c1 = TransportWorkload::new(photons, seed)?;
    let mut out = vec![ChannelWorkload {
        name: "C.1, 1 FOV".into(),
        scene: c1.scene,
        atm: c1.atm,
    }];
    let both: Vec<&str> = LINE_SHAPE_KEYS
        .iter()
        .chain(&IMPURITY_KEYS)
        .copied()
        .collect();
    for drop in [&both[..], &LINE_SHAPE_KEYS[..], &[][..]] {
        let mut scene = default_without(drop)?;
        scene.simulation.photons = photons;
        scene.simulation.seed = seed;
        let atm = OpticalAtmosphere::build(&scene)?;
        out.push(ChannelWorkload {
            name: format!("default scene, {} channels", atm.n_channels),
            scene,
            atm,
        });
    }
    Ok(out)
}

/// One row of the channel benchmark.
#[derive(Debug, Clone)]
pub struct ChannelRow {
    /// The workload's name.
    pub name: String,
    /// Its channels.
    pub channels: usize,
    /// Scattering events.
    pub events: u64,
    /// The transport's wall-clock time \[s\] (fastest run).
    pub wall_s: f64,
}

impl ChannelRow {
    /// Scattering events per second.
    pub fn events_per_s(&self) -> f64 {
        self.events as f64 / self.wall_s
    }

    /// Nanoseconds per scattering event.
    pub fn ns_per_event(&self) -> f64 {
        1e9 * self.wall_s / self.events as f64
    }
}

/// The fastest of `repeat` runs of every workload on `threads` threads, with the transport
/// settings of `configure`.
pub fn measure(
    workloads: &[ChannelWorkload],
    threads: usize,
    repeat: usize,
    configure: impl Fn(&mut Simulation) + Copy,
) -> Result<Vec<ChannelRow>, BenchError> {
    workloads
        .iter()
        .map(|w| {
            // The scene's own Monte Carlo settings: only the batches and the variance
            // reduction of `configure` (the defaults unless changed on the command line).
            let r = fastest(&w.scene, &w.atm, threads, repeat, |s| {
                let photons = s.photons;
                configure(s);
                s.photons = photons;
            })?;
            Ok(ChannelRow {
                name: w.name.clone(),
                channels: w.atm.n_channels,
                events: r.stats.collisions,
                wall_s: r.wall_s,
            })
        })
        .collect()
}

/// The table: per workload its events per second, the cost of an event, and the ratios the
/// issue asks for (events per second against C.1's, cost against the 2-channel default scene).
pub fn table(rows: &[ChannelRow], threads: usize) -> String {
    let c1 = rows.first().map_or(f64::NAN, ChannelRow::events_per_s);
    let two = rows
        .iter()
        .find(|r| r.channels == 2)
        .map_or(f64::NAN, ChannelRow::ns_per_event);
    let mut t = format!(
        "cost of a scattering event against the channel count, {threads} thread(s), fastest run\n\
         | workload | channels | events | wall s | M events/s | ns/event | events/s ÷ C.1's | ns/event ÷ 2 channels' |\n\
         |---|---|---|---|---|---|---|---|\n"
    );
    for r in rows {
        t.push_str(&format!(
            "| {} | {} | {} | {:.3} | {:.3} | {:.0} | {:.3} | {:.2} |\n",
            r.name,
            r.channels,
            r.events,
            r.wall_s,
            1e-6 * r.events_per_s(),
            r.ns_per_event(),
            r.events_per_s() / c1,
            r.ns_per_event() / two,
        ));
    }
    t
}

/// The rows as JSON.
pub fn json(rows: &[ChannelRow], threads: usize) -> serde_json::Value {
    serde_json::Value::Array(
        rows.iter()
            .map(|r| {
                serde_json::json!({
                    "workload": r.name, "channels": r.channels, "threads": threads,
                    "events": r.events, "wall_s": r.wall_s,
                    "events_per_s": r.events_per_s(), "ns_per_event": r.ns_per_event(),
                })
            })
            .collect(),
    )
}
