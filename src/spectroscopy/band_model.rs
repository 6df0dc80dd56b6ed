//! A compact model of the CO2 30012←00001 band (¹²C¹⁶O₂, 1.57–1.61 µm), the built-in line source
//! of the default scene when no HITRAN file is given. APPROXIMATE: one band of one
//! isotopologue; no hot bands, no other isotopologues, no other gases.
//!
//! With m = −J″ (P branch) or J″+1 (R branch), J′(J′+1) = m(m+1), J″(J″+1) = m(m−1) and
//! x(J) = J(J+1) (Herzberg 1945, *Infrared and Raman spectra*, ch. IV; Rothman & Young 1981,
//! JQSRT 25, 505 for CO2):
//!
//! ```text
//! E″(J″) = B″x − D″x² + H″x³,   E′(J′) = G′ + B′x − D′x² + H′x³,   ν_m = E′(J′) − E″(J″)     [cm⁻¹]
//! S_m(296 K) = S₀ · (ν_m/ν₀) · |m| · e^{−c₂E″/296} (1 − e^{−c₂ν_m/296})/(1 − e^{−c₂ν₀/296}) · F(m)   [cm/molecule]
//! F(m) = (1 + A₁m + A₂m² + A₃m³)²                                                         (Herman-Wallis)
//! γ_air, γ_self, n_air: polynomials in |m|;   δ_air: polynomial in m
//! ```
//!
//! with ν₀ = G′ the band origin and |m| the Hönl-London factor of a Σ–Σ band. The constants are
//! least-squares fits to the HITRAN2016 lines of the band (Gordon et al. 2017, JQSRT 203, 3),
//! made by `cargo run --release --example co2_band_model_fit` (`validation/co2_band_model/`),
//! which writes `data/co2_band_model/co2_30012_band.toml` (embedded here) and the fit report.
//! Only even J″ exist (¹⁶O nuclei have spin 0), so P(J″) and R(J″) for even J″.

use super::lines::{Line, LineList};

const EMBEDDED: &str = include_str!("../../data/co2_band_model/co2_30012_band.toml");

/// The constants of the band model (module docs); polynomial coefficients in increasing
/// powers.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Co2BandModel {
    /// Where the constants come from.
    pub source: String,
    /// Upper-state vibrational term G′ = band origin ν₀ [cm⁻¹].
    pub band_origin_cm1: f64,
    /// Upper-state rotational constant B′ [cm⁻¹].
    pub b_upper_cm1: f64,
    /// Upper-state centrifugal constant D′ [cm⁻¹].
    pub d_upper_cm1: f64,
    /// Upper-state sextic constant H′ [cm⁻¹].
    pub h_upper_cm1: f64,
    /// Ground-state B″ [cm⁻¹].
    pub b_lower_cm1: f64,
    /// Ground-state D″ [cm⁻¹].
    pub d_lower_cm1: f64,
    /// Ground-state H″ [cm⁻¹].
    pub h_lower_cm1: f64,
    /// Band strength normalisation S₀ [cm/molecule] (natural abundance included).
    pub strength_cm_per_molecule: f64,
    /// Herman-Wallis coefficients [A₁, A₂, A₃].
    pub herman_wallis: Vec<f64>,
    /// γ_air(|m|) [cm⁻¹/atm], polynomial coefficients.
    pub gamma_air_poly: Vec<f64>,
    /// γ_self(|m|) [cm⁻¹/atm].
    pub gamma_self_poly: Vec<f64>,
    /// n_air(|m|).
    pub n_air_poly: Vec<f64>,
    /// δ_air(m) [cm⁻¹/atm].
    pub delta_air_poly: Vec<f64>,
}

fn poly(c: &[f64], x: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, &a| acc * x + a)
}

impl Co2BandModel {
    /// The embedded constants.
    pub fn embedded() -> Co2BandModel {
        // Part of the build, written by the fit program; checked by the unit tests.
        toml::from_str(EMBEDDED).expect("embedded CO2 band model parses")
    }

    /// Lower-state energy E″ of rotational level J [cm⁻¹].
    pub fn lower_energy_cm1(&self, j: u32) -> f64 {
        let x = (j * (j + 1)) as f64;
        self.b_lower_cm1 * x - self.d_lower_cm1 * x * x + self.h_lower_cm1 * x * x * x
    }

    /// Upper-state energy E′ of rotational level J [cm⁻¹].
    pub fn upper_energy_cm1(&self, j: u32) -> f64 {
        let x = (j * (j + 1)) as f64;
        self.band_origin_cm1 + self.b_upper_cm1 * x - self.d_upper_cm1 * x * x
            + self.h_upper_cm1 * x * x * x
    }

