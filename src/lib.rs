//! lidarsim: a simulation testbed for atmospheric lidars.
//!
//! The library follows the pipeline of `docs/design.md` (§1; §8 has the module map and the
//! import rule): each module is one stage, consuming the previous stage's plain data types and
//! producing its own, and imports only the stages below it.
//!
//! | stage | module | produces |
//! |---|---|---|
//! | scene description | [`scene`] | a [`scene::Scene`]: parsed, validated, resolved (`docs/design.md` §5) |
//! | atmospheric state | [`atmosphere`] | [`atmosphere::Profile`], profile sets and ensembles |
//! | gas absorption | [`spectroscopy`] | cross-sections, layer optical depths |
//! | particles | [`particles`] | phase functions, Rayleigh and Mie optics |
//! | laser lines, receiver, noise | [`instrument`] | channels of each line, line returns, [`instrument::signals::Signals`] |
//! | optical atmosphere | [`optics`] | [`optics::OpticalAtmosphere`], the one input of transport |
//! | Monte Carlo | [`transport`] | [`returns::Returns`] by channel, FOV, gate and order; with `jacobians`, [`jacobians::Jacobians`] from the same photons |
//! | analytic single scatter | [`lidar_eq`] | [`returns::Returns`], order 1 |
//! | attenuated backscatter | [`backscatter`] | β′ and the range-corrected signal of returns |
//! | the aperture seen from close by | [`aperture`] | the factors both estimators share |
//! | what a scene does not need | [`skip`] | whether the Monte Carlo runs, and why |
//! | retrievals | [`retrieval`] | IPDA and DIAL [`retrieval::Product`]s against the truth |
//! | a scene from end to end | [`pipeline`] | prepare → trace → finish: [`pipeline::RunOutput`] |
//! | batches traced elsewhere | [`shard`], `distributed` (feature `mpi`) | shard files, merged runs |
//! | ensemble studies | [`study`] | `dial` and `select-lines` results |
//!
//! Beside the stages: [`input`] and [`limits`] check what a user gives, [`products`] makes
//! every file and report of the commands from their in-memory results (`returns.csv`,
//! `summary.json`, `run.nc`, the study tables), [`output`] writes a command's files whole or not
//! at all, [`netcdf`] makes the CF NetCDF files, [`benchmark`] holds the workloads and
//! measurements of `lidarsim bench`, and [`digest`] is the one hash (FNV-1a 64) of cache keys,
//! fingerprints and shard checksums.
//!
//! # From Rust
//!
//! A scene from a file or from values, its settings changed, run through the pipeline's three
//! steps and written as `lidarsim run` writes it (`docs/design.md` §5–§7):
//!
//! ```no_run
//! use std::path::Path;
//!
//! use lidarsim::pipeline;
//! use lidarsim::scene::{PerChannel, Scene, SceneDescription};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! // Parse → validate (no I/O) → resolve (files, Mie, line lists).
//! let text = std::fs::read_to_string("scenes/bissonnette_c1.toml")?;
//! let mut description = SceneDescription::parse(Path::new("c1.toml"), &text)?;
//! description.lidar.fov_full_angle_mrad = PerChannel::Many(vec![0.5, 2.0]);
//! description.validate()?;
//! let mut scene: Scene = description.resolve(Path::new("scenes"))?;
//! // How it runs is one settings type.
//! scene.simulation.photons = 100_000;
//! // Prepare (optics, analytic returns, retrieval set-up, skip decision) → trace → finish.
//! let prepared = pipeline::prepare(&scene)?;
//! let mc = prepared.trace(&|done, total| eprintln!("{done}/{total} batches"))?;
//! let run = prepared.finish(mc)?;
//! // The files of `lidarsim run`, all or none (no figures here).
//! lidarsim::products::run::write(Path::new("out"), &scene, &run, None, |_| Ok(()))?;
//! # Ok(())
//! # }
//! ```

#![forbid(unsafe_code)]
#![deny(missing_docs)]
// Numerical kernels index several parallel per-channel arrays with one index; iterator chains
// would hide that. `!(x > 0.0)` is used on purpose: it is true for NaN as well.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod aperture;
pub mod atmosphere;
pub mod backscatter;
pub mod benchmark;
pub mod constants;
pub mod digest;
#[cfg(feature = "mpi")]
pub mod distributed;
pub mod input;
pub mod instrument;
pub mod jacobians;
pub mod lidar_eq;
pub mod limits;
pub mod netcdf;
pub mod optics;
pub mod output;
pub mod particles;
pub mod pipeline;
pub mod products;
pub mod retrieval;
pub mod returns;
pub mod rng;
pub mod scene;
pub mod shard;
mod simd;
/// What a scene does not need: whether the Monte Carlo runs ([`pipeline::skip`]).
pub use pipeline::skip;
pub mod spectroscopy;
pub mod stats;
pub mod study;
pub mod transport;
