//! Signals: the receiver (filter, detector, background) and the photo-electrons and noise it
//! makes of line returns, per gate and per pulse, analytically and as noisy realisations of
//! shot-averaged measurements.
//!
//! Per gate of duration τ = 2Δr/c and per pulse of line ℓ ([`super::detector`] has the noise
//! formula): the signal is the line's return through the filter (energies in
//! [`LineReturns`] already carry the filter and the optical
//! efficiency), the background power is P_b = L Δλ Ω A η_opt T_f at the line's wavelength.
//!
//! A measurement averages N shot pairs. Shot s of line ℓ has energy e_s = E_ℓ(1 + ε_E z) and
//! frequency c + δ_s, δ_s ~ N(0, σ_j²); its expected return in a gate is
//! (e_s/E_ℓ)[P̄ − ½Cσ_j² + Sδ_s + ½Cδ_s²] ([`super::laser`]), and the energy monitor reads
//! e_s(1 + ε_M z'). Summed over the shots, the photo-electrons of a gate are drawn once
//! ([`Detector::sample_sum`]); the laser state (energies, frequencies, monitor readings) is
//! drawn shot by shot and shared by every gate of that line, as in the instrument.

use std::ops::Range;

use rand_distr::{Distribution, StandardNormal};

use super::detector::{self, Detector, GateNoise};
use super::laser::{Filter, Laser, Line, LineReturns};
use crate::constants::SPEED_OF_LIGHT_M_PER_S;
use crate::returns::{Order, Returns, Source};
use crate::rng::Rng;

/// The receiver behind the telescope (whose area, efficiency and fields of view are the
/// lidar's).
#[derive(Debug, Clone, PartialEq)]
pub struct Receiver {
    /// The spectral filter (also bounds the background).
    pub filter: Filter,
    /// The photo-detector and its electronics.
    pub detector: Detector,
    /// Radiance of the scene seen by the telescope (sunlit surface or cloud)
    /// \[W m⁻² sr⁻¹ µm⁻¹\]; 0 at night.
    pub background_radiance_w_per_m2_sr_um: f64,
}

/// The telescope's share of the receiver: collecting area and optical efficiency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Telescope {
    /// Collecting area \[m²\].
    pub area_m2: f64,
    /// Optical efficiency of the receiver optics before the filter (0, 1].
    pub optical_efficiency: f64,
}

/// Mean photo-electrons and noise per pulse, by line, field of view and gate, for one set of
/// returns (a source and a scattering order).
#[derive(Debug, Clone, PartialEq)]
pub struct Signals {
    /// Where the returns came from.
    pub source: Source,
    /// Which scattering order they hold.
    pub order: Order,
    /// The lines.
    pub lines: Vec<Line>,
    /// Fields of view (full angles) \[mrad\].
    pub fov_full_angle_mrad: Vec<f64>,
    /// Gate centres \[m\].
    pub range_m: Vec<f64>,
    /// Duration of one gate \[s\].
    pub gate_duration_s: f64,
    /// The detector.
    pub detector: Detector,
    /// Background power at the detector per line and FOV \[W\], index `line * n_fov + fov`.
    pub background_power_w: Vec<f64>,
    /// Mean received energy per pulse \[J\], index [`Signals::index`].
    pub energy_j: Vec<f64>,
    /// ∂E/∂ν \[J/MHz\] and ∂²E/∂ν² \[J/MHz²\] per gate (zero without frequency jitter).
    pub slope_j_per_mhz: Vec<f64>,
    /// See `slope_j_per_mhz`.
    pub curvature_j_per_mhz2: Vec<f64>,
    /// Photo-electrons and noise per pulse, same index.
    pub noise: Vec<GateNoise>,
}

