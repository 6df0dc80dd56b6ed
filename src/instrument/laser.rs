//! The laser: its lines, their emission spectrum and energy, and the monochromatic channels
//! that sample them.
//!
//! A *line* is what the user names (`on`, `off`): a nominal wavenumber. The laser emits around
//! it with a line shape g(x) (x the frequency offset from the line's actual centre, which sits
//! `frequency_offset_mhz` from the nominal one), a fraction 1 − p of the energy (spectral
//! impurity, e.g. amplified spontaneous emission) elsewhere, and a frequency that jitters from
//! shot to shot with rms σ_j. The transport and the lidar equation are monochromatic, so each
//! line becomes a few *channels* riding on the same photon paths (docs/design.md §1):
//!
//! * the n quadrature nodes of g over the filter's pass band ([`LineShape::nodes_within`]),
//!   P̄ = Σᵢ wᵢ P(c + xᵢ), the energy outside the band being blocked;
//! * with jitter, a three-point stencil c − h, c, c + h (h = max(2σ_j, 1 MHz)) giving the slope
//!   S = ∂P/∂ν and curvature C = ∂²P/∂ν² of the return with respect to the laser frequency;
//!   a shot at c + δ returns P̄ + S δ + ½ C δ², so the mean over shots is P̄ + ½ C σ_j². The
//!   derivatives are those of the monochromatic return at the line centre, standing in for those
//!   of the line-shape average: exact to second order in (line width / absorption-line width);
//! * with p < 1, one channel at the impurity's wavenumber.
//!
//! The receiver's filter (a flat top of full width B and peak transmission T_f around each line's
//! nominal wavenumber) weights each channel, so the line returns are what reaches the detector.
//! A line's return is a linear [`Combination`] of channel returns:
//!
//! ```text
//! P_line = (E_line/E_0) [ p Σᵢ wᵢ T_f(νᵢ) Pᵢ + (1 − p) T_f(ν_imp) P_imp + p T_f(c) ½ σ_j² C ]
//! ```
//!
//! with E_0 the pulse energy the transport runs with (that of the first line). Ehret et al.
//! (2008, Appl. Phys. B 90, 593) set the scale of these effects for a 1.6 µm CO2 IPDA: frequency
//! stability ±0.3 MHz, spectral purity 99.9 % behind a 1 GHz filter.

use super::line_shape::{LineShape, MHZ_PER_CM1};
use crate::returns::{Combination, Returns};

/// A laser line as the user names it.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    /// Name (`on`, `off`, …).
    pub name: String,
    /// Nominal vacuum wavenumber [cm⁻¹].
    pub wavenumber_cm1: f64,
}

/// The emitter of a DIAL/IPDA lidar: one emission model for all its lines.
#[derive(Debug, Clone, PartialEq)]
pub struct Laser {
    /// Emission line shape around each line's actual centre.
    pub line_shape: LineShape,
    /// Quadrature nodes per line (1 for a monochromatic laser).
    pub nodes: usize,
    /// Systematic offset of each line's actual centre from its nominal wavenumber \[MHz\].
    pub frequency_offset_mhz: Vec<f64>,
    /// Shot-to-shot frequency jitter, rms \[MHz\].
    pub frequency_jitter_rms_mhz: f64,
    /// Fraction p of the energy inside the line shape; the rest is at the impurity wavenumber.
    pub spectral_purity: f64,
    /// Where each line's impure energy is emitted [cm⁻¹] (unused when p = 1).
    pub impurity_wavenumber_cm1: Vec<f64>,
    /// Pulse energy of each line \[J\].
    pub pulse_energy_j: Vec<f64>,
    /// Shot pairs per second (one pulse of every line per period, as a double-pulse laser).
    pub repetition_rate_hz: f64,
    /// Shot-to-shot fluctuation of the pulse energy, relative rms.
    pub pulse_energy_jitter_fraction: f64,
    /// Relative rms error of the energy monitor's reading of one pulse.
    pub energy_monitor_error_fraction: f64,
}

impl Laser {
    /// A monochromatic, perfectly stable laser with one pulse energy for all `n_lines` lines and
    /// an unknown repetition rate (NaN): the laser of a scene without a `[laser]` section.
    pub fn ideal(pulse_energy_j: f64, n_lines: usize) -> Laser {
        Laser {
            line_shape: LineShape::Monochromatic,
            nodes: 1,
            frequency_offset_mhz: vec![0.0; n_lines],
            frequency_jitter_rms_mhz: 0.0,
            spectral_purity: 1.0,
            impurity_wavenumber_cm1: vec![f64::NAN; n_lines],
            pulse_energy_j: vec![pulse_energy_j; n_lines],
            repetition_rate_hz: f64::NAN,
            pulse_energy_jitter_fraction: 0.0,
            energy_monitor_error_fraction: 0.0,
        }
    }

