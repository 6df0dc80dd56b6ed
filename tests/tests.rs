//! lidarsim integration tests: one binary, one module per theme (`cargo test --release`).
#![allow(clippy::neg_cmp_op_on_partial_ord)] // `!(a < b)` is meant to be true for NaN too.

mod util;

/// Atmospheric state: standard atmospheres, profile sets, ensembles.
mod atmosphere;
/// Beyond-Voigt line shapes against HAPI, HITRAN conventions, CSV line lists.
mod beyond_voigt;
/// The command line.
mod cli;
/// Multiple scattering in clouds against closed forms (issue 10, item 3): absorption in a
/// far-viewed cloud, the single-scatter Platt integral.
mod clouds;
/// Edge-case scenes (issue 17, item 3): gates below, between and above particle layers, a
/// downward beam with no surface, slant paths to 89°, an optically thick layer; the analytic
/// lidar equation and the Monte Carlo against closed-form quadratures and each other.
mod edges;
/// Fuzzing: property tests over the readers, a mutation fuzz of the shipped scenes through the
/// binary (issue 11, item 4).
mod fuzz;
/// Every subcommand but `run` fuzzed through the binary: option values and input files
/// mutated, shard files damaged (issue 37, item 6).
mod fuzz_cli;
/// Scattering matrices (issue 16): Mie matrices against reference amplitudes and BH's output,
/// the dipole limit, the Mueller inequalities, C.1 near backscatter, scalar tables unchanged.
mod matrices;
/// `run.nc` read by xarray and netCDF4-python against the CSV files (issue 12, item 4).
mod netcdf;
/// Output written whole or not at all; CSV quoting.
mod output;
/// Particles: Mie, size distributions, phase-function tables and sampling.
mod particles;
/// Polarised transport: co- and cross-polarised returns and depolarisation ratios against
/// exact values (issue 16, item 4).
mod polarisation;
/// Instrument and retrieval: line shapes, noise, retrievals against the truth.
mod retrieval;
/// Every file lidarsim writes read back (issue 37, item 6): quoted CSV text, profile sets,
/// covariances, shards, Mie tables in scenes, gas optical-depth tables.
mod roundtrip;
/// Scenes: parsing, validation and their documented errors.
mod scene;
/// The scene's three steps (issue 38): a description built in code checked like a file,
/// written as TOML and read back, validated without reading a file.
mod scene_lifecycle;
/// Line selection for CO2 IPDA: sensitivities against hand-made finite differences, the CLI.
mod select_lines;
/// Sharded runs: `run --shard I/N` and `merge` against the single run; refused shard sets
/// (issue 12, item 1).
mod shard;
/// What a scene does not need: the Monte Carlo skipped where multiple scattering cannot
/// matter, no line-by-line work for absent gases (issue 10, item 4).
mod skip;
/// Line-by-line gas absorption against HAPI.
mod spectroscopy;
/// Extreme physical scenes: finite, conserved, bounded.
mod stress;
/// Ensemble studies: `lidarsim dial` and its error budget.
mod study;
/// `bench --depth`'s plain reference and `mie` without index contrast (issue 37: F4, F16).
mod tools_edges;
/// Monte Carlo transport against the analytic lidar equation and conservation laws.
mod transport;
/// Every input validated: hostile scene values, options and file fields refused at their file,
/// line and key; problem sizes refused before allocating (issue 11, item 1).
mod validation_inputs;
