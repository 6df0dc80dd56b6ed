//! OPAC aerosol components and aerosol types (Hess, Koepke & Schult 1998, BAMS 79, 831).
//!
//! OPAC describes tropospheric aerosol as external mixtures of a few components, each a
//! log-normal size distribution of spheres with a spectral refractive index. This module holds
//! the five components the continental, urban, maritime and Arctic types are made of, in their
//! **dry (0 % relative humidity)** state, and the number densities of those types:
//!
//! | component | meaning | σ_g | r_mod \[µm\] | r_min…r_max \[µm\] |
//! |---|---|---|---|---|
//! | `inso` | water-insoluble (soil particles, organic material) | 2.51 | 0.471 | 0.005…20 |
//! | `waso` | water-soluble (sulfates, nitrates, organics) | 2.24 | 0.0212 | 0.005…20 |
//! | `soot` | soot (absorbing black carbon) | 2.00 | 0.0118 | 0.005…20 |
//! | `ssam` | sea salt, accumulation mode | 2.03 | 0.209 | 0.005…20 |
//! | `sscm` | sea salt, coarse mode | 2.03 | 1.75 | 0.005…60 |
//!
//! (Hess et al. 1998, Table 1: σ_g, the number mode radius r_modN of the dry particles and the
//! truncation radii; the same values head OPAC's data files `inso00`, `ssam00`, `sscm00`.) The
//! log-normal is `n(r) = N/(√(2π) ln σ_g r) exp(−ln²(r/r_mod)/(2 ln²σ_g))`, truncated to
//! `[r_min, r_max]` with `N` the number density of the untruncated formula — OPAC's own
//! normalisation: the mass per particle `M*` of Hess et al. Table 1 (e.g. 1.34e-3 µg m⁻³ per
//! cm⁻³ for `waso`, 5.99e-5 for `soot`) is reproduced only with this convention, not with `N`
//! counting just the particles inside `[r_min, r_max]` (see `validation/mie_opac/`).
//!
//! Refractive indices are OPAC's tabulation (`data/opac/refractive_indices.csv`, 0.25–2.5 µm,
//! provenance in `data/opac/PROVENANCE.md`), interpolated **linearly in wavelength** in both the
//! real part n and the imaginary part k between OPAC's wavelengths (0.25, 0.30, …, 0.80, 0.90,
//! 1.00, 1.25, 1.50, 1.75, 2.00, 2.50 µm). The imaginary part is ≥ 0 for absorption here (OPAC's
//! files write it as a negative number or as a magnitude).
//!
//! The aerosol types are Hess et al. (1998) Table 4 (number densities in cm⁻³); with dry
//! components they are the types at 0 % relative humidity. Humidity growth (OPAC's `waso50`,
//! `ssam50`, … files) is not included.

use std::sync::OnceLock;

use num_complex::Complex64;

use super::distribution::{BulkOptics, BulkOptions, Component, SizeDistribution};
use super::distribution::{
    MieProgress, bulk_optics_mixture_with_progress, format_refractive_index,
};
use super::mie::MieError;
use crate::input::CsvTable;

/// The embedded OPAC refractive-index table (see `data/opac/PROVENANCE.md`).
const REFRACTIVE_INDEX_CSV: &str = include_str!("../../data/opac/refractive_indices.csv");

/// Where the refractive indices come from (written into tables).
pub const REFRACTIVE_INDEX_SOURCE: &str = "OPAC 3.1 (Hess, Koepke & Schult 1998, BAMS 79, 831) \
component files, dry (0 % RH): inso00, ssam00, sscm00 as copied in USEPA/CMAQ \
UTIL/inline_phot_preproc/water_clouds/; waso00, soot00 as copied in libRadtran \
data/aerosol/OPAC/refractive_indices/; linear interpolation in wavelength (data/opac/PROVENANCE.md)";

/// Where the size distributions and number densities come from (written into tables).
pub const SIZE_DISTRIBUTION_SOURCE: &str = "OPAC (Hess, Koepke & Schult 1998) Table 1 (dry \
log-normal sigma_g, r_modN, r_min, r_max; N of the untruncated log-normal) and Table 4 (number \
densities of the aerosol types)";

/// One OPAC aerosol component (dry, 0 % relative humidity).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OpacComponent {
    /// Water-insoluble: soil particles with some organic material (`inso`).
    Inso,
    /// Water-soluble: sulfates, nitrates and organics (`waso`).
    Waso,
    /// Soot: absorbing black carbon (`soot`).
    Soot,
    /// Sea salt, accumulation mode (`ssam`).
    Ssam,
    /// Sea salt, coarse mode (`sscm`).
    Sscm,
}

