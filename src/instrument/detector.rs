//! Photo-detection: received energy per range gate → primary photo-electrons and their noise.
//!
//! Consumes the optical energy received in a range gate from one pulse (a gate of
//! [`crate::returns::Returns`]) and the background optical power at the detector; produces, per
//! gate and pulse, the mean photo-electrons of signal, background and dark current and the noise
//! variance ([`Detector::gate`] → [`GateNoise`]), and random realisations of the shot-summed,
//! background-subtracted signal ([`Detector::sample_sum`]). The receiver is a direct-detection
//! one: an avalanche photodiode (APD), a photomultiplier (PMT) or an ideal photon counter.
//!
//! # Model
//!
//! The direct-detection lidar signal-to-noise ratio in its photo-electron-count form[^1][^2].
//! Everything is per range gate of duration τ = 2Δr/c and per pulse, and is counted in
//! *primary* photo-electrons, i.e. referred to the detector input, before the avalanche gain M:
//!
//! - signal N_s = η E_s / (h ν), E_s the received energy in the gate \[J\], η the quantum
//!   efficiency and ν = c ν̃ the optical frequency (ν̃ the wavenumber);
//! - background N_b = η P_b τ / (h ν), P_b the background optical power at the detector \[W\];
//! - dark N_d = I_d τ / e, I_d the primary (multiplied, bulk) dark current \[A\];
//! - variance Var = F (N_s + N_b + N_d) + N_nep² + N_amp² + (σ_ro / M)², where the
//!   Poisson (shot) noise of the multiplied carriers is raised by the excess noise factor F of
//!   the gain process, and the remaining terms are additive white noise:
//!   - N_nep² = (η NEP / (h ν))² B τ² / max(2Bτ, 1), NEP the noise-equivalent power referred to
//!     the optical input \[W/√Hz\];
//!   - N_amp² = (i_amp / (e M))² B τ² / max(2Bτ, 1), i_amp the input current-noise density of
//!     the amplifier that follows the gain \[A/√Hz\];
//!   - σ_ro the readout noise, rms electrons per gate at the output (after the gain);
//! - SNR = N_s / √Var.
//!
//! An ideal photon counter has η = 1, M = F = 1 and no other noise, so Var = N_s + N_b + N_d:
//! the Poisson variance of the count.
//!
//! **White noise in a gate.** A white current noise of density i \[A/√Hz\] seen through an
//! electrical bandwidth B has variance i² B and decorrelates after 1/(2B) (Nyquist), so a gate
//! of duration τ holds max(2Bτ, 1) independent samples. The charge collected in the gate then
//! has variance (i √B τ)² = i² B τ² when 2Bτ ≤ 1 (one sample: the noise is constant across the
//! gate) and 2Bτ · (i √B / (2B))² = i² τ / 2 when 2Bτ ≥ 1; both read i² B τ² / max(2Bτ, 1),
//! continuous at 2Bτ = 1. Dividing by (e M)² refers it to primary photo-electrons; for the NEP
//! the "current" is the optical power converted with η/(h ν) and needs no gain correction.
//!
//! **Excess noise factor.** For an APD with electron injection and ionisation-coefficient ratio
//! k = β/α, F = k M + (1 − k)(2 − 1/M)[^3] ([`excess_noise_factor`]). For a PMT enter its
//! measured F.
//!
//! **Not modelled.** Speckle noise (many speckle cells per gate are assumed, as in direct
//! detection of a diffuse target), the gain's variation with temperature and bias, afterpulsing
//! and dead time of photon counters. Shot-to-shot laser energy jitter is the caller's: it
//! passes the signal photo-electrons summed over its shots to [`Detector::sample_sum`].
//!
//! [^1]: R. M. Measures (1984), *Laser Remote Sensing: Fundamentals and Applications*, Wiley,
//!     New York, ch. 4 (detection and noise) and ch. 7 (the lidar signal-to-noise ratio).
//!
//! [^2]: G. Ehret, C. Kiemle, M. Wirth, A. Amediek, A. Fix and S. Houweling (2008), Space-borne
//!     remote sensing of CO2, CH4, and N2O by integrated path differential absorption lidar: a
//!     sensitivity analysis, *Appl. Phys. B* 90, 593–608, Sect. 3, doi:10.1007/s00340-007-2892-3.
//!
//! [^3]: R. J. McIntyre (1966), Multiplication noise in uniform avalanche diodes, *IEEE Trans.
//!     Electron Devices* 13, 164–168, doi:10.1109/T-ED.1966.15651.

use rand_distr::{Distribution, Poisson, StandardNormal};

use crate::constants::{ELEMENTARY_CHARGE_C, PLANCK_J_S, SPEED_OF_LIGHT_M_PER_S};
use crate::rng::Rng;

