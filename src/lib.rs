//! lidarsim: a simulation testbed for atmospheric lidars.
//!
//! The library follows the pipeline of `DESIGN.md`: each module is one stage, consuming the
//! previous stage's plain data types and producing its own.
//!
//! | stage | module | produces |
//! |---|---|---|
//! | scene file | [`scene`] | a validated [`scene::Scene`] |
//! | atmospheric state | [`atmosphere`] | [`atmosphere::Profile`] |
//! | gas absorption | [`spectroscopy`] | cross-sections, layer optical depths |
//! | particles | [`particles`] | phase functions, Rayleigh and Mie optics |
//! | optical atmosphere | [`optics`] | [`optics::OpticalAtmosphere`], the one input of transport |
//! | Monte Carlo | [`transport`] | [`returns::Returns`] by channel, FOV, gate and order |
//! | analytic single scatter | [`lidar_eq`] | [`returns::Returns`], order 1 |
//! | the aperture seen from close by | [`aperture`] | the factors both estimators share |
//! | what a scene does not need | [`skip`] | whether the Monte Carlo runs, and why |
//!
//! Beside the stages: [`output`] writes a command's files whole or not at all, and [`netcdf`]
//! makes `run.nc`, the CF NetCDF file of a run's returns, signals and retrievals.

#![forbid(unsafe_code)]
#![deny(missing_docs)]
// Numerical kernels index several parallel per-channel arrays with one index; iterator chains
// would hide that. `!(x > 0.0)` is used on purpose: it is true for NaN as well.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod aperture;
pub mod atmosphere;
pub mod constants;
pub mod digest;
#[cfg(feature = "mpi")]
pub mod distributed;
pub mod input;
pub mod instrument;
pub mod lidar_eq;
pub mod limits;
pub mod netcdf;
pub mod optics;
pub mod output;
pub mod particles;
pub mod pipeline;
pub mod retrieval;
pub mod returns;
pub mod rng;
pub mod scene;
pub mod shard;
pub mod skip;
pub mod spectroscopy;
pub mod stats;
pub mod study;
pub mod transport;