/// Log-normal parameters of a dry OPAC component (Hess et al. 1998, Table 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OpacLognormal {
    /// Geometric standard deviation σ_g.
    pub sigma_g: f64,
    /// Number mode (median) radius r_modN \[µm\].
    pub mode_radius_um: f64,
    /// Smallest radius of the distribution \[µm\].
    pub r_min_um: f64,
    /// Largest radius of the distribution \[µm\].
    pub r_max_um: f64,
}

impl OpacComponent {
    /// All components, in OPAC's order.
    pub const ALL: [OpacComponent; 5] = [
        OpacComponent::Inso,
        OpacComponent::Waso,
        OpacComponent::Soot,
        OpacComponent::Ssam,
        OpacComponent::Sscm,
    ];

    /// OPAC's short name (`inso`, `waso`, `soot`, `ssam`, `sscm`).
    pub fn name(self) -> &'static str {
        match self {
            OpacComponent::Inso => "inso",
            OpacComponent::Waso => "waso",
            OpacComponent::Soot => "soot",
            OpacComponent::Ssam => "ssam",
            OpacComponent::Sscm => "sscm",
        }
    }

    /// A one-line description.
    pub fn description(self) -> &'static str {
        match self {
            OpacComponent::Inso => "water-insoluble (soil particles and organic material)",
            OpacComponent::Waso => "water-soluble (sulfates, nitrates, organics)",
            OpacComponent::Soot => "soot (black carbon)",
            OpacComponent::Ssam => "sea salt, accumulation mode",
            OpacComponent::Sscm => "sea salt, coarse mode",
        }
    }

    /// The component with OPAC's short name `name` (case-insensitive).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|c| c.name().eq_ignore_ascii_case(name.trim()))
    }

    /// Dry log-normal parameters (Hess et al. 1998, Table 1).
    pub fn lognormal(self) -> OpacLognormal {
        let (sigma_g, mode_radius_um, r_max_um) = match self {
            OpacComponent::Inso => (2.51, 0.471, 20.0),
            OpacComponent::Waso => (2.24, 0.0212, 20.0),
            OpacComponent::Soot => (2.00, 0.0118, 20.0),
            OpacComponent::Ssam => (2.03, 0.209, 20.0),
            OpacComponent::Sscm => (2.03, 1.75, 60.0),
        };
        OpacLognormal {
            sigma_g,
            mode_radius_um,
            r_min_um: 0.005,
            r_max_um,
        }
    }

    /// The component's truncated log-normal with `number_density_per_cm3` particles per cm³
    /// (number density of the untruncated formula, as in OPAC).
    pub fn size_distribution(
        self,
        number_density_per_cm3: f64,
    ) -> Result<SizeDistribution, MieError> {
        let p = self.lognormal();
        SizeDistribution::lognormal(number_density_per_cm3, p.mode_radius_um, p.sigma_g)?
            .truncated(p.r_min_um, p.r_max_um)
    }

    /// OPAC's refractive index (imaginary part ≥ 0 absorbing) at `wavelength_m`, linear in
    /// wavelength between OPAC's tabulated wavelengths; valid 0.25–2.5 µm (an error outside).
    pub fn refractive_index(self, wavelength_m: f64) -> Result<Complex64, MieError> {
        let table = &refractive_index_table()[self as usize];
        let w = wavelength_m * 1e6;
        let (lo, hi) = (table[0].0, table[table.len() - 1].0);
        if !(w.is_finite() && w >= lo * (1.0 - 1e-12) && w <= hi * (1.0 + 1e-12)) {
            return Err(MieError::Parameter {
                name: "wavelength_m",
                value: wavelength_m,
                reason: "outside OPAC's tabulated refractive indices (0.25-2.5 um)",
            });
        }
        let w = w.clamp(lo, hi);
        let i = table
            .windows(2)
            .position(|p| w <= p[1].0)
            .unwrap_or(table.len() - 2);
        let ((w0, n0, k0), (w1, n1, k1)) = (table[i], table[i + 1]);
        let t = (w - w0) / (w1 - w0);
        // Rounded to 10 significant digits (the data have 3–4) so tables print 1.51744, not
        // 1.5174400000000001.
        Ok(Complex64::new(
            round_significant(n0 + t * (n1 - n0), 10),
            round_significant(k0 + t * (k1 - k0), 10),
        ))
    }

    /// The component as part of a mixture: its size distribution with `number_density_per_cm3`
    /// and its refractive index at `wavelength_m`.
    pub fn component(
        self,
        number_density_per_cm3: f64,
        wavelength_m: f64,
    ) -> Result<Component, MieError> {
        Ok(Component {
            name: self.name().to_string(),
            distribution: self.size_distribution(number_density_per_cm3)?,
            refractive_index: self.refractive_index(wavelength_m)?,
        })
    }

    /// Bulk optics of this component alone with `number_density_per_cm3` particles per cm³
    /// (per-particle cross-sections do not depend on it); the table's metadata names OPAC.
    pub fn bulk_optics(
        self,
        number_density_per_cm3: f64,
        wavelength_m: f64,
        opts: &BulkOptions,
    ) -> Result<BulkOptics, MieError> {
        self.bulk_optics_with_progress(number_density_per_cm3, wavelength_m, opts, &|_| {})
    }

    /// [`Self::bulk_optics`], telling `progress` how far it is
    /// ([`super::distribution::bulk_optics_mixture_with_progress`]).
    pub fn bulk_optics_with_progress(
        self,
        number_density_per_cm3: f64,
        wavelength_m: f64,
        opts: &BulkOptions,
        progress: &dyn Fn(&MieProgress),
    ) -> Result<BulkOptics, MieError> {
        let mut b = bulk_optics_mixture_with_progress(
            &[self.component(number_density_per_cm3, wavelength_m)?],
            wavelength_m,
            opts,
            progress,
        )?;
        insert_meta(
            &mut b,
            &[
                (
                    "aerosol_component",
                    format!(
                        "OPAC {} ({}), dry (0 % relative humidity)",
                        self.name(),
                        self.description()
                    ),
                ),
                ("relative_humidity_percent", "0".to_string()),
                (
                    "refractive_index_source",
                    REFRACTIVE_INDEX_SOURCE.to_string(),
                ),
                (
                    "size_distribution_source",
                    SIZE_DISTRIBUTION_SOURCE.to_string(),
                ),
            ],
        );
        Ok(b)
    }
}