/// A direct-detection receiver: detector, gain and the electronics behind it.
///
/// Build it with a struct literal (or [`Detector::ideal_photon_counter`]) and call
/// [`Detector::validate`] once; [`Detector::gate`] and [`Detector::sample_sum`] assume a
/// valid detector.
#[derive(Debug, Clone, PartialEq)]
pub struct Detector {
    /// Quantum efficiency η, primary photo-electrons per incident photon, in (0, 1].
    pub quantum_efficiency: f64,
    /// Mean gain M (avalanche or dynode multiplication), ≥ 1; 1 for a detector without gain.
    pub gain: f64,
    /// Excess noise factor F = ⟨m²⟩/⟨m⟩² of the gain m, ≥ 1 (see [`excess_noise_factor`]).
    pub excess_noise_factor: f64,
    /// Primary (multiplied, bulk) dark current I_d \[A\], referred to the input, ≥ 0.
    pub dark_current_a: f64,
    /// Noise-equivalent power referred to the optical input [W/√Hz], ≥ 0.
    pub nep_w_per_sqrt_hz: f64,
    /// Input current-noise density of the amplifier after the gain [A/√Hz], ≥ 0.
    pub amplifier_noise_a_per_sqrt_hz: f64,
    /// Readout noise, rms electrons per gate at the output (after the gain), ≥ 0.
    pub readout_noise_electrons: f64,
    /// Electrical bandwidth B of the detection chain \[Hz\], > 0.
    pub bandwidth_hz: f64,
}

impl Detector {
    /// An ideal photon counter (η = 1, M = F = 1, no dark or electronic noise, B = 1 GHz).
    ///
    /// Its count in a gate is Poisson: Var = N_s + N_b.
    pub fn ideal_photon_counter() -> Self {
        Detector {
            quantum_efficiency: 1.0,
            gain: 1.0,
            excess_noise_factor: 1.0,
            dark_current_a: 0.0,
            nep_w_per_sqrt_hz: 0.0,
            amplifier_noise_a_per_sqrt_hz: 0.0,
            readout_noise_electrons: 0.0,
            bandwidth_hz: 1e9,
        }
    }

    /// Check every field (finite and in range); Err names the field and value and the constraint.
    ///
    /// η ∈ (0, 1], M ≥ 1, F ≥ 1, dark current, NEP, amplifier and readout noise ≥ 0, B > 0. F is
    /// not checked against M: McIntyre's F ≥ 2 − 1/M holds for APDs only.
    pub fn validate(&self) -> Result<(), String> {
        let checks: [(&str, f64, bool, &str); 8] = [
            (
                "quantum_efficiency",
                self.quantum_efficiency,
                self.quantum_efficiency > 0.0 && self.quantum_efficiency <= 1.0,
                "in (0, 1]",
            ),
            ("gain", self.gain, self.gain >= 1.0, "≥ 1"),
            (
                "excess_noise_factor",
                self.excess_noise_factor,
                self.excess_noise_factor >= 1.0,
                "≥ 1",
            ),
            (
                "dark_current_a",
                self.dark_current_a,
                self.dark_current_a >= 0.0,
                "≥ 0",
            ),
            (
                "nep_w_per_sqrt_hz",
                self.nep_w_per_sqrt_hz,
                self.nep_w_per_sqrt_hz >= 0.0,
                "≥ 0",
            ),
            (
                "amplifier_noise_a_per_sqrt_hz",
                self.amplifier_noise_a_per_sqrt_hz,
                self.amplifier_noise_a_per_sqrt_hz >= 0.0,
                "≥ 0",
            ),
            (
                "readout_noise_electrons",
                self.readout_noise_electrons,
                self.readout_noise_electrons >= 0.0,
                "≥ 0",
            ),
            (
                "bandwidth_hz",
                self.bandwidth_hz,
                self.bandwidth_hz > 0.0,
                "> 0",
            ),
        ];
        for (name, value, in_range, constraint) in checks {
            // The comparisons are false for NaN; infinities are caught here.
            if !(in_range && value.is_finite()) {
                return Err(format!(
                    "detector: {name} = {value} must be finite and {constraint}"
                ));
            }
        }
        Ok(())
    }

    /// Mean photo-electrons and noise of one gate and one pulse, in primary photo-electrons.
    ///
    /// N_s = η E_s/(h ν), N_b = η P_b τ/(h ν), N_d = I_d τ/e and
    /// Var = F (N_s + N_b + N_d) + N_nep² + N_amp² + (σ_ro/M)² with the white-noise terms
    /// x² B τ²/max(2Bτ, 1) (module docs; Measures 1984, Ehret et al. 2008, Sect. 3).
    ///
    /// `signal_energy_j` is E_s, the received energy in the gate \[J\]; `background_power_w` is P_b
    /// at the detector \[W\] (see [`background_power_w`]); `wavenumber_cm1` is ν̃ \[cm⁻¹\], > 0;
    /// `gate_duration_s` is τ = 2Δr/c \[s\], > 0. Energies and powers are expected ≥ 0 and finite;
    /// other values are carried through the formulas as they are (no panic).
    pub fn gate(
        &self,
        signal_energy_j: f64,
        background_power_w: f64,
        wavenumber_cm1: f64,
        gate_duration_s: f64,
    ) -> GateNoise {
        let photon_j = photon_energy_j(wavenumber_cm1);
        let eta = self.quantum_efficiency;
        let tau = gate_duration_s;
        let m = self.gain;
        let f = self.excess_noise_factor;

        let signal_pe = eta * signal_energy_j / photon_j;
        let background_pe = eta * background_power_w * tau / photon_j;
        let dark_pe = self.dark_current_a * tau / ELEMENTARY_CHARGE_C;

        // Charge variance of a unit white noise density over the gate: B τ²/max(2Bτ, 1) [s].
        let white_s = white_gate_factor_s(self.bandwidth_hz, tau);
        let nep_pe_per_s = eta * self.nep_w_per_sqrt_hz / photon_j;
        let amp_pe_per_s = self.amplifier_noise_a_per_sqrt_hz / (ELEMENTARY_CHARGE_C * m);
        let readout_pe = self.readout_noise_electrons / m;
        let white_variance_pe2 = nep_pe_per_s * nep_pe_per_s * white_s
            + amp_pe_per_s * amp_pe_per_s * white_s
            + readout_pe * readout_pe;

        GateNoise {
            signal_pe,
            background_pe,
            dark_pe,
            variance_pe2: f * (signal_pe + background_pe + dark_pe) + white_variance_pe2,
            white_variance_pe2,
            excess_noise_factor: f,
        }
    }

