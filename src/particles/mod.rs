//! Particle and molecular scattering: phase functions, Rayleigh cross-sections, Mie.
//!
//! Consumes particle descriptions (Henyey-Greenstein parameters, phase-function tables, size
//! distributions with a refractive index); produces scattering coefficients, single-scattering
//! albedos and [`phase::PhaseFunction`]s that the transport can evaluate and sample.

pub mod distribution;
pub mod mie;
pub mod phase;
pub mod rayleigh;
pub mod table;