impl Signals {
    /// Signals of the line returns `lines` (order `order`) through `receiver`.
    pub fn new(
        returns: &LineReturns,
        order: Order,
        laser_lines: &[Line],
        receiver: &Receiver,
        telescope: Telescope,
        gate_width_m: f64,
    ) -> Option<Signals> {
        let mean = &returns.mean;
        let o = mean.order_index(order)?;
        let n_fov = mean.fov_full_angle_mrad.len();
        let n_gates = mean.range_m.len();
        let tau = 2.0 * gate_width_m / SPEED_OF_LIGHT_M_PER_S;
        let mut background_power_w = Vec::new();
        for l in laser_lines {
            // Δλ [µm] = Δν λ² = Δν / ν² · 1e4 with ν in cm⁻¹.
            let dl_um = receiver.filter.bandwidth_cm1 / (l.wavenumber_cm1 * l.wavenumber_cm1) * 1e4;
            for fov in &mean.fov_full_angle_mrad {
                background_power_w.push(if receiver.background_radiance_w_per_m2_sr_um > 0.0 {
                    detector::background_power_w(
                        receiver.background_radiance_w_per_m2_sr_um,
                        dl_um,
                        *fov,
                        telescope.area_m2,
                        telescope.optical_efficiency,
                        receiver.filter.transmission,
                    )
                } else {
                    0.0
                });
            }
        }
        let n = laser_lines.len() * n_fov * n_gates;
        let (mut energy_j, mut slope, mut curvature, mut noise) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        let deriv = |r: &Returns, l: usize, f: usize, g: usize| r.energy_j[r.index(l, f, g, o)];
        for (l, line) in laser_lines.iter().enumerate() {
            for f in 0..n_fov {
                for g in 0..n_gates {
                    let e = mean.energy_j[mean.index(l, f, g, o)].max(0.0);
                    energy_j.push(e);
                    let (s, c) = match &returns.derivatives {
                        Some((s, c)) => (deriv(s, l, f, g), deriv(c, l, f, g)),
                        None => (0.0, 0.0),
                    };
                    slope.push(s);
                    curvature.push(c);
                    noise.push(receiver.detector.gate(
                        e,
                        background_power_w[l * n_fov + f],
                        line.wavenumber_cm1,
                        tau,
                    ));
                }
            }
        }
        Some(Signals {
            source: mean.source,
            order,
            lines: laser_lines.to_vec(),
            fov_full_angle_mrad: mean.fov_full_angle_mrad.clone(),
            range_m: mean.range_m.clone(),
            gate_duration_s: tau,
            detector: receiver.detector.clone(),
            background_power_w,
            energy_j,
            slope_j_per_mhz: slope,
            curvature_j_per_mhz2: curvature,
            noise,
        })
    }

    /// Flat index of (line, fov, gate).
    pub fn index(&self, line: usize, fov: usize, gate: usize) -> usize {
        (line * self.fov_full_angle_mrad.len() + fov) * self.range_m.len() + gate
    }

    /// Photo-electrons and noise of one gate per pulse.
    pub fn gate(&self, line: usize, fov: usize, gate: usize) -> &GateNoise {
        &self.noise[self.index(line, fov, gate)]
    }

    /// Mean energy, slope and curvature of the echo summed over `gates`.
    pub fn window_energy(&self, line: usize, fov: usize, gates: Range<usize>) -> (f64, f64, f64) {
        gates.fold((0.0, 0.0, 0.0), |(e, s, c), g| {
            let i = self.index(line, fov, g);
            (
                e + self.energy_j[i],
                s + self.slope_j_per_mhz[i],
                c + self.curvature_j_per_mhz2[i],
            )
        })
    }

    /// The echo summed over `gates` (a hard target's window, or one gate): its expected energy,
    /// frequency derivatives, and photo-electrons and noise per pulse (one integration of the
    /// gates' joint duration).
    pub fn window(&self, line: usize, fov: usize, gates: Range<usize>) -> WindowSignal {
        let n = gates.len() as f64;
        let (e, s, c) = self.window_energy(line, fov, gates);
        WindowSignal {
            noise: self.detector.gate(
                e,
                self.background_power_w[line * self.fov_full_angle_mrad.len() + fov],
                self.lines[line].wavenumber_cm1,
                n * self.gate_duration_s,
            ),
            energy_j: e,
            slope_j_per_mhz: s,
            curvature_j_per_mhz2: c,
        }
    }

