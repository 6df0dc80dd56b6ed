//! The products of the commands: every file `run`, `dial`, `select-lines` and `merge` write
//! (the CSV tables, `summary.json`, the NetCDF files) and the reports they print, made from the
//! in-memory results of the pipeline and the studies. The caller (the command line, a notebook)
//! supplies the figures, which this library does not draw, through a callback that stages them
//! in the same [`OutputSet`](crate::output::OutputSet): all files of a command are written
//! together or none.
//!
//! | command | module | files |
//! |---|---|---|
//! | `run` | [`run`] | `returns.csv`, `depolarisation.csv`, `signals.csv`, `retrieval.csv`, `run.nc`, `summary.json` |
//! | `dial` | [`dial`] | `profiles.csv`, `summary.csv`, `budget.csv`, `failed.csv`, `profiles.nc`, `summary.nc`, `summary.json` |
//! | `select-lines` | [`select`] | `sensitivities.csv`, `sensitivities.nc`, `failed.csv` |
//! | `merge` | [`merge`] | those of the command whose shards it folds |
//! | `lbl` | [`lbl`] | the cross-section and layer optical-depth tables |
//! | `mie` | [`mie`] | the JSON it prints |
//! | `profiles info` | [`profiles`] | the table it prints |

pub mod dial;
pub mod lbl;
pub mod merge;
pub mod mie;
pub mod profiles;
pub mod run;
pub mod select;

use std::path::Path;

use crate::scene::{Scene, SceneOverride};

/// Why a command's products could not be made or written.
#[derive(Debug, thiserror::Error)]
pub enum ProductError {
    /// Staging or committing the files.
    #[error(transparent)]
    Output(#[from] crate::output::OutputError),
    /// Making a NetCDF file.
    #[error(transparent)]
    Netcdf(#[from] crate::netcdf::NetcdfError),
    /// Reading the scene.
    #[error(transparent)]
    Input(#[from] crate::input::InputError),
    /// Reading or folding shard files.
    #[error(transparent)]
    Shard(#[from] crate::shard::ShardError),
    /// A study's results that cannot be reported (a group that fails its checks).
    #[error(transparent)]
    Select(#[from] crate::study::select::SelectError),
    /// A request that cannot be resolved (an option that names nothing, a study beyond the
    /// limits), with the reason.
    #[error("{0}")]
    Request(String),
    /// Sizing a study.
    #[error(transparent)]
    Optics(#[from] crate::optics::OpticsError),
    /// Setting up a study.
    #[error(transparent)]
    Study(#[from] crate::study::dial::StudyError),
    /// The atmosphere (a profile, a covariance, an ensemble).
    #[error(transparent)]
    Atmosphere(#[from] crate::atmosphere::AtmosphereError),
    /// Writing a report (a closed pipe: `lidarsim … | head`).
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// Mie scattering.
    #[error(transparent)]
    Mie(#[from] crate::particles::mie::MieError),
    /// An error and the option or value it concerns.
    #[error("{context}")]
    Context {
        /// The option or value.
        context: String,
        /// The error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// Profiles of a study failed: every one of them, or any with
    /// [`FailurePolicy::Strict`](crate::study::FailurePolicy::Strict). Nothing is written as if
    /// the study had succeeded; the one line says the counts by reason
    /// ([`crate::study::FailureReport::verdict`]).
    #[error("{0}")]
    ProfilesFailed(String),
}

impl ProductError {
    /// `source` with the option or value it concerns (as `anyhow`'s `context`).
    pub fn context(
        context: &str,
        source: impl std::error::Error + Send + Sync + 'static,
    ) -> ProductError {
        ProductError::Context {
            context: context.to_string(),
            source: Box::new(source),
        }
    }
}

/// The scene of a command: the file at `path` (`-`: standard input), or the embedded default
/// scene without one, with the command line's `--set` overrides ([`Scene::read_with`]). A
/// shard (`absolute`) reads a file by its absolute path, so that shards started from different
/// directories agree ([`crate::shard::read_scene`]).
pub fn read_scene(
    path: Option<&Path>,
    overrides: &[SceneOverride],
    absolute: bool,
) -> Result<Scene, ProductError> {
    match path {
        Some(p) if absolute && p != Path::new("-") => {
            let abs = std::fs::canonicalize(p).map_err(|error| crate::shard::ShardError::Io {
                path: p.to_path_buf(),
                error,
            })?;
            Ok(Scene::read_with(&abs, overrides)?)
        }
        Some(p) => Ok(Scene::read_with(p, overrides)?),
        None => Ok(Scene::default_with(overrides)?),
    }
}