    /// (J″, J′) of line m (m ≠ 0).
    pub fn j_of_m(m: i32) -> (u32, u32) {
        if m > 0 {
            ((m - 1) as u32, m as u32)
        } else {
            ((-m) as u32, (-m - 1) as u32)
        }
    }

    /// Position ν_m [cm⁻¹].
    pub fn position_cm1(&self, m: i32) -> f64 {
        let (jl, ju) = Self::j_of_m(m);
        self.upper_energy_cm1(ju) - self.lower_energy_cm1(jl)
    }

    /// Intensity S_m at 296 K [cm/molecule] (module docs), with HITRAN's c₂ convention.
    pub fn strength_296(&self, m: i32) -> f64 {
        let c2 = crate::constants::C2_CM_K;
        let t = 296.0;
        let (jl, _) = Self::j_of_m(m);
        let nu = self.position_cm1(m);
        let nu0 = self.band_origin_cm1;
        let mf = m as f64;
        let hw = 1.0 + poly(&self.herman_wallis, mf) * mf;
        self.strength_cm_per_molecule
            * (nu / nu0)
            * mf.abs()
            * (-c2 * self.lower_energy_cm1(jl) / t).exp()
            * (1.0 - (-c2 * nu / t).exp())
            / (1.0 - (-c2 * nu0 / t).exp())
            * hw
            * hw
    }

    /// The HITRAN-like line of index m.
    pub fn line(&self, m: i32) -> Line {
        let (jl, _) = Self::j_of_m(m);
        let am = m.unsigned_abs() as f64;
        let mut quanta = [b' '; 60];
        quanta[0..15].copy_from_slice(b"       3 0 0 12");
        quanta[15..30].copy_from_slice(b"       0 0 0 01");
        let label = format!("     {} {:>2}e     ", if m > 0 { 'R' } else { 'P' }, jl);
        quanta[45..60].copy_from_slice(&label.as_bytes()[..15]);
        Line {
            molecule_id: 2,
            iso_id: 1,
            nu_cm1: self.position_cm1(m),
            sw_cm_per_molecule: self.strength_296(m),
            einstein_a_per_s: 0.0,
            gamma_air_cm1_per_atm: poly(&self.gamma_air_poly, am),
            gamma_self_cm1_per_atm: poly(&self.gamma_self_poly, am),
            elower_cm1: self.lower_energy_cm1(jl),
            n_air: poly(&self.n_air_poly, am),
            delta_air_cm1_per_atm: poly(&self.delta_air_poly, m as f64),
            quanta,
            shape: None,
        }
    }

    /// The band's lines for |m| ≤ `max_m` (P(J″) and R(J″), J″ even), sorted by wavenumber.
    pub fn line_list(&self, max_m: u32) -> LineList {
        let mut lines: Vec<Line> = (-(max_m as i32)..=max_m as i32)
            .filter(|&m| m != 0 && Self::j_of_m(m).0 % 2 == 0)
            .map(|m| self.line(m))
            .collect();
        lines.sort_by(|a, b| a.nu_cm1.total_cmp(&b.nu_cm1));
        LineList {
            source: format!("<built-in CO2 30012<-00001 band model: {}>", self.source),
            lines,
        }
    }
}

impl LineList {
    /// The built-in model of the CO2 30012←00001 band (626 only, P and R branches
    /// |m| ≤ 60), for scenes without a HITRAN file. Approximate: see
    /// [`super::band_model`] and `validation/co2_band_model/`.
    pub fn co2_30012_band_model() -> LineList {
        super::band_model::Co2BandModel::embedded().line_list(60)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_model_has_the_known_band_structure() {
        let b = Co2BandModel::embedded();
        // Band origin of 30012←00001 (Rothman & Young 1981: 6347.85 cm⁻¹) and the ground-state
        // B″ of CO2 (0.39022 cm⁻¹; Herzberg).
        assert!(
            (b.band_origin_cm1 - 6347.85).abs() < 0.01,
            "{}",
            b.band_origin_cm1
        );
        assert!((b.b_lower_cm1 - 0.390_22).abs() < 1e-4, "{}", b.b_lower_cm1);
        let l = LineList::co2_30012_band_model();
        // P(60)…P(2) and R(0)…R(58): 30 + 30 lines.
        assert_eq!(l.len(), 60);
        let r16 = b.line(17);
        assert_eq!(r16.local_lower_quanta(), "     R 16e     ");
        assert!((r16.nu_cm1 - 6359.967).abs() < 0.002);
    }
}
