//! One profile of a study: its truths measured, its reference states, its retrievals and
//! records.

use super::*;

/// Line returns and signals of one truth.
struct Measured {
    scene: Scene,
    lines: LineReturns,
    signals: Signals,
}

impl Study<'_> {
    /// The reference state of `profile` on `edges` (cut to the profile's top), as the
    /// retrieval assumes the scene's instrument.
    pub(super) fn reference(
        &self,
        profile: &Profile,
        edges: &[f64],
    ) -> Result<ReferenceState, String> {
        self.reference_as(profile, edges, true, &mut LayerDepthMemo::new())
    }

    /// The reference state with the retrieval's own spectroscopy (`assumed`) or the truth's,
    /// with the line-by-line work of the profile's `memo`.
    fn reference_as(
        &self,
        profile: &Profile,
        edges: &[f64],
        assumed: bool,
        memo: &mut LayerDepthMemo,
    ) -> Result<ReferenceState, String> {
        let gas = self.scene.gas.as_ref().ok_or("no gas absorption")?;
        let (lines, options) = if assumed {
            self.config.assumed(&gas.lines, &gas.options)
        } else {
            (&*gas.lines, gas.options)
        };
        ReferenceState::new_with(
            profile,
            &fit_edges(edges, profile),
            &self.config.gas,
            lines,
            &options,
            AssumedInstrument {
                laser: &self.scene.laser,
                lines: &self.scene.sampling.lines,
                filter: &self.filter,
            },
            memo,
        )
        .map_err(|e| e.to_string())
    }

    /// The expected returns and signals of the truths `scenes` (the scene's laser and its
    /// perturbations on one profile; `None` where a perturbation does not apply), in order.
    /// With photons each is traced from the profile's `seed` (every truth of one profile on the
    /// same photons). Analytic: one optical atmosphere and one lidar equation for the channels
    /// of all of them, each channel once (a channel's analytic return depends on its wavenumber
    /// and its line alone), each truth's channels picked from them.
    fn measure_all(
        &self,
        scenes: Vec<Option<Scene>>,
        seed: u64,
        memo: &mut LayerDepthMemo,
    ) -> Result<Vec<Option<Measured>>, String> {
        let scenes: Vec<Option<Scene>> = scenes
            .into_iter()
            .map(|s| {
                s.map(|mut s| {
                    s.simulation.photons = self.options.photons;
                    s.simulation.seed = seed;
                    s
                })
            })
            .collect();
        if self.options.photons > 0 {
            return scenes
                .into_iter()
                .map(|s| s.map(|s| self.trace(s, memo)).transpose())
                .collect();
        }
        let Some(first) = scenes.iter().flatten().next() else {
            return Ok(scenes.into_iter().map(|_| None).collect());
        };
        let same = |a: &SampledChannel, b: &SampledChannel| {
            a.line == b.line && a.wavenumber_cm1.to_bits() == b.wavenumber_cm1.to_bits()
        };
        let mut all = first.sampling.channels.clone();
        let mut extra = Vec::new();
        for c in scenes.iter().flatten().flat_map(|s| &s.sampling.channels) {
            if !all.iter().any(|a| same(a, c)) {
                all.push(c.clone());
                extra.push(c.clone());
            }
        }
        let union = first
            .with_extra_channels(&extra)
            .ok_or("a truth samples a line the scene does not have")?;
        let optics = Clock::time(&self.clock.truth_optics, || {
            OpticalAtmosphere::build_with(&union, memo).map_err(|e| e.to_string())
        })?;
        let analytic = Clock::time(&self.clock.returns, || {
            lidar_eq::single_scatter(&union, &optics)
        });
        scenes
            .into_iter()
            .map(|s| {
                s.map(|s| {
                    Clock::time(&self.clock.returns, || {
                        let index: Vec<usize> = s
                            .sampling
                            .channels
                            .iter()
                            .map(|c| all.iter().position(|a| same(a, c)))
                            .collect::<Option<_>>()
                            .ok_or("a truth's channel is not among the channels computed")?;
                        let channels = analytic.channel_subset(&index);
                        let lines = s.sampling.combine(&channels);
                        with_signals(s, lines, Order::Exactly(1))
                    })
                })
                .transpose()
            })
            .collect()
    }

    /// The Monte Carlo returns and signals of one truth `scene` (its photons and seed set).
    fn trace(&self, scene: Scene, memo: &mut LayerDepthMemo) -> Result<Measured, String> {
        let optics = Clock::time(&self.clock.truth_optics, || {
            OpticalAtmosphere::build_with(&scene, memo).map_err(|e| e.to_string())
        })?;
        Clock::time(&self.clock.returns, || {
            let (_, lines) = Clock::time(&self.clock.transport, || {
                pipeline::trace_lines(&scene, &optics).map_err(|e| e.to_string())
            })?;
            with_signals(scene, lines.ok_or("no combined returns")?, Order::Total)
        })
    }

    /// The retrieval set-up of the truth `m` with `reference`: its paths through the reference
    /// state, computed once for every pair ([`Retrieval::set_pair`]) and every truth of the
    /// profile ([`Self::retrieve`]).
    fn retrieval(
        &self,
        m: &Measured,
        reference: ReferenceState,
        truth: &LayerColumns,
        seed: u64,
    ) -> Result<Retrieval, String> {
        Clock::time(&self.clock.retrievals, || {
            let mut config = self.config.clone();
            config.realisations = 1;
            (config.on, config.off) = self.options.pairs[0];
            pipeline::retrieval_of(&m.scene, config, reference, truth.clone(), seed)
                .map_err(|e| e.to_string())
        })
    }

    /// The products of every pair retrieved from `m` with the set-up `r` of a truth of the same
    /// profile. The truths differ only in their laser, which is all of the scene a set-up reads
    /// after it is made (its pulse energies and the measurement's imperfections): `m`'s
    /// replaces it.
    fn retrieve(&self, r: &mut Retrieval, m: &Measured) -> Result<Vec<Vec<Product>>, String> {
        Clock::time(&self.clock.retrievals, || {
            r.laser.clone_from(&m.scene.laser);
            let name = |(on, off): (usize, usize)| pipeline::pair_name(&m.scene, on, off);
            let mut out = Vec::with_capacity(self.options.pairs.len());
            for &(on, off) in &self.options.pairs {
                r.set_pair(on, off, name((on, off)))
                    .map_err(|e| e.to_string())?;
                out.push(
                    r.retrieve(&m.lines, &m.signals, self.options.fov)
                        .map_err(|e| e.to_string())?,
                );
            }
            Ok(out)
        })
    }

    /// The scene with `member` as its truth, or why it cannot be run: it does not fit the scene
    /// ([`Scene::with_profile`]) or is supersaturated.
    pub(super) fn usable(&self, member: &SetMember) -> Result<Scene, String> {
        usable_in(self.scene, member)
    }

    /// Every record of one profile, `scene` its truth ([`Self::usable`]).
    pub(super) fn profile(
        &self,
        member: &SetMember,
        scene: Scene,
        seed: u64,
    ) -> Result<Vec<Record>, String> {
        let profile = scene
            .atmosphere
            .as_ref()
            .map(|a| a.profile.clone())
            .ok_or("no atmosphere")?;
        let mean = self
            .means
            .iter()
            .find(|(c, _)| *c == member.meta.class())
            .map(|(_, r)| r)
            .ok_or("no mean profile of its class")?;
        let edges = scene.molecular_edges().ok_or("no molecular grid")?;
        // The profile's line-by-line work, shared by its truths and reference states.
        let mut memo = LayerDepthMemo::new();
        let layers = memo
            .layers(&profile, &edges, &[&self.config.gas])
            .map_err(|e| crate::retrieval::RetrievalError::from(e).to_string())?;
        let truth = LayerColumns::of_layers(&profile, &edges, &layers, &self.config.gas)
            .map_err(|e| e.to_string())?;
        let truth_member = SetMember {
            meta: member.meta.clone(),
            profile,
        };
        let steps = &self.options.steps;
        // References: the truth's own, re-levelled, and one per knowledge error.
        let (own, exact, knowledge) = Clock::time(&self.clock.references, || {
            let own = self.reference_as(&truth_member.profile, &edges, true, &mut memo)?;
            // The truth's spectroscopy, where the retrieval assumes another.
            let exact = match &self.config.spectroscopy {
                Some(_) => {
                    Some(self.reference_as(&truth_member.profile, &edges, false, &mut memo)?)
                }
                None => None,
            };
            let mut shifted = |s: StateShift| -> Result<ReferenceState, String> {
                let p = shift_member(&truth_member, &s).map_err(|e| e.to_string())?;
                check_dry_air(&p.profile, s.h2o_factor)?;
                self.reference_as(&p.profile, &edges, true, &mut memo)
            };
            let none = StateShift::NONE;
            let knowledge = [
                shifted(none)?,
                shifted(StateShift {
                    temperature_k: -steps.temperature_k,
                    ..none
                })?,
                shifted(StateShift {
                    h2o_factor: 1.0 / (1.0 + steps.humidity_fraction),
                    ..none
                })?,
                shifted(StateShift {
                    surface_pressure_hpa: steps.surface_pressure_hpa,
                    ..none
                })?,
            ];
            Ok::<_, String>((own, exact, knowledge))
        })?;
        // Truths: the scene's laser, and one per laser perturbation (None: the row is 0).
        let laser = &scene.laser;
        let mut offset = laser.clone();
        for &(on, _) in &self.options.pairs {
            offset.frequency_offset_mhz[on] += steps.frequency_offset_mhz;
        }
        let no_jitter = (laser.frequency_jitter_rms_mhz > 0.0).then(|| Laser {
            frequency_jitter_rms_mhz: 0.0,
            ..laser.clone()
        });
        let wider = widened(&laser.line_shape, 1.0 + steps.linewidth_fraction).map(|s| Laser {
            line_shape: s,
            ..laser.clone()
        });
        let pure = (laser.spectral_purity < 1.0).then(|| Laser {
            spectral_purity: 1.0,
            ..laser.clone()
        });
        let variant = |l: Option<Laser>| -> Result<Option<Scene>, String> {
            l.map(|l| scene.with_laser(l).map_err(|e| e.to_string()))
                .transpose()
        };
        let variants = [
            variant(Some(offset))?,
            variant(no_jitter)?,
            variant(wider)?,
            variant(pure)?,
        ];
        let mut measured = self
            .measure_all(
                std::iter::once(Some(scene)).chain(variants).collect(),
                seed,
                &mut memo,
            )?
            .into_iter();
        let base = measured.next().flatten().ok_or("no truth measured")?;
        let lasers: Vec<Option<Measured>> = measured.collect();
        let one = |reference: ReferenceState| -> Result<Vec<Vec<Product>>, String> {
            self.retrieve(&mut self.retrieval(&base, reference, &truth, seed)?, &base)
        };
        let paper = one(mean.clone())?;
        let mut own_r = self.retrieval(&base, own, &truth, seed)?;
        let own_p = self.retrieve(&mut own_r, &base)?;
        let exact_p = exact.map(one).transpose()?;
        let know: Vec<Vec<Vec<Product>>> =
            knowledge.into_iter().map(one).collect::<Result<_, _>>()?;
        let mut las: Vec<Option<Vec<Vec<Product>>>> = Vec::with_capacity(lasers.len());
        for m in &lasers {
            las.push(
                m.as_ref()
                    .map(|m| self.retrieve(&mut own_r, m))
                    .transpose()?,
            );
        }
        let mut records: Vec<Record> = Vec::new();
        for p in 0..self.options.pairs.len() {
            let know_p: Vec<Vec<Product>> = know.iter().map(|k| k[p].clone()).collect();
            let las_p: Vec<Option<Vec<Product>>> = las
                .iter()
                .map(|l| l.as_ref().map(|l| l[p].clone()))
                .collect();
            let exact = exact_p.as_ref().map(|e| e[p].as_slice());
            records.extend(pair_records(&paper[p], &own_p[p], exact, &know_p, &las_p));
        }
        check_records(&mut records, self.options.photons > 0)?;
        Ok(records)
    }
}

