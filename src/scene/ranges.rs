//! The physical range of every numeric scene key, in the unit its name says.
//!
//! A value outside is refused at its own line and key. The ranges are generous (they admit any
//! instrument or atmosphere lidarsim can model) and exist to refuse typing errors and values
//! that would overflow or hang the computation (a pulse of 1e300 J, an extinction of 1e18 per
//! metre); where a bound has a specific reason it is given.

use crate::input::Bounds;

/// Altitudes and heights of anything in the scene \[m\] (lidar, surface, layers, profile
/// levels, top of the atmosphere): from below the Dead Sea to beyond geostationary orbit.
pub(super) const ALTITUDE_M: Bounds = Bounds::closed(-1e4, 1e8);
/// The same in km.
pub(super) const ALTITUDE_KM: Bounds = Bounds::closed(-10.0, 1e5);
/// Zenith angle of the pointing \[deg\].
pub(super) const ZENITH_DEG: Bounds = Bounds::closed(0.0, 180.0);
/// Azimuth of the pointing \[deg\].
pub(super) const AZIMUTH_DEG: Bounds = Bounds::closed(-360.0, 360.0);
/// Pulse energy \[J\]: from a femtojoule (a million times below the microjoule pulses of
/// photon-counting lidars; smaller pulses would only give energies near the end of the double
/// range, subnormal, with meaningless error bars) to a kilojoule.
pub(super) const PULSE_ENERGY_J: Bounds = Bounds::closed(1e-15, 1e3);
/// Full divergence angle of the beam \[mrad\]: a lidar beam, not a lamp.
pub(super) const DIVERGENCE_MRAD: Bounds = Bounds::below(0.0, 1000.0);
/// Full angle of a field of view \[mrad\].
pub(super) const FOV_MRAD: Bounds = Bounds::open(0.0, 1000.0);
/// Telescope diameter \[m\]: from 0.1 mm.
pub(super) const TELESCOPE_DIAMETER_M: Bounds = Bounds::closed(1e-4, 100.0);
/// Efficiencies and transmissions that must pass some light: [1e-9, 1] (any real optics passes
/// more than a billionth; below, energies again reach the subnormal range).
pub(super) const EFFICIENCY: Bounds = Bounds::closed(1e-9, 1.0);
/// Fractions, albedos, single-scattering albedos, reflectances: [0, 1].
pub(super) const FRACTION: Bounds = Bounds::closed(0.0, 1.0);
/// Vacuum wavelength of a channel \[nm\] (100 nm to 100 µm).
pub(super) const WAVELENGTH_NM: Bounds = Bounds::closed(100.0, 1e5);
/// Vacuum wavenumber of a channel or a grid \[cm⁻¹\] (the same span).
pub(super) const WAVENUMBER_CM1: Bounds = Bounds::closed(100.0, 1e5);
/// Start and end of the range gates \[m\].
pub(super) const RANGE_M: Bounds = Bounds::positive(1e8);
/// Gate width \[m\].
pub(super) const GATE_WIDTH_M: Bounds = Bounds::positive(1e7);
/// CO2 dry-air column average \[ppm\].
pub(super) const CO2_PPM: Bounds = Bounds::positive(1e6);
/// Air number density of an explicit profile \[1/m³\] (sea level is 2.5e25).
pub(super) const AIR_NUMBER_DENSITY_PER_M3: Bounds = Bounds::positive(1e27);
/// Thickness of the molecular layers \[m\].
pub(super) const LAYER_THICKNESS_M: Bounds = Bounds::positive(1e6);
/// Depolarisation factor of air (Bucholtz's values are near 0.03; 0.5 would make the phase
/// function singular).
pub(super) const DEPOLARISATION: Bounds = Bounds::closed(0.0, 0.49);
/// Particle extinction and extra absorption coefficients \[1/m\]: 1000 per metre is a
/// visibility of 4 mm, far denser than any fog or cloud, and leaves room for opaque test
/// layers (a hard target made of fog).
pub(super) const COEFFICIENT_PER_M: Bounds = Bounds::closed(0.0, 1e3);
/// The same per km.
pub(super) const COEFFICIENT_PER_KM: Bounds = Bounds::closed(0.0, 1e6);
/// Particle number density \[1/cm³\].
pub(super) const PARTICLE_DENSITY_PER_CM3: Bounds = Bounds::positive(1e10);
/// Particle radii of a size distribution \[µm\] (up to 1 cm rain drops).
pub(super) const RADIUS_UM: Bounds = Bounds::positive(1e4);
/// Condensed water content of a cloud \[g/m³\] (convective cores reach ~5).
pub(super) const WATER_CONTENT_G_PER_M3: Bounds = Bounds::positive(100.0);
/// Geometric standard deviation of a log-normal distribution.
pub(super) const SIGMA_G: Bounds = Bounds::above(1.0, 10.0);
/// Shape parameters `alpha`, `b`, `gamma` of a modified gamma distribution.
pub(super) const GAMMA_SHAPE: Bounds = Bounds::closed(-10.0, 1e3);
/// Line wing cutoff \[cm⁻¹\].
pub(super) const WING_CM1: Bounds = Bounds::positive(1e3);
/// Step of a gas optical-depth table \[cm⁻¹\].
pub(super) const TABLE_STEP_CM1: Bounds = Bounds::positive(10.0);
/// Laser repetition rate \[Hz\].
pub(super) const REPETITION_RATE_HZ: Bounds = Bounds::positive(1e9);
/// Laser line width (FWHM) \[MHz\]: up to 1 THz.
pub(super) const LINEWIDTH_MHZ: Bounds = Bounds::positive(1e6);
/// Frequency offset of a laser line \[MHz\]: beyond 100 GHz it is another line, not an offset.
pub(super) const FREQUENCY_OFFSET_MHZ: Bounds = Bounds::closed(-1e5, 1e5);
/// Frequency jitter (rms) \[MHz\]: below 10 GHz.
pub(super) const FREQUENCY_JITTER_MHZ: Bounds = Bounds::closed(0.0, 1e4);
/// Spectral purity of the laser.
pub(super) const PURITY: Bounds = Bounds::positive(1.0);
/// Fractions that must stay below 1 (energy jitter, energy-monitor error).
pub(super) const FRACTION_BELOW_1: Bounds = Bounds::below(0.0, 1.0);
/// Optical filter width \[nm\].
pub(super) const FILTER_WIDTH_NM: Bounds = Bounds::positive(1e4);
/// Optical filter width \[GHz\].
pub(super) const FILTER_WIDTH_GHZ: Bounds = Bounds::positive(1e6);
/// Detector gain.
pub(super) const GAIN: Bounds = Bounds::closed(1.0, 1e8);
/// Excess noise factor of an avalanche detector.
pub(super) const EXCESS_NOISE: Bounds = Bounds::closed(1.0, 1e4);
/// Dark current \[A\].
pub(super) const DARK_CURRENT_A: Bounds = Bounds::closed(0.0, 1.0);
/// Noise-equivalent power \[W/√Hz\] and amplifier noise \[A/√Hz\].
pub(super) const NOISE_DENSITY: Bounds = Bounds::closed(0.0, 1e-3);
/// Readout noise \[electrons\].
pub(super) const READOUT_NOISE_E: Bounds = Bounds::closed(0.0, 1e6);
/// Electrical bandwidth \[MHz\].
pub(super) const BANDWIDTH_MHZ: Bounds = Bounds::positive(1e6);
/// Background radiance \[W/(m² sr µm)\] (the solar disk is about 4e6).
pub(super) const RADIANCE: Bounds = Bounds::closed(0.0, 1e8);
/// Solar spectral irradiance \[W/(m² µm)\] (about 2000 at its peak).
pub(super) const IRRADIANCE: Bounds = Bounds::closed(0.0, 1e5);
/// Solar zenith angle \[deg\]: the sun above the horizon.
pub(super) const SOLAR_ZENITH_DEG: Bounds = Bounds::closed(0.0, 90.0);
/// Lengths along the beam of a retrieval (target window, DIAL cell) \[m\].
pub(super) const PATH_LENGTH_M: Bounds = Bounds::closed(0.0, 1e8);
/// Averaging length along track \[km\].
pub(super) const AVERAGING_LENGTH_KM: Bounds = Bounds::positive(1e5);
/// Platform speed \[m/s\].
pub(super) const SPEED_M_PER_S: Bounds = Bounds::positive(1e5);
/// `simulation.multiple_scattering_tolerance`: a share of the single-scatter return, (0, 1).
/// Above 1 "auto" would call any multiple scattering negligible.
pub(super) const MS_TOLERANCE: Bounds = Bounds::open(0.0, 1.0);
/// Pressure of a profile given by values \[Pa\] (generous: the profile's own check, when
/// resolved, holds it to the atmosphere's range).
pub(super) const PROFILE_PRESSURE_PA: Bounds = Bounds::positive(1e8);
/// Temperature of a profile given by values \[K\] (generous, as the pressure).
pub(super) const PROFILE_TEMPERATURE_K: Bounds = Bounds::positive(1e5);
