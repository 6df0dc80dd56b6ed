//! Tracing one shard of a run and writing its file.

use super::*;

/// Write batch `t` as one record.
fn write_record(w: &mut impl Write, t: &BatchTally) -> io::Result<()> {
    // Destructured in full so that a new counter cannot be left out of the format silently.
    let RunStats {
        photons,
        collisions,
        surface_reflections,
        local_estimates,
        roulette_kills,
        cut,
        escaped,
        zero_weight,
        splits,
    } = t.stats;
    let counters: [u64; N_COUNTERS] = [
        photons,
        collisions,
        surface_reflections,
        local_estimates,
        roulette_kills,
        cut,
        escaped,
        zero_weight,
        splits,
    ];
    w.write_all(&(t.index as u64).to_le_bytes())?;
    for c in counters {
        w.write_all(&c.to_le_bytes())?;
    }
    for part in [
        &t.bins,
        &t.flux.up,
        &t.flux.down,
        &t.flux.absorbed,
        &t.flux.cut,
    ] {
        for v in part {
            w.write_all(&v.to_le_bytes())?;
        }
    }
    Ok(())
}

/// Run shard `spec` of `scene` (its settings: `scene.simulation`) and write it as `out_dir/`[`ShardSpec::file_name`]
/// (whole or not at all).
///
/// The shard runs [`pipeline::prepare`], so that everything checked before the Monte Carlo in a
/// single run (the optics, the analytic returns, the retrieval's set-up and its analytic
/// products, the Monte Carlo's work) is checked here too: a scene a merge would refuse is
/// refused before any photon is traced. It then traces the shard's batches of the plan on
/// `scene.simulation.threads` threads and writes them; [`Prepared::finish`](pipeline::Prepared::finish)
/// is the merge's.
pub fn run(scene: &Scene, spec: ShardSpec, out_dir: &Path) -> Result<ShardReport, ShardError> {
    if scene.simulation.photons == 0 {
        return Err(ShardError::Spec {
            spec,
            what: "a shard needs photons (0 photons runs the analytic lidar equation only)".into(),
        });
    }
    let path = out_dir.join(spec.file_name());
    output::check_paths(&[&path])?;
    let prepared = pipeline::prepare(scene)?;
    if let Some(note) = prepared.warning() {
        crate::limits::warn(&note);
    }
    match prepared.plan()? {
        Some(plan) => write_shard(scene, prepared.layout(), &plan, spec, &path),
        None => Err(ShardError::Spec {
            spec,
            what: format!(
                "the scene runs no Monte Carlo ({})",
                prepared.decision().reason
            ),
        }),
    }
}

/// Trace the batches of `spec` from `plan` and write the shard file.
fn write_shard(
    scene: &Scene,
    layout: &TallyLayout,
    plan: &transport::Plan,
    spec: ShardSpec,
    path: &Path,
) -> Result<ShardReport, ShardError> {
    let total = plan.batches();
    if spec.count > total {
        return Err(ShardError::Spec {
            spec,
            what: format!(
                "{} shards of a run of {total} batches leave some without a batch (at most one shard per batch; `simulation.batches` sets the batches)",
                spec.count
            ),
        });
    }
    let range = spec.batches(total);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(scene.simulation.threads)
        .build()
        .map_err(|e| {
            RunError::Transport(TransportError::Threads(
                scene.simulation.threads,
                e.to_string(),
            ))
        })?;
    let threads = pool.current_num_threads();
    let started = Instant::now();
    // The first batch alone: its buffers give the header's sizes and the chunk size.
    let first = plan.trace_batch(range.start);
    let header = ShardHeader {
        kind: KIND_RUN.to_string(),
        lidarsim_version: VERSION.to_string(),
        scene_path: scene.path.to_string_lossy().into_owned(),
        scene_text: scene.text().to_string(),
        scene_digest: run_scene_digest(scene),
        seed: scene.simulation.seed,
        photons: scene.simulation.photons,
        batches: total as u64,
        photons_per_batch: plan.photons_per_batch(),
        shard_index: spec.index as u64,
        shard_count: spec.count as u64,
        first_batch: range.start as u64,
        end_batch: range.end as u64,
        max_order: scene.simulation.max_order,
        ddis_epsilon_bits: scene.simulation.variance_reduction.ddis_epsilon.to_bits(),
        range_stratification_bits: scene
            .simulation
            .variance_reduction
            .range_stratification
            .to_bits(),
        flux_tally: layout.flux,
        bins_per_batch: first.bins.len() as u64,
        channels: first.flux.up.len() as u64,
    };
    let json = serde_json::to_vec(&header).map_err(|e| ShardError::Bad {
        path: path.to_path_buf(),
        what: format!("cannot encode the header: {e}"),
    })?;
    // A few batch buffers per thread at a time, within the memory limit; the size does not
    // change the bytes.
    let chunk = (4 * threads)
        .min(crate::limits::MAX_LIVE_TALLY_VALUES / first.bins.len().max(1))
        .max(1);
    let mut wall_s = 0.0;
    let mut set = OutputSet::new();
    set.write_with(path, |file| {
        let mut w = FrameWriter::start(BufWriter::new(file), &json)?;
        write_record(&mut w, &first)?;
        let mut start = range.start + 1;
        while start < range.end {
            let end = (start + chunk).min(range.end);
            let tallies: Vec<BatchTally> = pool.install(|| {
                (start..end)
                    .into_par_iter()
                    .map(|b| plan.trace_batch(b))
                    .collect()
            });
            for t in &tallies {
                write_record(&mut w, t)?;
            }
            start = end;
        }
        wall_s = started.elapsed().as_secs_f64();
        w.write_all(&wall_s.to_le_bytes())?;
        w.write_all(&(threads as u64).to_le_bytes())?;
        w.finish()
    })?;
    set.commit()?;
    Ok(ShardReport {
        path: path.to_path_buf(),
        batches: range,
        total_batches: total,
        photons_per_batch: plan.photons_per_batch(),
        wall_s,
        threads,
    })
}
