//! Testbed studies: how a lidar's retrieval behaves over many atmospheres.
//!
//! * [`dial`]: a scene's instrument and retrievals run for every profile of an ensemble, with
//!   the error of each profile's retrieval and an error budget per class and line pair (the
//!   seed paper's study: 300 NWP-perturbed profiles per latitude class);
//! * [`select`]: sensitivities of candidate on/off line positions (line selection), set up and
//!   summarised as `lidarsim select-lines` does by [`select_study`].
//!
//! [`shard`] and [`select_shard`] run slices of either study and merge them.
//!
//! Both call the stages (atmosphere, spectroscopy, optics, lidar equation, instrument,
//! retrieval) directly, once per profile, without files in between.

pub mod dial;
pub mod select;
pub mod select_shard;
pub mod select_study;
pub mod shard;
