//! Rayleigh scattering (in progress).