    /// Step h of the frequency-jitter stencil \[MHz\]: 2σ_j, at least 1 MHz. The return is
    /// smooth on the scale of the Doppler width (≈ 200 MHz at 1.6 µm), so the finite
    /// differences are accurate to (h/200 MHz)², and the channels share photon paths, so the
    /// differences carry little Monte Carlo noise.
    pub fn jitter_step_mhz(&self) -> f64 {
        (2.0 * self.frequency_jitter_rms_mhz).max(1.0)
    }
}

/// The receiver's spectral filter: a flat top of full width `bandwidth_cm1` and peak
/// transmission `transmission`, centred on each line's nominal wavenumber.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Filter {
    /// Full width [cm⁻¹] (∞: no filter).
    pub bandwidth_cm1: f64,
    /// Peak transmission (0, 1].
    pub transmission: f64,
}

impl Filter {
    /// No filter: every wavenumber passes unattenuated.
    pub fn none() -> Self {
        Filter {
            bandwidth_cm1: f64::INFINITY,
            transmission: 1.0,
        }
    }

    /// The quadrature nodes of a line of `laser` whose centre sits `offset_mhz` from the
    /// filter's centre (its nominal wavenumber) that pass this filter: the line shape
    /// integrated over the pass band only ([`LineShape::nodes_within`]), offsets relative to
    /// the line's actual centre, weights summing to the share of its energy inside the band.
    pub fn line_nodes(
        &self,
        laser: &Laser,
        offset_mhz: f64,
    ) -> Vec<super::line_shape::QuadratureNode> {
        let half_mhz = 0.5 * self.bandwidth_cm1 * MHZ_PER_CM1;
        let off = offset_mhz;
        laser
            .line_shape
            .nodes_within(laser.nodes, -half_mhz - off, half_mhz - off)
    }

    /// Transmission at `wavenumber_cm1` of the filter centred on `centre_cm1`.
    pub fn transmission_at(&self, wavenumber_cm1: f64, centre_cm1: f64) -> f64 {
        if (wavenumber_cm1 - centre_cm1).abs() <= 0.5 * self.bandwidth_cm1 {
            self.transmission
        } else {
            0.0
        }
    }
}

/// What a sampled channel stands for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChannelRole {
    /// Quadrature node i of the line shape (0-based).
    Node(usize),
    /// The line's spectral impurity.
    Impurity,
    /// The jitter stencil: c − h, c, c + h.
    JitterMinus,
    /// The line's actual centre, for the jitter stencil (when no node sits there).
    JitterCentre,
    /// c + h.
    JitterPlus,
}

/// One monochromatic channel of the transport.
#[derive(Debug, Clone, PartialEq)]
pub struct SampledChannel {
    /// Name (`on` for a monochromatic line; `on#3`, `on#jitter+`, `on#impurity` otherwise).
    pub name: String,
    /// Vacuum wavenumber [cm⁻¹].
    pub wavenumber_cm1: f64,
    /// The line it belongs to.
    pub line: usize,
    /// What it stands for (in that line).
    pub role: ChannelRole,
}

/// The channels that sample a laser's lines, and the combinations that turn their returns into
/// line returns.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralSampling {
    /// The lines.
    pub lines: Vec<Line>,
    /// The monochromatic channels, in transport order (channel 0 is the transport's reference).
    pub channels: Vec<SampledChannel>,
    /// Mean return of each line (per pulse, through the filter).
    pub mean: Vec<Combination>,
    /// Per line, ∂P/∂ν [J/MHz] and ∂²P/∂ν² [J/MHz²] at the line's centre (with jitter only).
    pub derivatives: Option<(Vec<Combination>, Vec<Combination>)>,
}

/// The line returns a sampling's combinations give.
#[derive(Debug, Clone, PartialEq)]
pub struct LineReturns {
    /// Mean return of each line \[J\], channels named as the lines.
    pub mean: Returns,
    /// ∂P/∂ν \[J/MHz\] and ∂²P/∂ν² \[J/MHz²\] per line, where the laser jitters.
    pub derivatives: Option<(Returns, Returns)>,
}