/// An OPAC aerosol type made of the components of this module (Hess et al. 1998, Table 4),
/// with dry components (0 % relative humidity).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OpacType {
    /// Continental clean: waso 2600, inso 0.15 cm⁻³.
    ContinentalClean,
    /// Continental average: waso 7000, inso 0.4, soot 8300 cm⁻³.
    ContinentalAverage,
    /// Continental polluted: waso 15700, inso 0.6, soot 34300 cm⁻³.
    ContinentalPolluted,
    /// Urban: waso 28000, inso 1.5, soot 130000 cm⁻³.
    Urban,
    /// Maritime clean: waso 1500, ssam 20, sscm 3.2e-3 cm⁻³.
    MaritimeClean,
    /// Maritime polluted: waso 3800, ssam 20, sscm 3.2e-3, soot 5180 cm⁻³.
    MaritimePolluted,
    /// Maritime tropical: waso 590, ssam 10, sscm 1.3e-3 cm⁻³.
    MaritimeTropical,
    /// Arctic: waso 1300, inso 0.01, ssam 1.9, soot 5300 cm⁻³.
    Arctic,
}

impl OpacType {
    /// All types provided.
    pub const ALL: [OpacType; 8] = [
        OpacType::ContinentalClean,
        OpacType::ContinentalAverage,
        OpacType::ContinentalPolluted,
        OpacType::Urban,
        OpacType::MaritimeClean,
        OpacType::MaritimePolluted,
        OpacType::MaritimeTropical,
        OpacType::Arctic,
    ];

