//! Clouds given as libRadtran users give them: a condensed-water content (liquid, LWC, or ice,
//! IWC, in g/m³) and an effective radius r_eff = ⟨r³⟩/⟨r²⟩ (Hansen & Travis 1974, Eq. 2.53),
//! turned into the extinction coefficient or the number density of a layer.
//!
//! * **Geometric optics** (a layer whose single-scattering albedo and phase function are
//!   given): β_ext = Q_ext · (projected area per volume of air) with Q_ext = 2, the large-particle
//!   limit of the extinction efficiency (the extinction paradox; Hansen & Travis 1974, "Light
//!   scattering in planetary atmospheres", Space Sci. Rev. 16; Stephens 1978, "Radiation
//!   profiles in extended water clouds. II: Parameterization schemes", J. Atmos. Sci. 35). With
//!   WC = ρ (4/3)π ⟨r³⟩ N and area π ⟨r²⟩ N:
//!
//!   ```text
//!   β_ext = 3 Q_ext WC / (4 ρ r_eff) = 3 WC / (2 ρ r_eff)
//!   ```
//!
//!   the same at every wavelength; within a few per cent of Mie for size parameters
//!   2π r_eff/λ ≳ 30 (the Deirmendjian C.1 water cloud, r_eff = 6 µm, x = 35 at
//!   1064 nm, has Q_ext = 2.204 by Mie, miepython in `../shared/reference/c1_summary.csv`: the
//!   limit is 9 % low there); for smaller ones (r_eff = 10 µm at 10.6 µm, x ≈ 6) the limit
//!   is poor and a Mie layer should be used.
//!
//!   **Ice** uses the same limit with ρ_ice = 917 kg/m³ and r_eff = 3 IWC/(4 ρ_ice A) (A the
//!   projected area per volume of air: the definition of Foot 1988 and of the Yang et al. 2013
//!   and Baum et al. 2014 ice optics libRadtran reads), β = 3 IWC/(2 ρ_ice r_eff). This was
//!   chosen over Fu (1996, "An accurate parameterization of the solar radiative properties of
//!   cirrus clouds for climate models", J. Climate 9), β = IWC (a₀ + a₁/D_ge): Fu's fit is to
//!   his own hexagonal-column habits and his generalized size D_ge, whose relation to an
//!   effective radius differs between codes (libRadtran's `ic_fu reff_def`), while a₁/D_ge is
//!   itself the geometric-optics term, so with a stated r_eff the limit is the one formula
//!   whose meaning does not depend on a habit; the scattering's angular shape and albedo are
//!   the user's (`phase`, `single_scattering_albedo`).
//! * **Mie** (a layer of `particles`): the number density that holds the water content,
//!   N = WC / (ρ V̄) with V̄ the mean particle volume of the size distribution (truncated as the
//!   Mie integration is, per particle of the full distribution); the extinction at each channel
//!   is then N times the Mie cross-section of the distribution, Q_ext at the channel's
//!   wavelength included.

use super::distribution::SizeDistribution;

/// Density of liquid water \[kg/m³\] (999.8 at 0 °C, 997.0 at 25 °C; the 1000 of the
/// cloud-physics formulas above).
pub const WATER_DENSITY_KG_PER_M3: f64 = 1000.0;
/// Density of ice Ih \[kg/m³\] at 0 °C (916.7).
pub const ICE_DENSITY_KG_PER_M3: f64 = 917.0;
/// Extinction efficiency in the geometric-optics limit (Hansen & Travis 1974).
pub const GEOMETRIC_OPTICS_Q_EXT: f64 = 2.0;

/// Which condensed water a content is of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Condensate {
    /// Liquid water droplets (`lwc_g_per_m3`).
    Liquid,
    /// Ice crystals (`iwc_g_per_m3`).
    Ice,
}

impl Condensate {
    /// The bulk density of the condensate \[kg/m³\].
    pub fn density_kg_per_m3(self) -> f64 {
        match self {
            Condensate::Liquid => WATER_DENSITY_KG_PER_M3,
            Condensate::Ice => ICE_DENSITY_KG_PER_M3,
        }
    }
}

/// Extinction coefficient \[1/m\] of a cloud of `content_g_per_m3` with effective radius
/// `r_eff_um` in the geometric-optics limit, β = 3 Q_ext WC/(4 ρ r_eff) with Q_ext = 2 (module
/// docs).
pub fn geometric_optics_extinction_per_m(
    content_g_per_m3: f64,
    r_eff_um: f64,
    condensate: Condensate,
) -> f64 {
    let wc_kg_per_m3 = content_g_per_m3 * 1e-3;
    3.0 * GEOMETRIC_OPTICS_Q_EXT * wc_kg_per_m3
        / (4.0 * condensate.density_kg_per_m3() * r_eff_um * 1e-6)
}