impl SpectralSampling {
    /// One channel per line, each its own line: a monochromatic laser.
    pub fn identity(lines: &[Line]) -> Self {
        SpectralSampling {
            lines: lines.to_vec(),
            channels: lines
                .iter()
                .enumerate()
                .map(|(i, l)| SampledChannel {
                    name: l.name.clone(),
                    wavenumber_cm1: l.wavenumber_cm1,
                    line: i,
                    role: ChannelRole::Node(0),
                })
                .collect(),
            mean: lines
                .iter()
                .enumerate()
                .map(|(i, l)| Combination {
                    name: l.name.clone(),
                    terms: vec![(i, 1.0)],
                })
                .collect(),
            derivatives: None,
        }
    }

    /// Sample the lines of `laser` for a receiver with `filter` (module docs). `laser`'s
    /// per-line vectors must have one entry per line.
    pub fn new(laser: &Laser, lines: &[Line], filter: &Filter) -> Self {
        let mut channels: Vec<SampledChannel> = Vec::new();
        // Channels are never shared between lines, even at one wavenumber: lines may differ in
        // other per-line properties (layer absorption, albedo).
        let mut channel = |name: String, nu: f64, line: usize, role: ChannelRole| -> usize {
            channels.push(SampledChannel {
                name,
                wavenumber_cm1: nu,
                line,
                role,
            });
            channels.len() - 1
        };
        let jitter = laser.frequency_jitter_rms_mhz > 0.0;
        let h = laser.jitter_step_mhz();
        let p = laser.spectral_purity;
        let e0 = laser.pulse_energy_j[0];
        let mut mean = Vec::new();
        let (mut slope, mut curvature) = (Vec::new(), Vec::new());
        for (l, line) in lines.iter().enumerate() {
            let scale = laser.pulse_energy_j[l] / e0;
            let centre = line.wavenumber_cm1 + laser.frequency_offset_mhz[l] / MHZ_PER_CM1;
            let tf = |nu: f64| filter.transmission_at(nu, line.wavenumber_cm1);
            let nodes = filter.line_nodes(laser, laser.frequency_offset_mhz[l]);
            let mut terms: Vec<(usize, f64)> = Vec::new();
            let mut centre_channel = None;
            for (i, q) in nodes.iter().enumerate() {
                let nu = centre + q.offset_mhz / MHZ_PER_CM1;
                let name = if nodes.len() == 1 {
                    line.name.clone()
                } else {
                    format!("{}#{}", line.name, i + 1)
                };
                let k = channel(name, nu, l, ChannelRole::Node(i));
                if q.offset_mhz == 0.0 {
                    centre_channel = Some(k);
                }
                terms.push((k, scale * p * q.weight * tf(nu)));
            }
            if p < 1.0 {
                let nu = laser.impurity_wavenumber_cm1[l];
                let k = channel(
                    format!("{}#impurity", line.name),
                    nu,
                    l,
                    ChannelRole::Impurity,
                );
                terms.push((k, scale * (1.0 - p) * tf(nu)));
            }
            if jitter {
                let c0 = centre_channel.unwrap_or_else(|| {
                    channel(
                        format!("{}#centre", line.name),
                        centre,
                        l,
                        ChannelRole::JitterCentre,
                    )
                });
                let minus = channel(
                    format!("{}#jitter-", line.name),
                    centre - h / MHZ_PER_CM1,
                    l,
                    ChannelRole::JitterMinus,
                );
                let plus = channel(
                    format!("{}#jitter+", line.name),
                    centre + h / MHZ_PER_CM1,
                    l,
                    ChannelRole::JitterPlus,
                );
                let a = scale * p * tf(centre);
                let d2 = [
                    (minus, a / (h * h)),
                    (c0, -2.0 * a / (h * h)),
                    (plus, a / (h * h)),
                ];
                let var = laser.frequency_jitter_rms_mhz.powi(2);
                terms.extend(d2.iter().map(|(k, c)| (*k, 0.5 * var * c)));
                slope.push(Combination {
                    name: format!("{}:d_dnu_per_mhz", line.name),
                    terms: vec![(minus, -a / (2.0 * h)), (plus, a / (2.0 * h))],
                });
                curvature.push(Combination {
                    name: format!("{}:d2_dnu2_per_mhz2", line.name),
                    terms: d2.to_vec(),
                });
            }
            mean.push(Combination {
                name: line.name.clone(),
                terms: merge_terms(terms),
            });
        }
        SpectralSampling {
            lines: lines.to_vec(),
            channels,
            mean,
            derivatives: jitter.then_some((slope, curvature)),
        }
    }

