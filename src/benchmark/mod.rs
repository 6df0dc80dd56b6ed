//! The workloads and measurements of `lidarsim bench`; the command line prints them.
//!
//! - [`transport`]: speed and Monte Carlo efficiency of the transport on the Bissonnette et al.
//!   (1995) case C.1 (`scenes/bissonnette_c1.toml`, compiled in) with one 1 mrad field of
//!   view. The figure of merit is FOM = 1/(rel_err² · t) of the multiple-scattering return
//!   (orders ≥ 2) in the gate starting 100 m into the cloud (1100–1110 m), t the wall-clock
//!   time of the transport at the given thread count.
//! - [`StudyWorkload`]: the speed of the reference study's clear-sky ensemble study:
//!   `scenes/study_co2_ipda.toml` (compiled in) run by `lidarsim dial` over N generated profiles
//!   per latitude class (3N in all), every one of its 10 on-lines against the off-line, IPDA and
//!   DIAL, with the whole error budget, analytic lidar equation; or the same study with a cirrus
//!   in every profile ([`CIRRUS`]), which takes a Monte Carlo per truth of each profile.
//! - [`scene_variants`] and [`crate::pipeline::compare_skip`]: what skipping saves on whole scene runs.
//! - [`channels`]: the cost of a scattering event against the number of channels (the default
//!   scene at 2, 4 and 16 channels beside C.1's one).
//! - [`depth`]: the figure of merit of C.1's multiple scattering at every gate and field of view
//!   against the plain local estimate.

pub mod channels;
pub mod depth;

use std::path::Path;
use std::time::Instant;

use crate::atmosphere::{LatitudeClass, ProfileSet, class_ensemble};
use crate::optics::OpticalAtmosphere;
use crate::returns::Order;
use crate::scene::Scene;
use crate::scene::Simulation;
use crate::stats;
use crate::study::dial::{self, StudyOptions};
use crate::transport::{self, McResult, Progress, TallyLayout};

const C1_SCENE: &str = include_str!("../../scenes/bissonnette_c1.toml");
const C1_TABLE_FILE: &str = r#"file = "../phase_functions/bissonnette_c1_1064nm.txt""#;
const C1_TABLE_BUILTIN: &str = r#"builtin = "bissonnette_c1_1064nm""#;
const STUDY_SCENE: &str = include_str!("../../scenes/study_co2_ipda.toml");

/// The cirrus of the cloudy study benchmark, added to the study scene: 9–10 km, vertical
/// optical depth 0.3, Henyey-Greenstein g = 0.75 (lidarsim has no ice-crystal phase function;
/// 0.75 is a typical cirrus asymmetry parameter near 1.6 µm), nearly conservative.
pub const CIRRUS: &str = r#"
[[layer]]
name = "cirrus"
base_m = 9000.0
top_m = 10000.0
extinction_per_km = 0.3
single_scattering_albedo = 0.99
phase = { kind = "henyey_greenstein", g = 0.75 }
"#;

/// Photons per truth of the cloudy study benchmark unless asked otherwise.
pub const CLOUDY_STUDY_PHOTONS: u64 = 20_000;

/// Photons of a forced Monte Carlo for a scene that asks for none (the default scene's count).
pub const FORCED_PHOTONS: u64 = 200_000;