    /// One noisy measurement of a line, averaged over `shots` pulses: the background-subtracted
    /// photo-electrons summed over the shots in each of `windows` (of that line and one field
    /// of view, from [`Signals::window`]), and the energy monitor's reading summed over the
    /// shots, in units of the nominal pulse energy (module docs).
    pub fn realise(
        &self,
        laser: &Laser,
        windows: &[WindowSignal],
        shots: u64,
        rng: &mut Rng,
    ) -> (Vec<f64>, f64) {
        let shot = draw_shots(laser, shots, rng);
        let var = laser.frequency_jitter_rms_mhz.powi(2);
        let counts = windows
            .iter()
            .map(|w| {
                let (e, s, c) = (w.energy_j, w.slope_j_per_mhz, w.curvature_j_per_mhz2);
                let energy_sum = shot.energy * (e - 0.5 * c * var)
                    + s * shot.energy_delta
                    + 0.5 * c * shot.energy_delta2;
                let pe_per_j = if e > 0.0 { w.noise.signal_pe / e } else { 0.0 };
                self.detector
                    .sample_sum((energy_sum * pe_per_j).max(0.0), &w.noise, shots, rng)
            })
            .collect();
        (counts, shot.monitored_energy)
    }
}

/// The expected echo of a window of gates of one line and field of view, per pulse.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowSignal {
    /// Photo-electrons and noise.
    pub noise: GateNoise,
    /// Mean energy \[J\].
    pub energy_j: f64,
    /// ∂E/∂ν \[J/MHz\].
    pub slope_j_per_mhz: f64,
    /// ∂²E/∂ν² \[J/MHz²\].
    pub curvature_j_per_mhz2: f64,
}

impl WindowSignal {
    /// Relative signal change per shot caused by a frequency jitter of rms σ_j, σ_j S/P̄
    /// (signed; 0 without signal).
    pub fn jitter_relative(&self, jitter_rms_mhz: f64) -> f64 {
        if self.energy_j > 0.0 {
            jitter_rms_mhz * self.slope_j_per_mhz / self.energy_j
        } else {
            0.0
        }
    }
}

/// Header of `signals.csv`: per pulse, by source, order, line, field of view and gate.
pub const CSV_HEADER: &str = "source,order,channel,fov_full_angle_mrad,range_m,signal_photoelectrons,background_photoelectrons,dark_electrons,noise_std_photoelectrons,snr";

impl Signals {
    /// The CSV rows (no header), ordered by line, field of view, gate.
    pub fn csv_rows(&self, out: &mut String) {
        use std::fmt::Write as _;
        let (src, order) = (self.source.label(), self.order.label());
        for (l, line) in self.lines.iter().enumerate() {
            for (f, fov) in self.fov_full_angle_mrad.iter().enumerate() {
                for (g, r) in self.range_m.iter().enumerate() {
                    let n = self.gate(l, f, g);
                    let _ = writeln!(
                        out,
                        "{src},{order},{},{fov},{r},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e}",
                        crate::output::csv_field(&line.name),
                        crate::output::csv_number(n.signal_pe),
                        crate::output::csv_number(n.background_pe),
                        crate::output::csv_number(n.dark_pe),
                        crate::output::csv_number(n.std_pe()),
                        crate::output::csv_number(n.snr())
                    );
                }
            }
        }
    }
}

/// Sums over the shots of one line of a measurement (energies relative to the nominal one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShotSums {
    /// Σ e_s/E.
    pub energy: f64,
    /// Σ (e_s/E) δ_s \[MHz\].
    pub energy_delta: f64,
    /// Σ (e_s/E) δ_s² \[MHz²\].
    pub energy_delta2: f64,
    /// Σ (e_s/E)(1 + ε_M z'_s): what the energy monitor reads.
    pub monitored_energy: f64,
}

/// Above this many shots the sums are drawn from their joint normal distribution (central
/// limit theorem) instead of shot by shot, so that an average over 10⁹ shots costs no more
/// than one over 10³.
pub const SHOTS_DRAWN_ONE_BY_ONE: u64 = 256;