/// Refuse a water-vapour factor that leaves a level of `p` (a state shifted by it) without dry
/// air: the dry-air column, and with it the mixing ratio, would be 0 or negative.
fn check_dry_air(p: &Profile, factor: f64) -> Result<(), String> {
    let Some(h2o) = p.gas("H2O") else {
        return Ok(());
    };
    match h2o.iter().enumerate().find(|(_, x)| !(**x < 1.0)) {
        Some((k, x)) => Err(format!(
            "the humidity budget's assumed state (water vapour × {factor:.4}) has an H2O mole fraction of {x:.3} at {:.0} m, leaving no dry air (give a smaller --budget-humidity-percent below 0)",
            p.altitude_m[k]
        )),
        None => Ok(()),
    }
}

/// Which values of a profile's records must be defined, and what an undefined one is written
/// as: the truth always (it is the profile's own column); the noise-free retrievals and the
/// budget rows when the returns are analytic (`monte_carlo` false: a noise-free lidar
/// equation has energy in every window, so a value that is not finite is a failure, and the
/// profile fails with it named). From Monte Carlo returns, as from one noisy measurement, a
/// window may hold no energy (a few photons, a far cell behind a cloud): the retrieval has no
/// logarithm there, and the value is honestly undefined, set to NaN (an infinity too: a ratio
/// over no energy), written as an empty field and left out of the statistics with its count
/// ([`Summary::retrieved_profiles`], [`Summary::noisy_profiles`]).
fn check_records(records: &mut [Record], monte_carlo: bool) -> Result<(), String> {
    let undefined = |v: &mut f64| {
        if !v.is_finite() {
            *v = f64::NAN;
        }
    };
    for r in records.iter_mut() {
        undefined(&mut r.retrieved_noisy_ppm);
        if monte_carlo {
            undefined(&mut r.retrieved_ppm);
            undefined(&mut r.retrieved_own_ppm);
            r.budget_ppm.iter_mut().for_each(undefined);
        }
        let values = [
            ("truth_ppm", r.truth_ppm),
            ("retrieved_ppm", r.retrieved_ppm),
            ("retrieved_own_profile_ppm", r.retrieved_own_ppm),
        ];
        let budget = Source::ALL
            .iter()
            .zip(&r.budget_ppm)
            .map(|(s, v)| (s.column(), *v));
        let must = |name: &str| !monte_carlo || name == "truth_ppm";
        if let Some((name, v)) = values
            .into_iter()
            .chain(budget)
            .find(|(name, v)| must(name) && !v.is_finite())
        {
            return Err(format!(
                "{name} of {} {} {:.0}–{:.0} m is {v}: it cannot be computed",
                r.pair,
                r.method.label(),
                r.altitude_m.0,
                r.altitude_m.1
            ));
        }
    }
    Ok(())
}