    /// Every combination, in the order [`Self::split`] expects: line means, then (with jitter)
    /// slopes, then curvatures.
    pub fn combinations(&self) -> Vec<Combination> {
        let mut all = self.mean.clone();
        if let Some((s, c)) = &self.derivatives {
            all.extend(s.iter().cloned());
            all.extend(c.iter().cloned());
        }
        all
    }

    /// The pairs of [`Self::combinations`] whose covariance a Monte Carlo run should fold: every
    /// pair of line means (the on/off covariance the retrievals use).
    pub fn covariance_pairs(&self) -> Vec<(usize, usize)> {
        let n = self.lines.len();
        (0..n)
            .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
            .collect()
    }

    /// Line returns from the returns of [`Self::combinations`] (Monte Carlo: combined batch by
    /// batch).
    pub fn split(&self, combined: &Returns) -> LineReturns {
        let n = self.lines.len();
        let pick = |from: usize| combined.channel_subset(&(from..from + n).collect::<Vec<_>>());
        LineReturns {
            mean: pick(0),
            derivatives: self.derivatives.as_ref().map(|_| (pick(n), pick(2 * n))),
        }
    }

    /// Line returns from monochromatic channel returns (analytic: combined bin by bin).
    pub fn combine(&self, channels: &Returns) -> LineReturns {
        self.split(&channels.combine(&self.combinations()))
    }
}

/// Sum the coefficients of repeated channels.
fn merge_terms(terms: Vec<(usize, f64)>) -> Vec<(usize, f64)> {
    let mut out: Vec<(usize, f64)> = Vec::new();
    for (k, c) in terms {
        match out.iter_mut().find(|t| t.0 == k) {
            Some(t) => t.1 += c,
            None => out.push((k, c)),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines() -> Vec<Line> {
        vec![
            Line {
                name: "on".into(),
                wavenumber_cm1: 6360.0,
            },
            Line {
                name: "off".into(),
                wavenumber_cm1: 6360.6,
            },
        ]
    }

    #[test]
    fn ideal_laser_is_one_channel_per_line() {
        let l = lines();
        let s = SpectralSampling::new(&Laser::ideal(0.01, 2), &l, &Filter::none());
        assert_eq!(s, SpectralSampling::identity(&l));
    }

    #[test]
    fn weights_carry_purity_filter_and_energy() {
        // p = 0.9; the impurity of `on` passes the filter, that of `off` does not; off has
        // twice the energy; the stencil adds ½σ²C to each mean.
        let mut laser = Laser::ideal(0.01, 2);
        laser.pulse_energy_j[1] = 0.02;
        laser.spectral_purity = 0.9;
        laser.impurity_wavenumber_cm1 = vec![6360.01, 6362.0];
        laser.frequency_jitter_rms_mhz = 1.0;
        let filter = Filter {
            bandwidth_cm1: 0.1,
            transmission: 0.5,
        };
        let s = SpectralSampling::new(&laser, &lines(), &filter);
        // on: centre, impurity, jitter −, jitter +; off: the same four.
        assert_eq!(s.channels.len(), 8);
        // With a constant return P = 1 in every channel the line return is E/E0 · T_f · (p + (1−p) pass).
        let sum = |c: &Combination| c.terms.iter().map(|t| t.1).sum::<f64>();
        assert!((sum(&s.mean[0]) - 0.5).abs() < 1e-15);
        assert!((sum(&s.mean[1]) - 2.0 * 0.5 * 0.9).abs() < 1e-15);
        // Derivatives vanish on a constant and are exact on a parabola P = a + bν + cν².
        let (slope, curv) = s.derivatives.as_ref().unwrap();
        let h = laser.jitter_step_mhz();
        let on = &s.channels;
        let x = |k: usize| (on[k].wavenumber_cm1 - 6360.0) * MHZ_PER_CM1;
        let parabola = |k: usize| 3.0 + 0.2 * x(k) - 0.05 * x(k) * x(k);
        let apply = |c: &Combination| c.terms.iter().map(|(k, w)| w * parabola(*k)).sum::<f64>();
        assert!((apply(&slope[0]) - 0.5 * 0.9 * 0.2).abs() < 1e-9, "h {h}");
        assert!((apply(&curv[0]) - 0.5 * 0.9 * -0.1).abs() < 1e-9);
        assert!(sum(&slope[1]).abs() < 1e-15 && sum(&curv[1]).abs() < 1e-12);
    }
}