/// Mean volume per particle \[µm³\] of `dist`: (4/3)π ⟨r³⟩ over each mode's truncation range,
/// per particle of the full distribution (as the Mie integration's cross-sections are, module
/// docs of [`super::distribution`]). Each mode's support (where its density is not 0) is found
/// on a grid in ln r and its ends by bisection, then ∫ r³ n dr over it by Simpson's rule in
/// ln r (4000 intervals; within 1e-9 of a lognormal's closed form, `tests`).
pub fn mean_particle_volume_um3(dist: &SizeDistribution) -> f64 {
    let r3: f64 = dist.modes().iter().map(third_moment_integral).sum();
    4.0 / 3.0 * std::f64::consts::PI * r3 / dist.number_density_per_cm3()
}

/// ∫ r³ n(r) dr \[cm⁻³ µm³\] of one mode, over its support.
fn third_moment_integral(mode: &SizeDistribution) -> f64 {
    let (a, b) = (1e-4_f64.ln(), 1e5_f64.ln());
    let grid = 20_000;
    let at = |k: usize| a + (b - a) * k as f64 / grid as f64;
    let positive = |ln_r: f64| mode.density(ln_r.exp()) > 0.0;
    let Some(first) = (0..=grid).find(|&k| positive(at(k))) else {
        return 0.0;
    };
    let last = (first..=grid)
        .rev()
        .find(|&k| positive(at(k)))
        .unwrap_or(first);
    // An end of the support: between a grid point outside and one inside.
    let edge = |mut inside: f64, mut outside: f64| {
        for _ in 0..60 {
            let mid = 0.5 * (inside + outside);
            if positive(mid) {
                inside = mid;
            } else {
                outside = mid;
            }
        }
        inside
    };
    let lo = if first == 0 {
        a
    } else {
        edge(at(first), at(first - 1))
    };
    let hi = if last == grid {
        b
    } else {
        edge(at(last), at(last + 1))
    };
    let m = 4000;
    let h = (hi - lo) / m as f64;
    let f = |k: usize| {
        let r = (lo + k as f64 * h).exp();
        mode.density(r) * r.powi(4)
    };
    let s: f64 = (0..=m)
        .map(|k| {
            let w = if k == 0 || k == m {
                1.0
            } else if k % 2 == 1 {
                4.0
            } else {
                2.0
            };
            w * f(k)
        })
        .sum();
    s * h / 3.0
}

/// Number density \[1/m³\] of particles of `dist` that hold `content_g_per_m3` of condensate:
/// N = WC / (ρ V̄).
pub fn number_density_for_content_per_m3(
    content_g_per_m3: f64,
    dist: &SizeDistribution,
    condensate: Condensate,
) -> f64 {
    let v_m3 = mean_particle_volume_um3(dist) * 1e-18;
    content_g_per_m3 * 1e-3 / (condensate.density_kg_per_m3() * v_m3)
}

/// Median radius \[µm\] of the lognormal with geometric standard deviation `sigma_g` whose
/// effective radius is `r_eff_um`: r_eff = ⟨r³⟩/⟨r²⟩ = r_m exp(5/2 ln²σ_g) for a lognormal
/// (its k-th moment is r_mᵏ exp(k² ln²σ_g/2)).
pub fn lognormal_median_for_effective_radius_um(r_eff_um: f64, sigma_g: f64) -> f64 {
    r_eff_um / (2.5 * sigma_g.ln().powi(2)).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// β = 3·2·LWC/(4 ρ r_eff): 0.3 g/m³ of droplets of 10 µm is 0.045 /m (45 /km, a
    /// stratocumulus); ice of the same content and size 1000/917 times that.
    #[test]
    fn geometric_optics_by_hand() {
        let b = geometric_optics_extinction_per_m(0.3, 10.0, Condensate::Liquid);
        assert!((b - 0.045).abs() < 1e-15, "{b}");
        let i = geometric_optics_extinction_per_m(0.3, 10.0, Condensate::Ice);
        assert!((i / b - 1000.0 / 917.0).abs() < 1e-12);
    }

    /// The mean volume of a lognormal against its closed-form third moment, (4/3)π r_m³
    /// exp(9/2 ln²σ); a truncation that keeps (nearly) everything leaves it, and one that cuts
    /// the large half away takes most of the volume.
    #[test]
    fn mean_volume_of_a_lognormal() {
        let d = SizeDistribution::lognormal(1.0, 5.0, 1.5).unwrap();
        let exact = 4.0 / 3.0 * std::f64::consts::PI * 125.0 * (4.5 * 1.5f64.ln().powi(2)).exp();
        assert!((mean_particle_volume_um3(&d) / exact - 1.0).abs() < 1e-12);
        let wide = d.clone().truncated(0.01, 500.0).unwrap();
        assert!((mean_particle_volume_um3(&wide) / exact - 1.0).abs() < 1e-9);
        let cut = d.truncated(0.01, 5.0).unwrap();
        assert!(mean_particle_volume_um3(&cut) < 0.3 * exact);
        let r = lognormal_median_for_effective_radius_um(10.0, 1.5);
        let d = SizeDistribution::lognormal(1.0, r, 1.5).unwrap();
        assert!((d.effective_radius_um() - 10.0).abs() < 1e-12);
    }
}
