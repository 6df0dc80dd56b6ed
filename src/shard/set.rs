//! The shards of one run found, opened, checked against each other and folded.

use super::*;

/// The shard files among `inputs`: a directory gives every `*.lshard` file in it, a file is
/// taken as it is.
pub fn shard_paths(inputs: &[PathBuf]) -> Result<Vec<PathBuf>, ShardError> {
    let mut out = Vec::new();
    for p in inputs {
        let meta = fs::metadata(p).map_err(|error| ShardError::Io {
            path: p.clone(),
            error,
        })?;
        if meta.is_dir() {
            let mut found = Vec::new();
            for entry in fs::read_dir(p).map_err(|error| ShardError::Io {
                path: p.clone(),
                error,
            })? {
                let entry = entry.map_err(|error| ShardError::Io {
                    path: p.clone(),
                    error,
                })?;
                let path = entry.path();
                if path.extension().is_some_and(|e| e == EXTENSION) && path.is_file() {
                    found.push(path);
                }
            }
            found.sort();
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    if out.is_empty() {
        return Err(ShardError::NoShards(inputs.to_vec()));
    }
    Ok(out)
}

/// Every shard of one run, checked against each other: same version, scene, seed, photons,
/// batches, shard count and options; each shard exactly once.
#[derive(Debug, Clone)]
pub struct ShardSet {
    /// The shard files in shard order, headers only (the fold reads them again).
    pub shards: Vec<(PathBuf, ShardHeader)>,
}

impl ShardSet {
    /// Read and check the shard files `paths` ([`shard_paths`]). Each file is read whole and
    /// checked here, so that a damaged shard is refused before the optics are built.
    pub fn open(paths: &[PathBuf]) -> Result<ShardSet, ShardError> {
        let shards = whole_set(
            paths,
            |p| {
                let f = ShardFile::read(p)?;
                Ok((f.path, f.header))
            },
            |(a, ha), (b, hb)| check_same(a, ha, b, hb),
        )?;
        Ok(ShardSet { shards })
    }

    fn first(&self) -> &ShardHeader {
        &self.shards[0].1
    }

    /// The scene the shards ran, read again from the text of every shard at their path, with
    /// their photons and seed; refused if its digest is no longer theirs ([`scene_of`]).
    pub fn scene(&self) -> Result<Scene, ShardError> {
        let h = self.first();
        let claims: Vec<SceneClaim> = self
            .shards
            .iter()
            .map(|(file, h)| SceneClaim {
                file,
                path: &h.scene_path,
                text: &h.scene_text,
                digest: &h.scene_digest,
            })
            .collect();
        if h.flux_tally {
            return Err(ShardError::Bad {
                path: self.shards[0].0.clone(),
                what: "its header says the flux leaving the scene was tallied, which no run does"
                    .into(),
            });
        }
        // The scene with the settings the shards ran with (threads aside: they do not change
        // the numbers), as its digest was taken.
        scene_of(
            &claims,
            |s| {
                s.override_simulation(Some(h.photons), Some(h.seed), None)?;
                let sim = &mut s.simulation;
                sim.max_order = h.max_order;
                sim.variance_reduction.ddis_epsilon = f64::from_bits(h.ddis_epsilon_bits);
                sim.variance_reduction.range_stratification =
                    f64::from_bits(h.range_stratification_bits);
                Ok(())
            },
            run_scene_digest,
        )
    }

    /// Fold every shard's batches in batch order into the run's result. Its `wall_s` is the sum
    /// of the shards' transport times, its `threads` the most any shard used. `scene` is the
    /// scene the shards ran ([`ShardSet::scene`]): whether its light is polarised (the returns
    /// tallies are co- and cross-polarised), for the check of their signs, and its lidar, for
    /// the check of the energy received ([`check_folded`]).
    pub fn fold(&self, plan: &transport::Plan, scene: &Scene) -> Result<McResult, ShardError> {
        let polarised = scene.lidar.polarisation != crate::scene::Polarisation::None;
        let h = self.first();
        let (path0, _) = &self.shards[0];
        if plan.batches() as u64 != h.batches || plan.photons_per_batch() != h.photons_per_batch {
            return Err(ShardError::Bad {
                path: path0.clone(),
                what: format!(
                    "{} batches of {} photons, where the scene read now plans {} of {}",
                    h.batches,
                    h.photons_per_batch,
                    plan.batches(),
                    plan.photons_per_batch()
                ),
            });
        }
        let channels = plan.channels().max(1);
        // Returns tallies per channel: co- and cross-polarised ones count apart (channel fastest).
        let tally_channels = if polarised { 2 * channels } else { channels };
        // A batch's raw tallies in joules, as `Plan` scales them: pulse energy × optical
        // efficiency × telescope area per photon of the batch (the tallies are weight ×
        // geometric factor [sr⁻¹ m⁻², per m² of aperture]).
        let lidar = &scene.lidar;
        let joules_per_tally =
            lidar.pulse_energy_j * lidar.optical_efficiency * lidar.telescope_area_m2()
                / h.photons_per_batch.max(1) as f64;
        // Each batch's received energy per channel: every gate, order and field of view (the
        // tally's annuli and exact-order bins do not overlap), co and cross together.
        let mut received = Vec::with_capacity(h.batches as usize * channels);
        let mut fold = plan.fold();
        let (mut wall_s, mut threads) = (0.0, 0usize);
        for (path, header) in &self.shards {
            // Read again (one file in memory at a time); it may have changed since it was
            // checked.
            let f = ShardFile::read(path)?;
            if f.header != *header {
                return Err(ShardError::Bad {
                    path: path.clone(),
                    what: "changed while the merge was running".into(),
                });
            }
            for t in f.batches() {
                check_returns_signs(path, &t, h.channels as usize, polarised)?;
                let mut sums = vec![0.0; channels];
                for (i, v) in t.bins.iter().enumerate() {
                    sums[(i % tally_channels) % channels] += v;
                }
                received.extend(sums.iter().map(|v| v * joules_per_tally));
                fold.add(t).map_err(|e| ShardError::Bad {
                    path: path.clone(),
                    what: e.to_string(),
                })?;
            }
            wall_s += f.wall_s;
            threads = threads.max(f.threads as usize);
        }
        let result = fold.finish(wall_s, threads).map_err(|e| ShardError::Bad {
            path: path0.clone(),
            what: e.to_string(),
        })?;
        let limit_j = lidar.pulse_energy_j * lidar.optical_efficiency;
        check_folded(self, &result, &received, channels, limit_j)?;
        Ok(result)
    }

    /// The shard file that holds batch `batch`.
    pub(super) fn file_of_batch(&self, batch: usize) -> &Path {
        let h = self.first();
        let i = ShardSpec::of_batch(batch, h.shard_count as usize, h.batches as usize);
        self.shards
            .get(i)
            .map(|(p, _)| p.as_path())
            .unwrap_or(&self.shards[0].0)
    }
}