    /// One noisy realisation of the background-subtracted signal summed over `shots` pulses, in
    /// primary photo-electrons.
    ///
    /// `signal_pe_sum` is Σ N_s, the signal photo-electrons summed over those shots (they may
    /// differ shot to shot, e.g. by laser energy jitter); `per_shot` is the [`GateNoise`] of one
    /// shot from [`Detector::gate`] of this detector, whose background and dark means
    /// (N_b, N_d), white variance and F are the same every shot. Only those fields of
    /// `per_shot` are used, not its `signal_pe`.
    ///
    /// The draw, with λ = Σ N_s + shots (N_b + N_d):
    /// 1. the primary count n ~ Poisson(λ);
    /// 2. the multiplied count M n plus a Gaussian avalanche excess of variance n M² (F − 1): this
    ///    has the exact first two moments of the gain process, mean M n and variance n M² (F − 1)
    ///    given n (F = ⟨m²⟩/⟨m⟩²), but not McIntyre's skewed single-electron distribution, so
    ///    tails and higher moments are approximate at small n;
    /// 3. plus Gaussian white noise of variance shots · (N_nep² + N_amp² + (σ_ro/M)²) in primary
    ///    units (independent between shots, so the variances add);
    /// 4. the output divided by M, minus the known mean shots · (N_b + N_d).
    ///
    /// M cancels in steps 2–4, so the draw is done in primary units: n + √(n (F − 1)) z₁ +
    /// √(shots · white) z₂ − shots (N_b + N_d), z₁, z₂ standard normal. Its mean is Σ N_s and its
    /// variance F λ + shots · white, i.e. Var of [`GateNoise`] summed over the shots with Σ N_s in
    /// place of shots · N_s.
    ///
    /// λ = 0 gives n = 0 without drawing. For λ above [`Poisson::MAX_LAMBDA`] (1.844e19, the
    /// limit of `rand_distr`'s sampler) n is drawn from a Gaussian of the same mean and variance
    /// λ, whose skewness 1/√λ < 3e-10 there is below anything f64 can resolve in the sum. If
    /// λ is negative or not finite, or `per_shot` has F < 1 or a negative white variance (not
    /// from a valid detector), the result is NaN: no realisation exists.
    pub fn sample_sum(
        &self,
        signal_pe_sum: f64,
        per_shot: &GateNoise,
        shots: u64,
        rng: &mut Rng,
    ) -> f64 {
        let shots_f = shots as f64;
        let known_mean_pe = shots_f * (per_shot.background_pe + per_shot.dark_pe);
        let lambda = signal_pe_sum + known_mean_pe;
        let excess = per_shot.excess_noise_factor - 1.0;
        let white_pe2 = shots_f * per_shot.white_variance_pe2;
        if !(lambda >= 0.0 && lambda.is_finite() && excess >= 0.0 && white_pe2 >= 0.0) {
            return f64::NAN;
        }

        // 1. Primary count.
        let n = if lambda == 0.0 {
            0.0
        } else if lambda > Poisson::<f64>::MAX_LAMBDA {
            let z: f64 = StandardNormal.sample(rng);
            lambda + lambda.sqrt() * z
        } else {
            match Poisson::new(lambda) {
                Ok(poisson) => poisson.sample(rng),
                // Unreachable: λ is positive, finite and within the limit.
                Err(_) => return f64::NAN,
            }
        };

        // 2. Avalanche excess, referred to the input (variance n M² (F − 1) divided by M²).
        let mut out = n;
        if excess > 0.0 && n > 0.0 {
            let z: f64 = StandardNormal.sample(rng);
            out += (n * excess).sqrt() * z;
        }
        // 3. White noise of the electronics, summed over the shots.
        if white_pe2 > 0.0 {
            let z: f64 = StandardNormal.sample(rng);
            out += white_pe2.sqrt() * z;
        }
        // 4. Subtract the known background and dark means.
        out - known_mean_pe
    }
}