    /// Name in kebab case (`continental-average`, …), as the CLI takes it.
    pub fn name(self) -> &'static str {
        crate::input::names::OPAC_TYPES[self as usize]
    }

    /// The type named `name` (kebab or snake case, case-insensitive).
    pub fn from_name(name: &str) -> Option<Self> {
        crate::input::names::opac_type(name).map(|i| Self::ALL[i])
    }

    /// Components and their number densities [cm⁻³] (Hess et al. 1998, Table 4).
    pub fn composition(self) -> &'static [(OpacComponent, f64)] {
        use OpacComponent::*;
        match self {
            OpacType::ContinentalClean => &[(Waso, 2600.0), (Inso, 0.15)],
            OpacType::ContinentalAverage => &[(Waso, 7000.0), (Inso, 0.4), (Soot, 8300.0)],
            OpacType::ContinentalPolluted => &[(Waso, 15700.0), (Inso, 0.6), (Soot, 34300.0)],
            OpacType::Urban => &[(Waso, 28000.0), (Inso, 1.5), (Soot, 130000.0)],
            OpacType::MaritimeClean => &[(Waso, 1500.0), (Ssam, 20.0), (Sscm, 3.2e-3)],
            OpacType::MaritimePolluted => {
                &[(Waso, 3800.0), (Ssam, 20.0), (Sscm, 3.2e-3), (Soot, 5180.0)]
            }
            OpacType::MaritimeTropical => &[(Waso, 590.0), (Ssam, 10.0), (Sscm, 1.3e-3)],
            OpacType::Arctic => &[(Waso, 1300.0), (Inso, 0.01), (Ssam, 1.9), (Soot, 5300.0)],
        }
    }

    /// Total number density [cm⁻³].
    pub fn number_density_per_cm3(self) -> f64 {
        self.composition().iter().map(|(_, n)| n).sum()
    }

    /// The mixture's components at `wavelength_m` (for [`bulk_optics_mixture`]).
    pub fn components(self, wavelength_m: f64) -> Result<Vec<Component>, MieError> {
        self.composition()
            .iter()
            .map(|(c, n)| c.component(*n, wavelength_m))
            .collect()
    }

    /// Bulk optics of the mixture at `wavelength_m`: cross-sections per particle of the
    /// mixture (so a layer's extinction is its total number density times ⟨Cext⟩); the phase
    /// table's metadata names the type, the relative humidity and the sources.
    pub fn bulk_optics(
        self,
        wavelength_m: f64,
        opts: &BulkOptions,
    ) -> Result<BulkOptics, MieError> {
        self.bulk_optics_with_progress(wavelength_m, opts, &|_| {})
    }

    /// [`Self::bulk_optics`], telling `progress` how far it is
    /// ([`super::distribution::bulk_optics_mixture_with_progress`]).
    pub fn bulk_optics_with_progress(
        self,
        wavelength_m: f64,
        opts: &BulkOptions,
        progress: &dyn Fn(&MieProgress),
    ) -> Result<BulkOptics, MieError> {
        let comps = self.components(wavelength_m)?;
        let mut b = bulk_optics_mixture_with_progress(&comps, wavelength_m, opts, progress)?;
        let composition = self
            .composition()
            .iter()
            .map(|(c, n)| format!("{} {n} cm^-3", c.name()))
            .collect::<Vec<_>>()
            .join(", ");
        let indices = comps
            .iter()
            .map(|c| format!("{} {}", c.name, format_refractive_index(c.refractive_index)))
            .collect::<Vec<_>>()
            .join(", ");
        // The generic mixture metadata says only "external mixture": name the indices here.
        if let Some(v) = b
            .phase
            .meta
            .iter_mut()
            .find(|(k, _)| k == "refractive_index")
        {
            v.1 = format!("external mixture: {indices}");
        }
        if let Some(v) = b.phase.meta.iter_mut().find(|(k, _)| k == "distribution") {
            v.1 = format!(
                "OPAC {} (dry): {composition}; log-normal components listed as component_*",
                self.name()
            );
        }
        insert_meta(
            &mut b,
            &[
                (
                    "aerosol_type",
                    format!(
                        "OPAC {} (Hess, Koepke & Schult 1998, Table 4) with dry components",
                        self.name()
                    ),
                ),
                ("relative_humidity_percent", "0".to_string()),
                (
                    "refractive_index_source",
                    REFRACTIVE_INDEX_SOURCE.to_string(),
                ),
                (
                    "size_distribution_source",
                    SIZE_DISTRIBUTION_SOURCE.to_string(),
                ),
            ],
        );
        Ok(b)
    }
}

/// `x` rounded to `digits` significant decimal digits.
fn round_significant(x: f64, digits: i32) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let e = digits - 1 - x.abs().log10().floor() as i32;
    if e >= 0 {
        let f = 10f64.powi(e);
        (x * f).round() / f
    } else {
        let f = 10f64.powi(-e);
        (x / f).round() * f
    }
}

/// Insert metadata before the final `source` line.
fn insert_meta(b: &mut BulkOptics, kv: &[(&str, String)]) {
    let at = b
        .phase
        .meta
        .iter()
        .position(|(k, _)| k == "source")
        .unwrap_or(b.phase.meta.len());
    for (i, (k, v)) in kv.iter().enumerate() {
        b.phase.meta.insert(at + i, (k.to_string(), v.clone()));
    }
}

/// Per component (in [`OpacComponent::ALL`] order): (wavelength \[µm\], n, k) rows, increasing.
type IndexTable = [Vec<(f64, f64, f64)>; 5];