/// Draw the laser state of `shots` pulses (module docs). A perfect laser draws nothing.
///
/// Per shot, with e = 1 + ε_E z₁ (relative energy), δ = σ_j z₂ and m = 1 + ε_M z₃:
/// E⟨e⟩ = 1, E⟨eδ⟩ = 0, E⟨eδ²⟩ = σ², E⟨em⟩ = 1, and the covariances of (e, eδ², em):
/// Var e = ε², Var eδ² = (1 + ε²) 3σ⁴ − σ⁴, Var em = ε² + ε_M²(1 + ε²),
/// Cov(e, eδ²) = Cov(eδ², em) = ε²σ², Cov(e, em) = ε²; eδ is uncorrelated with the others,
/// Var eδ = (1 + ε²)σ². Above [`SHOTS_DRAWN_ONE_BY_ONE`] shots the sums are drawn from the
/// normal distribution with N times these moments (Cholesky factor of the 3 × 3 block).
pub fn draw_shots(laser: &Laser, shots: u64, rng: &mut Rng) -> ShotSums {
    let n = shots as f64;
    let (ee, sj, em) = (
        laser.pulse_energy_jitter_fraction,
        laser.frequency_jitter_rms_mhz,
        laser.energy_monitor_error_fraction,
    );
    if ee == 0.0 && sj == 0.0 && em == 0.0 {
        return ShotSums {
            energy: n,
            energy_delta: 0.0,
            energy_delta2: 0.0,
            monitored_energy: n,
        };
    }
    let mut normal = || -> f64 { StandardNormal.sample(rng) };
    if shots > SHOTS_DRAWN_ONE_BY_ONE {
        let (e2, s2) = (ee * ee, sj * sj);
        // Covariance of (e, eδ², em) per shot, and its Cholesky factor L (lower).
        let c = [
            [e2, e2 * s2, e2],
            [e2 * s2, (1.0 + e2) * 3.0 * s2 * s2 - s2 * s2, e2 * s2],
            [e2, e2 * s2, e2 + em * em * (1.0 + e2)],
        ];
        let l = cholesky3(&c);
        let z = [normal(), normal(), normal()];
        let sq = n.sqrt();
        let dev = |i: usize| sq * (0..=i).map(|j| l[i][j] * z[j]).sum::<f64>();
        return ShotSums {
            energy: n + dev(0),
            energy_delta: sq * ((1.0 + e2) * s2).sqrt() * normal(),
            energy_delta2: n * s2 + dev(1),
            monitored_energy: n + dev(2),
        };
    }
    let mut s = ShotSums {
        energy: 0.0,
        energy_delta: 0.0,
        energy_delta2: 0.0,
        monitored_energy: 0.0,
    };
    for _ in 0..shots {
        // A pulse cannot have negative energy (relevant only for absurd jitters).
        let e = if ee > 0.0 {
            (1.0 + ee * normal()).max(0.0)
        } else {
            1.0
        };
        let d = if sj > 0.0 { sj * normal() } else { 0.0 };
        let m = if em > 0.0 { 1.0 + em * normal() } else { 1.0 };
        s.energy += e;
        s.energy_delta += e * d;
        s.energy_delta2 += e * d * d;
        s.monitored_energy += e * m;
    }
    s
}