/// Signals of a truth's line returns through its receiver.
fn with_signals(scene: Scene, lines: LineReturns, order: Order) -> Result<Measured, String> {
    if scene.receiver.is_none() {
        return Err("no receiver".into());
    }
    let signals = pipeline::signals_of(&scene, &lines, order).ok_or("no signals of the returns")?;
    Ok(Measured {
        scene,
        lines,
        signals,
    })
}

/// The records of one pair from its products (in [`Retrieval`](crate::retrieval::Retrieval)'s target order: IPDA mixing
/// ratio and slant column, then per DIAL cell density and mixing ratio).
///
/// `exact` holds the products with the own reference in the truth's spectroscopy, where the
/// retrieval assumes another; `know` holds the products with the re-levelled own reference and with each knowledge error
/// (temperature, humidity, surface pressure); `las` those with each laser perturbation
/// (offset, no jitter, wider, pure), None where the perturbation does not apply.
fn pair_records(
    paper: &[Product],
    own: &[Product],
    exact: Option<&[Product]>,
    know: &[Vec<Product>],
    las: &[Option<Vec<Product>>],
) -> Vec<Record> {
    let mut out = Vec::new();
    let mut i = 0;
    while i + 1 < paper.len() {
        // (the column or density product, the mixing-ratio product) of this target.
        let (col, mr) = match paper[i].method {
            Method::Ipda => (i + 1, i),
            _ => (i, i + 1),
        };
        debug_assert_eq!(paper[mr].quantity, Quantity::MixingRatio);
        let truth = paper[mr].truth;
        // Dry-air amount of the truth in the column product's unit: N_dry = N / x.
        let dry = paper[col].truth / (truth * 1e-6);
        let ppm = |v: f64| v / dry * 1e6;
        let d = |a: &[Product], b: &[Product]| a[mr].retrieved - b[mr].retrieved;
        let mut budget = [0.0; N_SOURCES];
        budget[0] = ppm(paper[col].random_error_averaged);
        budget[1] = d(&know[1], &know[0]);
        budget[2] = d(&know[2], &know[0]);
        budget[3] = d(&know[3], &know[0]);
        let laser_row = |k: usize, sign: f64| {
            las[k]
                .as_ref()
                .map_or(0.0, |p| sign * (p[mr].retrieved - own[mr].retrieved))
        };
        budget[4] = laser_row(0, 1.0);
        budget[5] = laser_row(1, -1.0);
        budget[6] = laser_row(2, 1.0);
        budget[7] = laser_row(3, -1.0);
        let retrieved = ppm(paper[col].retrieved);
        budget[8] = retrieved - ppm(own[col].retrieved);
        budget[9] = exact.map_or(0.0, |e| own[mr].retrieved - e[mr].retrieved);
        out.push(Record {
            pair: paper[mr].channel_pair.clone(),
            method: paper[mr].method,
            altitude_m: paper[mr].altitude_m,
            truth_ppm: truth,
            retrieved_ppm: retrieved,
            retrieved_noisy_ppm: ppm(paper[col].simulated_first_averaged),
            retrieved_own_ppm: own[mr].retrieved,
            budget_ppm: budget,
        });
        i += 2;
    }
    out
}