fn refractive_index_table() -> &'static IndexTable {
    static TABLE: OnceLock<IndexTable> = OnceLock::new();
    TABLE.get_or_init(|| {
        // Compiled-in data, checked by the tests: a failure here is a build defect, not bad
        // user input.
        parse_refractive_indices(REFRACTIVE_INDEX_CSV)
            .expect("embedded data/opac/refractive_indices.csv is valid")
    })
}

fn parse_refractive_indices(text: &str) -> Result<IndexTable, crate::input::InputError> {
    use crate::input::InputError;
    let path = "data/opac/refractive_indices.csv";
    let t = CsvTable::parse(path, text)?;
    let (cc, cw, cn, ck) = (
        t.column("component")?,
        t.column("wavelength_um")?,
        t.column("n")?,
        t.column("k")?,
    );
    let mut out: IndexTable = Default::default();
    for (row, (line, f)) in t.rows().enumerate() {
        let c = OpacComponent::from_name(&f[cc])
            .ok_or_else(|| InputError::at(path, line, "component", "unknown OPAC component"))?;
        let (w, n, k) = (t.f64_at(row, cw)?, t.f64_at(row, cn)?, t.f64_at(row, ck)?);
        if !(w > 0.0 && n > 0.0 && k >= 0.0) {
            return Err(InputError::at(
                path,
                line,
                "n",
                "wavelength and n must be > 0, k ≥ 0",
            ));
        }
        let v = &mut out[c as usize];
        if v.last().is_some_and(|p| p.0 >= w) {
            return Err(InputError::at(
                path,
                line,
                "wavelength_um",
                "must increase within a component",
            ));
        }
        v.push((w, n, k));
    }
    if let Some(c) = OpacComponent::ALL
        .into_iter()
        .find(|c| out[*c as usize].len() < 2)
    {
        return Err(InputError::file(
            path,
            format!("component {} has fewer than 2 rows", c.name()),
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_table_parses_and_interpolates_linearly() {
        let t = refractive_index_table();
        for c in OpacComponent::ALL {
            assert_eq!(t[c as usize].len(), 19, "{}", c.name());
        }
        // At a node: the tabulated value (OPAC soot00 at 0.55 um: 1.75 - 0.44i).
        let m = OpacComponent::Soot.refractive_index(0.55e-6).unwrap();
        assert_eq!((m.re, m.im), (1.75, 0.44));
        // Between nodes: linear in wavelength (waso 1.0 um: 1.52, 1.55e-2; 1.25 um: 1.51, 1.9e-2).
        let m = OpacComponent::Waso.refractive_index(1.064e-6).unwrap();
        let t = (1.064 - 1.0) / 0.25;
        assert!((m.re - (1.52 - 0.01 * t)).abs() < 1e-9);
        assert!((m.im - (1.55e-2 + 0.35e-2 * t)).abs() < 1e-11);
        assert!(OpacComponent::Inso.refractive_index(0.2e-6).is_err());
        assert!(OpacComponent::Inso.refractive_index(3e-6).is_err());
        assert!(OpacComponent::Inso.refractive_index(2.5e-6).is_ok());
    }

    #[test]
    fn type_totals_match_table_4() {
        // Hess et al. (1998) Table 4 totals (cm^-3), rounded as printed there.
        let totals = [
            (OpacType::ContinentalClean, 2600.0),
            (OpacType::ContinentalAverage, 15300.0),
            (OpacType::ContinentalPolluted, 50000.0),
            (OpacType::Urban, 158000.0),
            (OpacType::MaritimeClean, 1520.0),
            (OpacType::MaritimePolluted, 9000.0),
            (OpacType::MaritimeTropical, 600.0),
            (OpacType::Arctic, 6600.0),
        ];
        for (t, n) in totals {
            assert!((t.number_density_per_cm3() / n - 1.0).abs() < 1e-3, "{t:?}");
            assert_eq!(OpacType::from_name(t.name()), Some(t));
        }
        assert_eq!(
            OpacType::from_name("Maritime_Clean"),
            Some(OpacType::MaritimeClean)
        );
        assert_eq!(OpacComponent::from_name("SOOT"), Some(OpacComponent::Soot));
    }

    #[test]
    fn bad_embedded_rows_are_reported() {
        let e = parse_refractive_indices("component,wavelength_um,n,k\nfoo,0.5,1.5,0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown OPAC component"), "{e}");
        let e = parse_refractive_indices("component,wavelength_um,n,k\ninso,0.5,1.5,-1\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("k ≥ 0"), "{e}");
    }
}