/// Cholesky factor of a 3 × 3 covariance matrix; rows of zeros where it is singular (a
/// quantity that does not fluctuate).
fn cholesky3(c: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut l = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            if i == j {
                l[i][i] = (c[i][i] - s).max(0.0).sqrt();
            } else if l[j][j] > 0.0 {
                l[i][j] = (c[i][j] - s) / l[j][j];
            }
        }
    }
    l
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{Stream, streams};

    /// A window of gates is one integration of the summed echo over the gates' joint duration:
    /// its energy, slope and curvature are the sums over the gates, its background and dark
    /// electrons n times one gate's (N_b = η P_b nτ/(hν), N_d = I_d nτ/e), with the background
    /// power of its own line and field of view. Two lines at different wavenumbers, two fields
    /// of view, and every per-gate value distinct, so a wrong sign or index shows.
    #[test]
    fn a_window_integrates_its_gates_with_its_own_background() {
        let (n_lines, n_fov, n_gates) = (2, 2, 3);
        // P_b of (line, fov) [W].
        let p_b_w = [1e-9, 2e-9, 5e-9, 11e-9];
        let value = |l: usize, f: usize, g: usize, kind: f64| {
            kind * (1.0 + l as f64 + 3.0 * f as f64 + 7.0 * g as f64)
        };
        let mut sig = Signals {
            source: Source::Analytic,
            order: Order::Total,
            lines: vec![
                Line {
                    name: "on".into(),
                    wavenumber_cm1: 6359.97,
                },
                Line {
                    name: "off".into(),
                    wavenumber_cm1: 6358.0,
                },
            ],
            fov_full_angle_mrad: vec![0.2, 1.0],
            range_m: vec![1000.0, 1030.0, 1060.0],
            gate_duration_s: 2.0e-7,
            detector: Detector {
                dark_current_a: 3e-9,
                ..Detector::ideal_photon_counter()
            },
            background_power_w: p_b_w.to_vec(),
            energy_j: Vec::new(),
            slope_j_per_mhz: Vec::new(),
            curvature_j_per_mhz2: Vec::new(),
            noise: Vec::new(),
        };
        for l in 0..n_lines {
            for f in 0..n_fov {
                for g in 0..n_gates {
                    sig.energy_j.push(value(l, f, g, 1e-15));
                    sig.slope_j_per_mhz.push(value(l, f, g, -2e-17));
                    sig.curvature_j_per_mhz2.push(value(l, f, g, 3e-19));
                }
            }
        }
        let planck_c = 6.626_070_15e-34 * 299_792_458.0;
        for l in 0..n_lines {
            for f in 0..n_fov {
                let w = sig.window(l, f, 0..n_gates);
                let sum = |kind: f64| (0..n_gates).map(|g| value(l, f, g, kind)).sum::<f64>();
                let close = |a: f64, b: f64| (a / b - 1.0).abs() < 1e-12;
                assert!(close(w.energy_j, sum(1e-15)), "line {l} fov {f}: energy");
                assert!(
                    close(w.slope_j_per_mhz, sum(-2e-17)),
                    "line {l} fov {f}: slope"
                );
                assert!(
                    close(w.curvature_j_per_mhz2, sum(3e-19)),
                    "line {l} fov {f}: curvature"
                );
                let photon_j = planck_c * sig.lines[l].wavenumber_cm1 * 100.0;
                let duration_s = n_gates as f64 * sig.gate_duration_s;
                let p_b = p_b_w[l * n_fov + f];
                assert!(
                    close(w.noise.signal_pe, sum(1e-15) / photon_j),
                    "line {l} fov {f}"
                );
                assert!(
                    close(w.noise.background_pe, p_b * duration_s / photon_j),
                    "line {l} fov {f}: background"
                );
                assert!(
                    close(w.noise.dark_pe, 3e-9 * duration_s / 1.602_176_634e-19),
                    "line {l} fov {f}: dark"
                );
            }
        }
    }

    /// σ_j S/P̄, signed, and 0 without signal (not 0/0).
    #[test]
    fn jitter_relative_is_signed_and_zero_without_signal() {
        let w = |energy_j: f64, slope_j_per_mhz: f64| WindowSignal {
            noise: Detector::ideal_photon_counter().gate(energy_j, 0.0, 6360.0, 1e-7),
            energy_j,
            slope_j_per_mhz,
            curvature_j_per_mhz2: 0.0,
        };
        assert_eq!(w(2e-15, -1e-17).jitter_relative(0.4), -0.002);
        assert_eq!(w(0.0, 0.0).jitter_relative(0.4), 0.0);
        assert_eq!(w(0.0, 1e-17).jitter_relative(0.4), 0.0);
    }

    #[test]
    fn shot_sums_have_the_stated_moments() {
        // Every moment `draw_shots` documents, shot by shot (N = 50) and from the joint normal
        // (N = 5000), a laser whose only imperfection is its energy monitor, and one with 30 %
        // energy jitter and a monitor error of 1, where ε_M²(1 + ε²) is 15 % above ε_M²(1 − ε²)
        // (the pulse energy's clipping at 0 moves the moments by < 1e-4 there). Tolerances:
        // 4 standard errors (means: √(Var/reps); variances: Var·√((2 + κ)/reps) with κ the
        // excess kurtosis, 12/N for Σeδ²; covariances: √(Var_a Var_b/reps) for the weak
        // correlations here).
        let laser = |ee: f64, sj: f64, em: f64| {
            let mut l = Laser::ideal(1.0, 1);
            l.pulse_energy_jitter_fraction = ee;
            l.frequency_jitter_rms_mhz = sj;
            l.energy_monitor_error_fraction = em;
            l
        };
        for (ee, sj, em) in [(0.05, 0.3, 0.01), (0.0, 0.0, 0.01), (0.3, 0.3, 1.0)] {
            let l = laser(ee, sj, em);
            let (e2, s2) = (ee * ee, sj * sj);
            for n in [50u64, 5000] {
                let mut rng = streams(5, Stream::Instrument, 1).remove(0);
                let reps = 4000;
                let draws: Vec<ShotSums> = (0..reps).map(|_| draw_shots(&l, n, &mut rng)).collect();
                let (r, nf) = (reps as f64, n as f64);
                let mean = |f: &dyn Fn(&ShotSums) -> f64| draws.iter().map(f).sum::<f64>() / r;
                let cov = |f: &dyn Fn(&ShotSums) -> f64, g: &dyn Fn(&ShotSums) -> f64| {
                    let (mf, mg) = (mean(f), mean(g));
                    draws.iter().map(|d| (f(d) - mf) * (g(d) - mg)).sum::<f64>() / (r - 1.0)
                };
                let a = |d: &ShotSums| d.energy;
                let b = |d: &ShotSums| d.energy_delta;
                let dd = |d: &ShotSums| d.energy_delta2;
                let m = |d: &ShotSums| d.monitored_energy;
                let var_a = nf * e2;
                let var_b = nf * (1.0 + e2) * s2;
                let var_d = nf * ((1.0 + e2) * 3.0 * s2 * s2 - s2 * s2);
                let var_m = nf * (e2 + em * em * (1.0 + e2));
                let what = format!("ε {ee}, σ {sj}, ε_M {em}, N {n}");
                let close = |got: f64, want: f64, se: f64| (got - want).abs() <= 4.0 * se;
                assert!(close(mean(&a), nf, (var_a / r).sqrt()), "{what}");
                assert!(close(mean(&m), nf, (var_m / r).sqrt()), "{what}");
                assert!(close(mean(&dd), nf * s2, (var_d / r).sqrt()), "{what}");
                let rel = |kurtosis: f64| ((2.0 + kurtosis) / r).sqrt();
                for (got, want, k) in [
                    (cov(&a, &a), var_a, 0.0),
                    (cov(&b, &b), var_b, 0.0),
                    (cov(&dd, &dd), var_d, 12.0 / nf),
                    (cov(&m, &m), var_m, 0.0),
                ] {
                    assert!(
                        close(got, want, want * rel(k)),
                        "{what}: variance {got} vs {want}"
                    );
                }
                for (got, want, se) in [
                    (cov(&a, &dd), nf * e2 * s2, (var_a * var_d / r).sqrt()),
                    (cov(&a, &m), nf * e2, (var_a * var_m / r).sqrt()),
                    (cov(&dd, &m), nf * e2 * s2, (var_d * var_m / r).sqrt()),
                    (cov(&a, &b), 0.0, (var_a * var_b / r).sqrt()),
                ] {
                    assert!(close(got, want, se), "{what}: covariance {got} vs {want}");
                }
            }
        }
    }
}
