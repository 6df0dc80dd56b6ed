//! TEMPORARY STUB: replaced by the real module from the `lineshape` branch.
#![allow(missing_docs, dead_code)]
pub const MHZ_PER_CM1: f64 = 29_979.245_8;
#[derive(Debug, Clone, PartialEq)]
pub enum LineShape {
    Monochromatic,
    Gaussian { fwhm_mhz: f64 },
    Lorentzian { fwhm_mhz: f64 },
    Table(LineShapeTable),
}
#[derive(Debug, Clone, PartialEq)]
pub struct LineShapeTable {
    pub source: std::path::PathBuf,
    pub offset_mhz: Vec<f64>,
    pub relative_intensity: Vec<f64>,
}
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuadratureNode {
    pub offset_mhz: f64,
    pub weight: f64,
}
impl LineShapeTable {
    pub fn read(path: &std::path::Path) -> Result<Self, crate::input::InputError> {
        Err(crate::input::InputError::file(path, "stub"))
    }
}
impl LineShape {
    pub fn gaussian(fwhm_mhz: f64) -> Result<Self, String> {
        Ok(LineShape::Gaussian { fwhm_mhz })
    }
    pub fn lorentzian(fwhm_mhz: f64) -> Result<Self, String> {
        Ok(LineShape::Lorentzian { fwhm_mhz })
    }
    pub fn density_per_mhz(&self, _x: f64) -> f64 {
        0.0
    }
    pub fn nodes(&self, _n: usize) -> Vec<QuadratureNode> {
        vec![QuadratureNode {
            offset_mhz: 0.0,
            weight: 1.0,
        }]
    }
}