/// `edges` cut to the top of `profile` (a profile re-levelled colder ends a little lower).
fn fit_edges(edges: &[f64], profile: &Profile) -> Vec<f64> {
    let top = profile.altitude_m[profile.len() - 1].min(edges[edges.len() - 1]);
    let mut out: Vec<f64> = edges.iter().copied().filter(|z| *z < top).collect();
    out.push(top);
    out
}

/// The line shape `factor` times wider, if it has a width to scale.
fn widened(shape: &LineShape, factor: f64) -> Option<LineShape> {
    match shape {
        LineShape::Gaussian { fwhm_mhz } => Some(LineShape::Gaussian {
            fwhm_mhz: fwhm_mhz * factor,
        }),
        LineShape::Lorentzian { fwhm_mhz } => Some(LineShape::Lorentzian {
            fwhm_mhz: fwhm_mhz * factor,
        }),
        LineShape::Monochromatic | LineShape::Table(_) => None,
    }
}

/// A profile supersaturated over liquid water (beyond [`MAX_RELATIVE_HUMIDITY`]) is refused.
/// `scene` with `member` as its truth, or why it cannot be run: it does not fit the scene
/// ([`Scene::with_profile`]) or is supersaturated.
pub(super) fn usable_in(scene: &Scene, member: &SetMember) -> Result<Scene, String> {
    let scene = scene
        .with_profile(member.profile.clone())
        .map_err(|e| e.to_string())?;
    match &scene.atmosphere {
        Some(a) => check_saturation(&a.profile)?,
        None => return Err("no atmosphere".into()),
    }
    Ok(scene)
}

fn check_saturation(p: &Profile) -> Result<(), String> {
    let Some(h2o) = p.gas("H2O") else {
        return Ok(());
    };
    for k in 0..p.len() {
        let e = h2o[k] * p.pressure_pa[k];
        let e_s = saturation_vapour_pressure_pa(p.temperature_k[k], SaturationOver::Water);
        if e > MAX_RELATIVE_HUMIDITY * e_s {
            return Err(format!(
                "supersaturated: relative humidity {:.1} % at {:.0} m ({:.1} hPa, {:.1} K)",
                100.0 * e / e_s,
                p.altitude_m[k],
                p.pressure_pa[k] / 100.0,
                p.temperature_k[k]
            ));
        }
    }
    Ok(())
}