/// Mean photo-electrons and noise of one range gate and one pulse, in primary photo-electrons.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateNoise {
    /// Signal photo-electrons N_s = η E_s/(h ν).
    pub signal_pe: f64,
    /// Background photo-electrons N_b = η P_b τ/(h ν).
    pub background_pe: f64,
    /// Dark-current electrons N_d = I_d τ/e.
    pub dark_pe: f64,
    /// Var in primary photo-electrons²: F (N_s + N_b + N_d) + N_nep² + N_amp² + (σ_ro/M)².
    pub variance_pe2: f64,
    /// The non-Poisson white-noise part N_nep² + N_amp² + (σ_ro/M)², per shot.
    pub white_variance_pe2: f64,
    /// F, copied so [`Detector::sample_sum`] and its variance can be computed from this alone.
    pub excess_noise_factor: f64,
}

impl GateNoise {
    /// Noise standard deviation √Var in primary photo-electrons.
    pub fn std_pe(&self) -> f64 {
        self.variance_pe2.sqrt()
    }

    /// Signal-to-noise ratio N_s/√Var of one gate and pulse (Measures 1984; Ehret et al. 2008,
    /// Sect. 3).
    ///
    /// 0 when the signal is 0 (or not positive, or not a number), and whenever Var is not
    /// positive; never NaN. With F ≥ 1, Var ≥ N_s, so a positive signal always has Var > 0.
    pub fn snr(&self) -> f64 {
        if self.signal_pe > 0.0 && self.variance_pe2 > 0.0 {
            self.signal_pe / self.variance_pe2.sqrt()
        } else {
            0.0
        }
    }
}

/// Excess noise factor of an APD from its gain and effective ionisation ratio (McIntyre 1966).
///
/// F = k M + (1 − k)(2 − 1/M), for electron injection with k = β/α the ratio of the hole to the
/// electron ionisation coefficient[^1] (for hole injection pass 1/k). F = 1 at M = 1, F = M at
/// k = 1 and F → 2 as M → ∞ at k = 0. Valid for M ≥ 1 and k ≥ 0; NaN outside (or for
/// non-finite input), which [`Detector::validate`] then rejects.
///
/// [^1]: R. J. McIntyre (1966), Multiplication noise in uniform avalanche diodes, *IEEE Trans.
///     Electron Devices* 13, 164–168, doi:10.1109/T-ED.1966.15651.
pub fn excess_noise_factor(gain: f64, ionisation_ratio: f64) -> f64 {
    let (m, k) = (gain, ionisation_ratio);
    if !(m >= 1.0 && m.is_finite() && k >= 0.0 && k.is_finite()) {
        return f64::NAN;
    }
    k * m + (1.0 - k) * (2.0 - 1.0 / m)
}

/// Background optical power at the detector \[W\] from a scene radiance.
///
/// P_b = L_λ Δλ Ω A η_opt T_f, with Ω = 2π (1 − cos(θ/2)) the exact solid angle of a cone of
/// full angle θ, evaluated as Ω = 4π sin²(θ/4) (the same quantity, without the cancellation of
/// 1 − cos at the sub-mrad angles of lidar receivers).
///
/// `radiance_w_per_m2_sr_um` is L_λ [W m⁻² sr⁻¹ µm⁻¹] (e.g. sunlight reflected by the surface or
/// scattered by clouds), `filter_bandwidth_um` Δλ \[µm\] (the equivalent width of the filter,
/// whose peak transmission is `filter_transmission` T_f), `fov_full_angle_mrad` θ \[mrad\] (full
/// angle, up to 2π rad), `telescope_area_m2` A \[m²\], `optical_efficiency` η_opt the receiver's
/// optical transmission other than the filter. Inputs are expected ≥ 0; they are not checked.
pub fn background_power_w(
    radiance_w_per_m2_sr_um: f64,
    filter_bandwidth_um: f64,
    fov_full_angle_mrad: f64,
    telescope_area_m2: f64,
    optical_efficiency: f64,
    filter_transmission: f64,
) -> f64 {
    let theta_rad = fov_full_angle_mrad * 1e-3;
    let s = (theta_rad / 4.0).sin();
    let solid_angle_sr = 4.0 * std::f64::consts::PI * s * s;
    radiance_w_per_m2_sr_um
        * filter_bandwidth_um
        * solid_angle_sr
        * telescope_area_m2
        * optical_efficiency
        * filter_transmission
}

/// Photon energy h c ν̃ \[J\] for a wavenumber ν̃ in cm⁻¹ (ν̃ · 100 in m⁻¹).
pub fn photon_energy_j(wavenumber_cm1: f64) -> f64 {
    PLANCK_J_S * SPEED_OF_LIGHT_M_PER_S * wavenumber_cm1 * 100.0
}