/// Why a benchmark could not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// A scene (an embedded one included).
    #[error(transparent)]
    Input(#[from] crate::input::InputError),
    /// The optical atmosphere.
    #[error(transparent)]
    Optics(#[from] crate::optics::OpticsError),
    /// The transport.
    #[error(transparent)]
    Transport(#[from] crate::transport::TransportError),
    /// A whole run.
    #[error(transparent)]
    Run(#[from] crate::pipeline::RunError),
    /// The ensemble study.
    #[error(transparent)]
    Study(#[from] crate::study::dial::StudyError),
    /// The ensemble.
    #[error(transparent)]
    Atmosphere(#[from] crate::atmosphere::AtmosphereError),
    /// Writing a file.
    #[error(transparent)]
    Output(#[from] crate::output::OutputError),
    /// The thread pool.
    #[error("cannot start the threads: {0}")]
    Threads(#[from] rayon::ThreadPoolBuildError),
    /// A workload or a reference file that cannot be used, with the reason.
    #[error("{0}")]
    Invalid(String),
}

/// `Err(BenchError::Invalid(message))` unless `condition`.
macro_rules! ensure {
    ($cond:expr, $($t:tt)*) => {
        if !$cond {
            return Err($crate::benchmark::BenchError::Invalid(format!($($t)*)));
        }
    };
}
pub(crate) use ensure;

/// The C.1 scene with a single 1 mrad field of view, orders split into 1 and 2+.
pub fn c1_scene() -> Result<Scene, BenchError> {
    ensure!(
        C1_SCENE.contains(C1_TABLE_FILE),
        "the C.1 scene no longer names its table"
    );
    let text = C1_SCENE.replace(C1_TABLE_FILE, C1_TABLE_BUILTIN);
    let mut scene = Scene::from_toml(Path::new("<embedded scenes/bissonnette_c1.toml>"), &text)?;
    scene.lidar.fov_full_angle_mrad = vec![1.0];
    scene.simulation.max_order = 1;
    Ok(scene)
}

/// Run `scene` `repeat` times with its settings changed by `configure`; the fastest run (least
/// disturbed by other load).
pub fn fastest(
    scene: &Scene,
    atm: &OpticalAtmosphere,
    threads: usize,
    repeat: usize,
    configure: impl Fn(&mut Simulation),
) -> Result<McResult, BenchError> {
    fastest_with(scene, atm, threads, repeat, configure, &transport::quiet)
}

/// [`fastest`], reporting each run's batches to `progress`.
pub fn fastest_with(
    scene: &Scene,
    atm: &OpticalAtmosphere,
    threads: usize,
    repeat: usize,
    configure: impl Fn(&mut Simulation),
    progress: Progress,
) -> Result<McResult, BenchError> {
    let mut best: Option<McResult> = None;
    for _ in 0..repeat.max(1) {
        let mut s = scene.clone();
        s.simulation.threads = threads;
        configure(&mut s.simulation);
        let plan = transport::Plan::new(&s, atm, &TallyLayout::default())?;
        let r = transport::run_plan(&plan, progress)?;
        if best.as_ref().is_none_or(|b| r.wall_s < b.wall_s) {
            best = Some(r);
        }
    }
    best.ok_or_else(|| BenchError::Invalid("at least one run".into()))
}

/// The transport benchmark's workload: C.1 with `photons` and `seed`, its optical atmosphere,
/// and the gate 100 m into the cloud whose multiple scattering is measured.
pub struct TransportWorkload {
    /// The scene.
    pub scene: Scene,
    /// Its optical atmosphere.
    pub atm: OpticalAtmosphere,
    /// The gate measured.
    pub gate: usize,
}

impl TransportWorkload {
    /// C.1 with `photons` and `seed`.
    pub fn new(photons: u64, seed: u64) -> Result<Self, BenchError> {
        let mut scene = c1_scene()?;
        scene.simulation.photons = photons;
        scene.simulation.seed = seed;
        let atm = OpticalAtmosphere::build(&scene)?;
        let gate = scene
            .gates
            .count
            .min(((1100.0 - scene.gates.start_m) / scene.gates.width_m).round() as usize);
        Ok(TransportWorkload { scene, atm, gate })
    }

    /// The measured gate's start and end \[m\].
    pub fn gate_m(&self) -> (f64, f64) {
        let g = &self.scene.gates;
        (
            g.start_m + self.gate as f64 * g.width_m,
            g.start_m + (self.gate + 1) as f64 * g.width_m,
        )
    }

    /// The title and the columns of the table of [`TransportRow::line`].
    pub fn header(&self) -> String {
        let (start_m, end_m) = self.gate_m();
        format!(
            "Bissonnette C.1, 1064 nm, FOV 1 mrad, {} photons; FOM of the multiple-scattering return at {start_m}–{end_m} m\n\
             threads  wall_s   photons/s   events/s  events/s/thread   E_ms [J]      rel_err     FOM [1/s]",
            self.scene.simulation.photons
        )
    }

    /// The fastest of `repeat` runs on `threads` threads with `configure`, measured.
    pub fn measure(
        &self,
        threads: usize,
        repeat: usize,
        configure: impl Fn(&mut Simulation),
    ) -> Result<TransportRow, BenchError> {
        let r = fastest(&self.scene, &self.atm, threads, repeat, configure)?;
        let ms = Order::AtLeast(2);
        let e = r.returns.energy(0, 0, self.gate, ms).unwrap_or(0.0);
        let se = r.returns.stderr(0, 0, self.gate, ms).unwrap_or(f64::NAN);
        let rel = stats::rel_err(e, se);
        let eps = r.stats.collisions as f64 / r.wall_s;
        Ok(TransportRow {
            threads: r.threads,
            wall_s: r.wall_s,
            photons: r.photons,
            photons_per_s: r.photons as f64 / r.wall_s,
            events_per_s: eps,
            multiple_scattering_j: e,
            rel_err: rel,
            fom_per_s: stats::figure_of_merit(rel, r.wall_s),
        })
    }
}

/// One thread count of the transport benchmark.
#[derive(Debug, Clone, Copy)]
pub struct TransportRow {
    /// Threads the run used.
    pub threads: usize,
    /// Wall-clock time of the transport \[s\].
    pub wall_s: f64,
    /// Photons traced.
    pub photons: u64,
    /// Photons per second.
    pub photons_per_s: f64,
    /// Scattering events per second.
    pub events_per_s: f64,
    /// The gate's multiple-scattering energy \[J\].
    pub multiple_scattering_j: f64,
    /// Its relative standard error.
    pub rel_err: f64,
    /// Its figure of merit \[1/s\].
    pub fom_per_s: f64,
}

impl TransportRow {
    /// The row of the table [`TransportWorkload::header`] begins.
    pub fn line(&self) -> String {
        let r = self;
        format!(
            "{:>7} {:>7.2} {:>11.3e} {:>10.3e} {:>16.3e} {:>10.4e} {:>11.3e} {:>11.3e}",
            r.threads,
            r.wall_s,
            r.photons_per_s,
            r.events_per_s,
            r.events_per_s / r.threads as f64,
            r.multiple_scattering_j,
            r.rel_err,
            r.fom_per_s
        )
    }

    /// The row as JSON (`--json`).
    pub fn json(&self) -> serde_json::Value {
        let eps = self.events_per_s;
        serde_json::json!({
            "threads": self.threads, "wall_s": self.wall_s, "photons": self.photons,
            "photons_per_s": self.photons_per_s, "events_per_s": eps, "events_per_s_per_thread": eps / self.threads as f64,
            "multiple_scattering_j": self.multiple_scattering_j, "rel_err": self.rel_err, "fom_per_s": self.fom_per_s,
        })
    }
}

/// The variants of a scene the skipping benchmark times: the scene, and without its particle
/// layers if it has any, each with its name.
pub fn scene_variants(path: &Path) -> Result<Vec<(String, Scene)>, BenchError> {
    let scene = Scene::read(path)?;
    let mut variants = vec![(path.display().to_string(), scene.clone())];
    if !scene.layers.is_empty() {
        let mut clear = scene.clone();
        clear.layers.clear();
        variants.push((format!("{} without its layers", path.display()), clear));
    }
    Ok(variants)
}

/// The title and the columns of the table of the skipping benchmark, fastest of `repeat`.
pub fn scenes_header(repeat: usize) -> String {
    format!(
        "whole runs (`lidarsim run`, no figures), fastest of {repeat}; forced = multiple_scattering \"always\" ({FORCED_PHOTONS} photons if the scene asks for none)\n\
         | scene | threads | Monte Carlo (auto) | optics s | auto s | forced s | forced transport s | saved s | why |\n\
         |---|---|---|---|---|---|---|---|---|"
    )
}

/// The row of the skipping benchmark's table of the scene `name` on `threads` threads, and the
/// same as JSON.
pub fn scene_row(
    name: &str,
    threads: usize,
    c: &crate::pipeline::Comparison,
) -> (String, serde_json::Value) {
    let saved = c.forced_s - c.auto_s;
    // Both run the Monte Carlo: their difference is only the noise of the machine.
    let saved_text = if c.decision.run {
        "— (both run it)".to_string()
    } else {
        format!("{saved:.3}")
    };
    let line = format!(
        "| {name} | {threads} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {saved_text} | {} |",
        if c.decision.run { "run" } else { "skipped" },
        c.optics_s,
        c.auto_s,
        c.forced_s,
        c.forced_transport_s,
        c.decision.reason
    );
    let json = serde_json::json!({
        "scene": name, "threads": threads, "monte_carlo_run": c.decision.run,
        "reason": c.decision.reason, "optics_s": c.optics_s, "auto_s": c.auto_s,
        "forced_s": c.forced_s, "forced_photons": c.forced_photons,
        "forced_transport_s": c.forced_transport_s, "saved_s": saved,
    });
    (line, json)
}

/// The ensemble study benchmark's workload (module docs).
pub struct StudyWorkload {
    /// The study scene.
    pub scene: Scene,
    /// 3N generated profiles.
    pub set: ProfileSet,
    /// Every on-line against the off-line.
    pub options: StudyOptions,
    /// Time to generate the ensemble \[s\].
    pub generate_s: f64,
}

impl StudyWorkload {
    /// N profiles per class from `seed`; refused beyond the limits for `runs` studies of them
    /// (every thread count, every repeat). With `cirrus_photons` > 0 every profile has the
    /// [`CIRRUS`] and each of its truths takes a Monte Carlo of that many photons.
    pub fn new(n: usize, seed: u64, runs: u64, cirrus_photons: u64) -> Result<Self, BenchError> {
        let scene = if cirrus_photons > 0 {
            Scene::from_toml(
                Path::new("<embedded scenes/study_co2_ipda.toml with a cirrus>"),
                &format!("{STUDY_SCENE}{CIRRUS}"),
            )?
        } else {
            Scene::from_toml(
                Path::new("<embedded scenes/study_co2_ipda.toml>"),
                STUDY_SCENE,
            )?
        };
        let no_retrieval = || BenchError::Invalid("study scene has a retrieval".into());
        let retrieval = scene.retrieval.as_ref().ok_or_else(no_retrieval)?;
        let pairs: Vec<(usize, usize)> = (0..scene.lines.len())
            .filter(|&k| k != retrieval.off)
            .map(|k| (k, retrieval.off))
            .collect();
        // Every thread count runs the study `repeat` times: its size before the ensemble is
        // drawn (README, "Limits").
        let work = crate::pipeline::study_work(
            &scene,
            (3 * n as u64).saturating_mul(runs),
            cirrus_photons,
        )?;
        work.check().map_err(|m| {
            BenchError::Invalid(format!("--study {n} (× --threads, × --repeat): {m}"))
        })?;
        work.warnings().iter().for_each(|w| crate::limits::warn(w));
        let t = Instant::now();
        let mut set = ProfileSet::default();
        for (i, c) in LatitudeClass::ALL.iter().enumerate() {
            set.members.extend(
                class_ensemble(*c, n, seed.wrapping_add(i as u64))?
                    .0
                    .members,
            );
        }
        let generate_s = t.elapsed().as_secs_f64();
        let options = StudyOptions {
            pairs,
            seed,
            photons: cirrus_photons,
            ..StudyOptions::from_scene(&scene).ok_or_else(no_retrieval)?
        };
        Ok(StudyWorkload {
            scene,
            set,
            options,
            generate_s,
        })
    }

    /// The title (of N profiles per class) and the columns of the table of [`Self::row`].
    pub fn header(&self, n: usize) -> String {
        let cells = self
            .scene
            .retrieval
            .as_ref()
            .and_then(|r| r.dial)
            .map_or(0, |d| d.cells);
        let (kind, sums) = if self.options.photons > 0 {
            (
                format!(
                    "cloudy ensemble study (cirrus 9–10 km, τ 0.3, HG g 0.75 in every profile; Monte Carlo of {} photons per truth, 5 truths per profile, profiles one after another, each transport on the threads)",
                    self.options.photons
                ),
                "  transport_s  transport_share  (wall: one profile at a time)",
            )
        } else {
            ("ensemble study".to_string(), "  (thread-summed)")
        };
        format!(
            "{kind}: {} profiles (3 classes × {n}), {} on-lines × IPDA and {} DIAL cells, error budget of {} rows; ensemble generated in {:.2} s\n\
             threads  wall_s  profiles/s  ms/profile  truth_optics_s  returns_s  references_s  retrievals_s{sums}",
            self.set.len(),
            self.options.pairs.len(),
            cells,
            dial::N_SOURCES,
            self.generate_s
        )
    }

    /// The row of the table of the timing `t` on `threads` threads, and the same as JSON.
    pub fn row(&self, threads: usize, t: &dial::Timing) -> (String, serde_json::Value) {
        let profiles = self.set.len() as f64;
        let mut line = format!(
            "{:>7} {:>7.2} {:>11.1} {:>11.2} {:>15.2} {:>10.2} {:>13.2} {:>13.2}",
            threads,
            t.wall_s,
            profiles / t.wall_s,
            1e3 * t.wall_s / profiles,
            t.truth_optics_s,
            t.returns_s,
            t.references_s + t.mean_references_s,
            t.retrievals_s
        );
        if self.options.photons > 0 {
            line += &format!(
                " {:>12.2} {:>15.1} %",
                t.transport_s,
                100.0 * t.transport_s / t.wall_s
            );
        }
        let json = serde_json::json!({
            "threads": threads, "profiles": self.set.len(), "wall_s": t.wall_s,
            "ms_per_profile": 1e3 * t.wall_s / profiles, "photons_per_truth": self.options.photons,
            "generate_s": self.generate_s, "truth_optics_s": t.truth_optics_s, "returns_s": t.returns_s,
            "transport_s": t.transport_s,
            "references_s": t.references_s + t.mean_references_s, "retrievals_s": t.retrievals_s,
        });
        (line, json)
    }

    /// The fastest of `repeat` studies on `pool`: its timing; an error if a profile failed.
    pub fn measure(
        &self,
        pool: &rayon::ThreadPool,
        repeat: usize,
    ) -> Result<Option<dial::Timing>, BenchError> {
        let mut best: Option<dial::Timing> = None;
        // A Monte Carlo study runs its profiles one after another, each transport on its own
        // threads: as many as the pool has.
        let mut scene = self.scene.clone();
        scene.simulation.threads = pool.current_num_threads();
        for _ in 0..repeat {
            let r = pool.install(|| dial::run(&scene, &self.set, &self.options, &|| {}))?;
            let failed = r.outcomes.iter().filter(|o| o.records.is_err()).count();
            ensure!(failed == 0, "{failed} profiles failed");
            if best.is_none_or(|b| r.timing.wall_s < b.wall_s) {
                best = Some(r.timing);
            }
        }
        Ok(best)
    }
}
