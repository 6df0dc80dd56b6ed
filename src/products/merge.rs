//! `lidarsim merge`: which command's shards the inputs hold, the files that command writes,
//! and the shards folded into its results ([`crate::shard`], [`crate::study::shard`],
//! [`crate::study::select_shard`]); the caller then writes them as the command would
//! ([`super::run`], [`super::dial`], [`super::select`]).

use std::path::{Path, PathBuf};

use super::ProductError;
use crate::shard;
use crate::study::select_shard::SelectMerged;
use crate::study::shard::DialMerged;

/// The shard files of one run or study, found and checked to be of one kind.
pub struct Shards {
    inputs: Vec<PathBuf>,
    paths: Vec<PathBuf>,
    kind: String,
}

/// The shards of one run or study folded together.
pub enum Merged {
    /// `lidarsim run --shard I/N`.
    Run(Box<shard::Merged>),
    /// `lidarsim dial --shard I/N`.
    Dial(Box<DialMerged>),
    /// `lidarsim select-lines --shard I/N`.
    Select(Box<SelectMerged>),
}

/// The shard files of `inputs` (directories holding `*.lshard` files, or the files), all of one
/// command.
pub fn find(inputs: &[PathBuf]) -> Result<Shards, ProductError> {
    let paths = shard::shard_paths(inputs)?;
    let kind = shard::common_kind(&paths)?;
    Ok(Shards {
        inputs: inputs.to_vec(),
        paths,
        kind,
    })
}

impl Shards {
    /// The files the merge may write into `dir`, to be checked before the work. A select-lines
    /// study's figures are left out: their names depend on the groups and are checked when
    /// written.
    pub fn files(&self, dir: &Path) -> Vec<PathBuf> {
        if self.kind == shard::KIND_SELECT {
            [
                "sensitivities.csv",
                "sensitivities.nc",
                super::select::FAILED_CSV,
            ]
            .map(|f| dir.join(f))
            .to_vec()
        } else if self.kind == shard::KIND_DIAL {
            super::dial::FILES.map(|f| dir.join(f)).to_vec()
        } else {
            super::run::FILES.map(|f| dir.join(f)).to_vec()
        }
    }

    /// Read and fold the shards.
    pub fn merge(&self) -> Result<Merged, ProductError> {
        Ok(if self.kind == shard::KIND_SELECT {
            Merged::Select(Box::new(crate::study::select_shard::merge(&self.paths)?))
        } else if self.kind == shard::KIND_DIAL {
            Merged::Dial(Box::new(crate::study::shard::merge(&self.paths)?))
        } else {
            Merged::Run(Box::new(shard::merge(&self.inputs)?))
        })
    }
}