/// B τ²/max(2Bτ, 1) \[s\]: the gate-charge variance of a white noise of unit density (module docs).
fn white_gate_factor_s(bandwidth_hz: f64, gate_duration_s: f64) -> f64 {
    let samples = (2.0 * bandwidth_hz * gate_duration_s).max(1.0);
    bandwidth_hz * gate_duration_s * gate_duration_s / samples
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{Stream, streams};
    use crate::stats::welford_add;

    /// Relative difference.
    fn rel(a: f64, b: f64) -> f64 {
        ((a - b) / b).abs()
    }

    /// The documented case: η = 0.8, M = 10, F = 3, I_d = 1 nA, NEP = 1e-14 W/√Hz,
    /// i_amp = 2 pA/√Hz, σ_ro = 50 e⁻, B = 10 MHz.
    fn apd() -> Detector {
        Detector {
            quantum_efficiency: 0.8,
            gain: 10.0,
            excess_noise_factor: 3.0,
            dark_current_a: 1e-9,
            nep_w_per_sqrt_hz: 1e-14,
            amplifier_noise_a_per_sqrt_hz: 2e-12,
            readout_noise_electrons: 50.0,
            bandwidth_hz: 1e7,
        }
    }

    // Reference values below were computed by hand at 30 digits (mpmath) from the formulas in
    // the module docs with the CODATA constants: h ν at 6360 cm⁻¹ = 1.2633795651467186532e-19 J.

    #[test]
    fn photon_energy_at_6360_cm1() {
        assert!(rel(photon_energy_j(6360.0), 1.263_379_565_146_718_7e-19) < 1e-14);
    }

    #[test]
    fn gate_matches_hand_computation() {
        // 1 fJ at 6360 cm⁻¹, P_b = 1 nW, τ = 1 µs (150 m), 2Bτ = 20.
        let g = apd().gate(1e-15, 1e-9, 6360.0, 1e-6);
        // N_s = 0.8e-15/(h c 636000 m⁻¹); N_b = 0.8 · 1e-9 · 1e-6/(h ν) (the same number).
        assert!(rel(g.signal_pe, 6_332.222_097_537_999) < 1e-13);
        assert!(rel(g.background_pe, 6_332.222_097_537_999) < 1e-13);
        // N_d = 1e-9 A · 1e-6 s / e.
        assert!(rel(g.dark_pe, 6_241.509_074_460_763) < 1e-13);
        // N_nep² = (0.8 · 1e-14/(h ν))² · τ/2 = 2004.85…; N_amp² = (2e-12/(10 e))² τ/2 =
        // 779128.71…; (σ_ro/M)² = 25.
        let white = 2_004.851_834_627_427 + 779_128.710_531_520_9 + 25.0;
        assert!(rel(g.white_variance_pe2, white) < 1e-13);
        assert!(rel(g.white_variance_pe2, 781_158.562_366_148_3) < 1e-13);
        // Var = 3 (N_s + N_b + N_d) + white.
        assert!(rel(g.variance_pe2, 837_876.422_174_758_6) < 1e-13);
        assert!(rel(g.snr(), 6.917_770_566_801_946) < 1e-13);
        assert!(rel(g.std_pe(), 837_876.422_174_758_6_f64.sqrt()) < 1e-13);
        assert_eq!(g.excess_noise_factor, 3.0);
    }

    #[test]
    fn nep_term_alone_in_both_bandwidth_limits() {
        let only_nep = |bandwidth_hz: f64| Detector {
            dark_current_a: 0.0,
            amplifier_noise_a_per_sqrt_hz: 0.0,
            readout_noise_electrons: 0.0,
            bandwidth_hz,
            ..apd()
        };
        let tau = 1e-6;
        // 2Bτ = 20 ≥ 1: the gate holds 20 samples, variance (η NEP/(h ν))² τ/2.
        let wide = only_nep(1e7).gate(0.0, 0.0, 6360.0, tau);
        assert!(rel(wide.white_variance_pe2, 2_004.851_834_627_427) < 1e-13);
        // No signal, background or dark: the variance is the white part only, and SNR is 0.
        assert_eq!(wide.variance_pe2, wide.white_variance_pe2);
        assert_eq!(wide.snr(), 0.0);
        // 2Bτ = 0.2 < 1: one sample, variance (η NEP/(h ν))² B τ² = 400.97….
        let narrow = only_nep(1e5).gate(0.0, 0.0, 6360.0, tau);
        assert!(rel(narrow.white_variance_pe2, 400.970_366_925_485_4) < 1e-13);
        // Continuous at 2Bτ = 1 (B = 500 kHz): B τ² = τ/2.
        let at = only_nep(5e5).gate(0.0, 0.0, 6360.0, tau);
        let just_below = only_nep(5e5 * (1.0 - 1e-12)).gate(0.0, 0.0, 6360.0, tau);
        assert!(rel(just_below.white_variance_pe2, at.white_variance_pe2) < 1e-11);
        assert!(rel(at.white_variance_pe2, 2_004.851_834_627_427) < 1e-13);
    }

    #[test]
    fn dark_current_term_alone_is_multiplied_shot_noise() {
        let d = Detector {
            nep_w_per_sqrt_hz: 0.0,
            amplifier_noise_a_per_sqrt_hz: 0.0,
            readout_noise_electrons: 0.0,
            ..apd()
        };
        let g = d.gate(0.0, 0.0, 6360.0, 1e-6);
        assert!(rel(g.dark_pe, 6_241.509_074_460_763) < 1e-13);
        assert_eq!(g.white_variance_pe2, 0.0);
        assert!(rel(g.variance_pe2, 3.0 * 6_241.509_074_460_763) < 1e-13);
    }

    #[test]
    fn amplifier_and_readout_noise_fall_with_gain() {
        // N_amp² ∝ 1/M², (σ_ro/M)² ∝ 1/M²: doubling M quarters both.
        let only_electronics = |gain: f64| Detector {
            gain,
            dark_current_a: 0.0,
            nep_w_per_sqrt_hz: 0.0,
            ..apd()
        };
        let g10 = only_electronics(10.0).gate(0.0, 0.0, 6360.0, 1e-6);
        let g20 = only_electronics(20.0).gate(0.0, 0.0, 6360.0, 1e-6);
        assert!(rel(g10.white_variance_pe2, 779_128.710_531_520_9 + 25.0) < 1e-13);
        assert!(rel(g20.white_variance_pe2, g10.white_variance_pe2 / 4.0) < 1e-13);
    }

    #[test]
    fn photon_counter_is_poisson() {
        let d = Detector::ideal_photon_counter();
        assert_eq!(d.validate(), Ok(()));
        let g = d.gate(1e-15, 1e-9, 6360.0, 1e-6);
        // η = 1: N_s = 1e-15/(h ν) = 6332.22…/0.8.
        assert!(rel(g.signal_pe, 6_332.222_097_537_999 / 0.8) < 1e-13);
        assert_eq!(g.dark_pe, 0.0);
        assert_eq!(g.white_variance_pe2, 0.0);
        assert_eq!(g.variance_pe2, g.signal_pe + g.background_pe);
        assert!(
            rel(
                g.snr(),
                g.signal_pe / (g.signal_pe + g.background_pe).sqrt()
            ) < 1e-15
        );
        // Nothing at all: SNR 0, not NaN.
        let empty = d.gate(0.0, 0.0, 6360.0, 1e-6);
        assert_eq!(empty.variance_pe2, 0.0);
        assert_eq!(empty.snr(), 0.0);
    }

    #[test]
    fn mcintyre_limits() {
        for m in [1.0, 2.0, 10.0, 150.0] {
            assert!(rel(excess_noise_factor(m, 0.0), 2.0 - 1.0 / m) < 1e-15);
            assert!(rel(excess_noise_factor(m, 1.0), m) < 1e-15);
        }
        for k in [0.0, 0.02, 0.3, 1.0, 2.0] {
            assert!(rel(excess_noise_factor(1.0, k), 1.0) < 1e-15);
        }
        // k = 0.02, M = 100: 2 + 0.98 · 1.99 = 3.9502.
        assert!(rel(excess_noise_factor(100.0, 0.02), 3.9502) < 1e-14);
        // McIntyre's form for electron injection: F = M [1 − (1 − k)((M − 1)/M)²].
        let (m, k): (f64, f64) = (37.0, 0.1);
        let mcintyre = m * (1.0 - (1.0 - k) * ((m - 1.0) / m).powi(2));
        assert!(rel(excess_noise_factor(m, k), mcintyre) < 1e-14);
        // Out of range: NaN, which validate rejects.
        assert!(excess_noise_factor(0.5, 0.1).is_nan());
        assert!(excess_noise_factor(10.0, -0.1).is_nan());
        assert!(excess_noise_factor(f64::NAN, 0.1).is_nan());
        let d = Detector {
            excess_noise_factor: excess_noise_factor(0.5, 0.1),
            ..apd()
        };
        assert!(d.validate().is_err());
    }

    #[test]
    fn background_power_matches_hand_computation() {
        // L = 10 W m⁻² sr⁻¹ µm⁻¹, Δλ = 1 nm, θ = 0.2 mrad full angle, A = 0.1 m², η_opt = 0.5,
        // T_f = 0.8: Ω = 2π (1 − cos 1e-4) = π 1e-8 (1 − 1e-8/12 + …) = 3.14159265097e-8 sr,
        // P_b = 10 · 1e-3 · Ω · 0.1 · 0.4 = 1.25663706038872e-11 W.
        let p = background_power_w(10.0, 1e-3, 0.2, 0.1, 0.5, 0.8);
        assert!(rel(p, 1.256_637_060_388_719_7e-11) < 1e-13);
        // Hemisphere (θ = π) and the whole sphere (θ = 2π): Ω = 2π and 4π.
        let pi = std::f64::consts::PI;
        assert!(
            rel(
                background_power_w(1.0, 1.0, pi * 1e3, 1.0, 1.0, 1.0),
                2.0 * pi
            ) < 1e-15
        );
        assert!(
            rel(
                background_power_w(1.0, 1.0, 2.0 * pi * 1e3, 1.0, 1.0, 1.0),
                4.0 * pi
            ) < 1e-15
        );
        // Linear in every other factor.
        let q = background_power_w(20.0, 2e-3, 0.2, 0.3, 0.25, 0.4);
        assert!(rel(q, p * 2.0 * 2.0 * 3.0 * 0.5 * 0.5) < 1e-14);
    }

    #[test]
    fn validate_rejects_bad_fields() {
        assert_eq!(apd().validate(), Ok(()));
        // (the field the error must name, the change that spoils it)
        type Case = (&'static str, fn(&mut Detector));
        let cases: [Case; 13] = [
            ("quantum_efficiency", |d| d.quantum_efficiency = f64::NAN),
            ("quantum_efficiency", |d| d.quantum_efficiency = 0.0),
            ("quantum_efficiency", |d| d.quantum_efficiency = 1.01),
            ("gain", |d| d.gain = 0.99),
            ("gain", |d| d.gain = f64::INFINITY),
            ("excess_noise_factor", |d| d.excess_noise_factor = 0.99),
            ("excess_noise_factor", |d| d.excess_noise_factor = f64::NAN),
            ("dark_current_a", |d| d.dark_current_a = -1e-12),
            ("nep_w_per_sqrt_hz", |d| d.nep_w_per_sqrt_hz = -1e-15),
            ("amplifier_noise_a_per_sqrt_hz", |d| {
                d.amplifier_noise_a_per_sqrt_hz = -1e-13
            }),
            ("readout_noise_electrons", |d| {
                d.readout_noise_electrons = -1.0
            }),
            ("bandwidth_hz", |d| d.bandwidth_hz = 0.0),
            ("bandwidth_hz", |d| d.bandwidth_hz = -1e6),
        ];
        for (field, spoil) in cases {
            let mut d = apd();
            spoil(&mut d);
            let err = d.validate().expect_err(field);
            assert!(err.contains(field), "{err}");
        }
        let err = Detector { gain: 0.5, ..apd() }
            .validate()
            .expect_err("gain");
        assert_eq!(err, "detector: gain = 0.5 must be finite and ≥ 1");
    }

    /// Realisations per Monte Carlo check, and the standard errors allowed (two-sided, a
    /// Gaussian false-alarm rate of 6e-5 per comparison; the seeds are fixed, so the test is
    /// deterministic).
    const REALISATIONS: usize = 10_000;
    const ALLOWED_STANDARD_ERRORS: f64 = 4.0;

    /// Draws `REALISATIONS` values of `sample_sum` and returns the z-scores of the sample
    /// variance against the formula and of the sample mean against Σ N_s.
    ///
    /// The formula, written out independently of `sample_sum`: with λ = Σ N_s + shots (N_b + N_d),
    /// a = F − 1 and s² = shots · white, X = n + √(n a) z₁ + s z₂ − const has the cumulant
    /// generating function K(t) = λ (exp(t + a t²/2) − 1) + s² t²/2, so
    /// κ₂ = F λ + s² (the variance under test) and κ₄ = λ (3a² + 6a + 1) (κ₄ = λ for a Poisson
    /// count, a = 0). The standard error of the sample variance of n draws is
    /// √((μ₄ − σ⁴ (n − 3)/(n − 1))/n) with μ₄ = κ₄ + 3σ⁴ (= λ + 3λ² for Poisson); that of the
    /// mean is σ/√n.
    fn moment_z_scores(
        det: &Detector,
        signal_pe_sum: f64,
        per_shot: &GateNoise,
        shots: u64,
        seed: u64,
    ) -> (f64, f64, f64) {
        let mut rng = streams(seed, Stream::Instrument, 1).remove(0);
        let (mut mean, mut m2) = (0.0, 0.0);
        for i in 0..REALISATIONS {
            let x = det.sample_sum(signal_pe_sum, per_shot, shots, &mut rng);
            welford_add(&mut mean, &mut m2, i + 1, x);
        }
        let n = REALISATIONS as f64;
        let sample_variance = m2 / (n - 1.0);

        let s = shots as f64;
        let lambda = signal_pe_sum + s * (per_shot.background_pe + per_shot.dark_pe);
        let a = per_shot.excess_noise_factor - 1.0;
        let variance = per_shot.excess_noise_factor * lambda + s * per_shot.white_variance_pe2;
        let kappa4 = lambda * (3.0 * a * a + 6.0 * a + 1.0);
        let mu4 = kappa4 + 3.0 * variance * variance;
        let se_variance = ((mu4 - variance * variance * (n - 3.0) / (n - 1.0)) / n).sqrt();
        let se_mean = (variance / n).sqrt();
        (
            (sample_variance - variance) / se_variance,
            (mean - signal_pe_sum) / se_mean,
            sample_variance / variance,
        )
    }

    fn assert_within(label: &str, z_variance: f64, z_mean: f64, ratio: f64) {
        eprintln!(
            "{label}: sample/formula variance = {ratio:.5}, z(variance) = {z_variance:+.3}, \
             z(mean) = {z_mean:+.3}"
        );
        assert!(
            z_variance.abs() < ALLOWED_STANDARD_ERRORS,
            "{label}: z = {z_variance}"
        );
        assert!(
            z_mean.abs() < ALLOWED_STANDARD_ERRORS,
            "{label}: z = {z_mean}"
        );
    }

    #[test]
    fn sample_variance_photon_counter_low_counts() {
        // Mean 3 photo-electrons, no background: a Poisson count, Var = 3.
        let d = Detector::ideal_photon_counter();
        let g = d.gate(3.0 * photon_energy_j(6360.0), 0.0, 6360.0, 1e-6);
        assert!(rel(g.signal_pe, 3.0) < 1e-14);
        assert!(rel(g.variance_pe2, 3.0) < 1e-14);
        let (zv, zm, ratio) = moment_z_scores(&d, g.signal_pe, &g, 1, 11);
        assert_within("photon counter, N_s = 3", zv, zm, ratio);
    }

    #[test]
    fn sample_variance_apd_with_background_and_nep() {
        // F = 5, M = 10, η = 0.8; N_s = 1000, N_b = 300, N_d = 62.4, N_nep² = 2004.9,
        // (σ_ro/M)² = 4: Var = 5 · 1362.4 + 2008.9 ≈ 8821.
        let d = Detector {
            quantum_efficiency: 0.8,
            gain: 10.0,
            excess_noise_factor: 5.0,
            dark_current_a: 1e-11,
            nep_w_per_sqrt_hz: 1e-14,
            amplifier_noise_a_per_sqrt_hz: 0.0,
            readout_noise_electrons: 20.0,
            bandwidth_hz: 1e7,
        };
        assert_eq!(d.validate(), Ok(()));
        let tau = 1e-6;
        let hnu = photon_energy_j(6360.0);
        let g = d.gate(1000.0 * hnu / 0.8, 300.0 * hnu / (0.8 * tau), 6360.0, tau);
        assert!(rel(g.signal_pe, 1000.0) < 1e-13);
        assert!(rel(g.background_pe, 300.0) < 1e-13);
        // One shot: the variance under test is gate's own Var.
        let expected = 5.0 * (g.signal_pe + g.background_pe + g.dark_pe) + g.white_variance_pe2;
        assert!(rel(g.variance_pe2, expected) < 1e-15);
        let (zv, zm, ratio) = moment_z_scores(&d, g.signal_pe, &g, 1, 12);
        assert_within("APD F = 5, M = 10, N_s = 1000", zv, zm, ratio);
    }

    #[test]
    fn sample_variance_shot_sum_with_varying_signal() {
        // 50 shots, per-shot signal 20 (1 + 0.3 sin i) photo-electrons (laser energy jitter);
        // F = 3, M = 20, τ = 200 ns, B = 50 MHz (2Bτ = 20), dark, amplifier and readout noise.
        let d = Detector {
            quantum_efficiency: 0.8,
            gain: 20.0,
            excess_noise_factor: 3.0,
            dark_current_a: 1e-11,
            nep_w_per_sqrt_hz: 0.0,
            amplifier_noise_a_per_sqrt_hz: 1e-13,
            readout_noise_electrons: 100.0,
            bandwidth_hz: 5e7,
        };
        assert_eq!(d.validate(), Ok(()));
        let (tau, wn) = (2e-7, 6360.0);
        let hnu = photon_energy_j(wn);
        let shots = 50_u64;
        let signal_pe_sum: f64 = (0..shots)
            .map(|i| {
                let energy_j = 20.0 * (1.0 + 0.3 * (i as f64).sin()) * hnu / 0.8;
                d.gate(energy_j, 0.0, wn, tau).signal_pe
            })
            .sum();
        let per_shot = d.gate(20.0 * hnu / 0.8, 5.0 * hnu / (0.8 * tau), wn, tau);
        // The shot sum's variance is Σ Var with Σ N_s in place of shots · N_s.
        let summed = shots as f64 * per_shot.variance_pe2
            + per_shot.excess_noise_factor * (signal_pe_sum - shots as f64 * per_shot.signal_pe);
        let lambda = signal_pe_sum + shots as f64 * (per_shot.background_pe + per_shot.dark_pe);
        assert!(
            rel(
                summed,
                3.0 * lambda + shots as f64 * per_shot.white_variance_pe2
            ) < 1e-12,
            "{summed}"
        );
        let (zv, zm, ratio) = moment_z_scores(&d, signal_pe_sum, &per_shot, shots, 13);
        assert_within("50 shots, APD F = 3, M = 20", zv, zm, ratio);
    }

    #[test]
    fn sample_sum_edge_cases() {
        let mut rng = streams(14, Stream::Instrument, 1).remove(0);
        let d = Detector::ideal_photon_counter();
        // λ = 0: exactly 0, nothing drawn.
        let empty = d.gate(0.0, 0.0, 6360.0, 1e-6);
        assert_eq!(d.sample_sum(0.0, &empty, 10, &mut rng), 0.0);
        // Not a realisable mean: NaN, no panic.
        assert!(d.sample_sum(f64::NAN, &empty, 1, &mut rng).is_nan());
        assert!(d.sample_sum(-1.0, &empty, 1, &mut rng).is_nan());
        let bad_f = GateNoise {
            excess_noise_factor: 0.5,
            ..empty
        };
        assert!(d.sample_sum(1.0, &bad_f, 1, &mut rng).is_nan());
        // Beyond rand_distr's Poisson limit: the Gaussian fallback, mean λ and sd √λ.
        let lambda = 1e20;
        assert!(lambda > Poisson::<f64>::MAX_LAMBDA);
        for _ in 0..100 {
            let x = d.sample_sum(lambda, &empty, 1, &mut rng);
            assert!(((x - lambda) / lambda.sqrt()).abs() < 5.0, "{x}");
        }
    }
}
