//! lidarsim integration tests: one binary, one module per theme (`cargo test --release`).
#![allow(clippy::neg_cmp_op_on_partial_ord)] // `!(a < b)` is meant to be true for NaN too.

mod util;

/// Atmospheric state: standard atmospheres, profile sets, ensembles.
mod atmosphere;
/// Attenuated backscatter and the range-corrected signal: the analytic order 1 against β T² O
/// by hand, the Monte Carlo against it on C.1, `backscatter.csv` against `returns.csv`.
mod backscatter;
/// Beyond-Voigt line shapes against HAPI, HITRAN conventions, CSV line lists.
mod beyond_voigt;
/// The command line.
mod cli;
/// The command line's habits: counts as people write them, the scene first, from stdin, with
/// `--set` overrides; errors that name what to use instead.
mod cli_habits;
/// Multiple scattering in clouds against closed forms: absorption in a
/// far-viewed cloud, the single-scatter Platt integral.
mod clouds;
/// Edge-case scenes: gates below, between and above particle layers, a
/// downward beam with no surface, slant paths to 89°, an optically thick layer; the analytic
/// lidar equation and the Monte Carlo against closed-form quadratures and each other.
mod edges;
/// Every command that produces returns or a study writes its figures.
mod figures;
/// Fuzzing: property tests over the readers, a mutation fuzz of the shipped scenes through the
/// binary.
mod fuzz;
/// Every subcommand but `run` fuzzed through the binary: option values and input files
/// mutated, shard files damaged.
mod fuzz_cli;
/// Scattering matrices: Mie matrices against reference amplitudes and BH's output,
/// the dipole limit, the Mueller inequalities, C.1 near backscatter, scalar tables unchanged.
mod matrices;
/// Multiple scattering as a measured quantity: the `2+` rows' errors, Jacobians.
mod multiple_scattering;
/// `run.nc` read by xarray and netCDF4-python against the CSV files.
mod netcdf;
/// Output written whole or not at all; CSV quoting.
mod output;
/// Particles: Mie, size distributions, phase-function tables and sampling.
mod particles;
/// Physical inputs as users give them: CO2 well mixed in dry air, clouds by water content and
/// effective radius, warnings of implausible values.
mod physical_inputs;
/// Polarised transport: co- and cross-polarised returns and depolarisation ratios against
/// exact values.
mod polarisation;
/// Instrument and retrieval: line shapes, noise, retrievals against the truth.
mod retrieval;
/// Every file lidarsim writes read back: quoted CSV text, profile sets,
/// covariances, shards, Mie tables in scenes, gas optical-depth tables.
mod roundtrip;
/// Scenes: parsing, validation and their documented errors.
mod scene;
/// The scene's three steps: a description built in code checked like a file,
/// written as TOML and read back, validated without reading a file.
mod scene_lifecycle;
/// Line selection for CO2 IPDA: sensitivities against hand-made finite differences, the CLI.
mod select_lines;
/// Sharded runs: `run --shard I/N` and `merge` against the single run; refused shard sets
///.
mod shard;
/// What a scene does not need: the Monte Carlo skipped where multiple scattering cannot
/// matter, no line-by-line work for absent gases.
mod skip;
/// The bound on multiple scattering against the Monte Carlo: aerosol, cirrus and a water cloud
/// from the ground and from space, with and without a surface.
mod skip_bound;
/// Line-by-line gas absorption against HAPI.
mod spectroscopy;
/// Extreme physical scenes: finite, conserved, bounded.
mod stress;
/// Ensemble studies: `lidarsim dial` and its error budget.
mod study;
/// `bench --depth`'s plain reference and `mie` without index contrast (F4, F16).
mod tools_edges;
/// Monte Carlo transport against the analytic lidar equation and conservation laws.
mod transport;
/// Every input validated: hostile scene values, options and file fields refused at their file,
/// line and key; problem sizes refused before allocating.
mod validation_inputs;
