//! The instrument: what the lidar emits and how its receiver turns returns into signals.
//!
//! Consumes the laser lines of a scene and the received energy per gate ([`crate::returns::Returns`]);
//! produces the monochromatic channels the transport must carry (line-shape quadrature nodes,
//! spectral impurity, frequency-jitter stencil) with the linear combinations that turn their
//! returns back into line returns, and, per gate and pulse, mean photo-electrons and noise.
//!
//! | step | module | entry point |
//! |---|---|---|
//! | laser line shapes and their quadrature | [`line_shape`] | [`line_shape::LineShape::nodes`] |
//! | lines, channels and their combinations | [`laser`] | [`laser::SpectralSampling::new`] |
//! | photo-detection and noise | [`detector`] | [`detector::Detector::gate`] |
pub mod detector;
pub mod laser;
pub mod line_shape;
pub mod signals;
