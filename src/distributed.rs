//! One run spread over MPI ranks (feature `mpi`): `mpirun -np K lidarsim run SCENE --out DIR`.
//!
//! Consumes a resolved [`Scene`] (its settings in `scene.simulation`), read alike by every rank;
//! produces on rank 0 the [`RunOutput`] a single process would produce, and nothing elsewhere.
//!
//! Every rank prepares the same run ([`pipeline::prepare`]) and builds the same transport plan
//! ([`pipeline::Prepared::plan`]); rank 0 alone finishes it ([`pipeline::Prepared::finish`]). Batches are assigned
//! statically, **round robin**: batch b is traced by rank b mod K. Each rank then gets an equal
//! share whatever the batch count, and batches reach rank 0 nearly in order, so that it folds
//! them as they come: rank 0 goes through the batches in chunks, traces its own batches of a
//! chunk on its threads, then receives the others' of that chunk in batch order and folds all,
//! holding at most one chunk of its own tallies and one received batch. The other ranks trace
//! their batches in groups on their threads and send each [`BatchTally`] as raw buffers (its
//! index and counters as `u64`, its bins and flux as `f64`): exact bits, so the fold, and every
//! file written from it, equals a single process's with the same scene and seed. Only rank 0
//! gets the output; the caller writes files there alone.
//!
//! Errors end the whole job, never leave a rank waiting. Before any batch is traced the ranks
//! agree, in one all-gather, on whether each set-up (optics, plan, worker threads) succeeded and
//! on the plan each built (batches, photons per batch, tally size, channels, seed). If any rank
//! failed or built another plan, every rank stops: rank 0 reports the failures (each distinct
//! message once, naming its rank) and the others end quietly ([`Outcome::Stopped`]). Past that
//! point nothing depends on input; a failure during the exchange (a panic, a malformed
//! message) prints its message and aborts every rank (`MPI_Abort`).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::Instant;

use mpi::Threading;
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::{CommunicatorCollectives, Destination, Source};
use rayon::prelude::*;
use thiserror::Error;

use crate::pipeline::{self, RunError, RunOutput};
use crate::scene::Scene;
use crate::transport::{BatchTally, Flux, McResult, Plan, RunStats, TransportError};

/// Exit status of a rank aborted by a failure during the exchange (input problems are refused
/// before it, with the command line's usual status 2).
const ABORT_STATUS: i32 = 2;

/// What a rank ends with.
#[derive(Debug)]
#[allow(clippy::large_enum_variant)] // one value per process
pub enum Outcome {
    /// Rank 0: the run, to be written out as a single process would.
    Root(RunOutput),
    /// Another rank: its batches are folded into rank 0's output; nothing to write.
    Worker,
    /// Another rank of a run that failed before the exchange; rank 0 reports why. The process
    /// should end quietly with status 0: rank 0 ends with the error status, which `mpirun`
    /// returns, and a rank ending with an error first makes `mpirun` kill rank 0, perhaps before
    /// its message is out.
    Stopped,
}

/// Why a distributed run failed (reported on rank 0).
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum DistributedError {
    /// MPI was already initialised (or finalised) in this process.
    #[error("MPI cannot be initialised: it already was in this process")]
    Init,
    /// The run failed on rank 0 (the message a single process would give).
    #[error(transparent)]
    Run(#[from] RunError),
    /// Ranks failed or disagreed before the exchange: every distinct message, with its rank.
    #[error("{0}")]
    Ranks(String),
}

/// Run `scene` on every rank of `mpirun`: rank 0 gets the output ([`Outcome::Root`]), the other
/// ranks trace their share of the batches. A process started without `mpirun` is one rank and
/// does everything. MPI is initialised here and finalised before returning, so it can be used
/// once per process.
pub fn run(scene: &Scene) -> Result<Outcome, DistributedError> {
    // Only the main thread calls MPI; rayon's workers only trace.
    let (universe, _) =
        mpi::initialize_with_threading(Threading::Funneled).ok_or(DistributedError::Init)?;
    let world = universe.world();
    let size = world.size() as usize;
    let outcome = if world.rank() == 0 {
        root(&world, size, scene).map(Outcome::Root)
    } else {
        Ok(worker(&world, world.rank() as usize, size, scene))
    };
    // `universe` is dropped here: MPI_Finalize on every rank, after the last message.
    outcome
}

/// Rank 0: the whole pipeline, with a Monte Carlo that gathers every rank's batches.
fn root(
    world: &SimpleCommunicator,
    size: usize,
    scene: &Scene,
) -> Result<RunOutput, DistributedError> {
    let prepared = match pipeline::prepare(scene) {
        Ok(p) => p,
        Err(e) => return stop_before_exchange(world, e),
    };
    if let Some(note) = prepared.warning() {
        crate::limits::warn(&note);
    }
    let plan = match prepared.plan() {
        Ok(p) => p,
        Err(e) => return stop_before_exchange(world, e),
    };
    let Some(plan) = plan else {
        // No Monte Carlo (0 photons, or none needed: `crate::skip`); the workers decide alike.
        return match agree(world, 0, &Ok(Digest::NONE)) {
            Ok(_) => Ok(prepared.finish(None)?),
            Err(failures) => Err(DistributedError::Ranks(report(&failures))),
        };
    };
    let pool = thread_pool(scene.simulation.threads);
    let mine = match &pool {
        Ok(p) => Ok(Digest::of(
            &plan,
            scene.simulation.seed,
            p.current_num_threads(),
        )),
        Err(e) => Err(e.to_string()),
    };
    let total_threads =
        agree(world, 0, &mine).map_err(|failures| DistributedError::Ranks(report(&failures)))?;
    let Ok(pool) = pool else {
        unreachable_after_agreement(world)
    };
    let mc = match catch_unwind(AssertUnwindSafe(|| {
        gather(world, size, &plan, &pool, total_threads)
    })) {
        Ok(Ok(mc)) => mc,
        Ok(Err(message)) => abort(world, &message),
        Err(_) => abort(world, "a panic on rank 0 (its message is above)"),
    };
    drop(plan);
    Ok(prepared.finish(Some(mc))?)
}

/// Rank 0's pipeline failed before the exchange: agree on it, and report the failure a single
/// process would (every rank failed alike) or every rank's distinct message.
fn stop_before_exchange(
    world: &SimpleCommunicator,
    e: RunError,
) -> Result<RunOutput, DistributedError> {
    match agree(world, 0, &Err(e.to_string())) {
        Err(failures) if failures.iter().all(|(_, m)| *m == e.to_string()) => {
            Err(DistributedError::Run(e))
        }
        Err(failures) => Err(DistributedError::Ranks(report(&failures))),
        // `agree` counts rank 0's own failure.
        Ok(_) => Err(DistributedError::Run(e)),
    }
}

/// Ranks 1…K−1: prepare the same run, agree on its plan, trace this rank's batches and send
/// them.
fn worker(world: &SimpleCommunicator, rank: usize, size: usize, scene: &Scene) -> Outcome {
    let prepared = pipeline::prepare(scene).map_err(|e| e.to_string());
    let plan = prepared
        .as_ref()
        .map_err(Clone::clone)
        .and_then(|p| p.plan().map_err(|e| e.to_string()));
    let plan = match plan {
        // No Monte Carlo (0 photons, or none needed: `crate::skip`), as rank 0 decides.
        Ok(None) => {
            return match agree(world, rank, &Ok(Digest::NONE)) {
                Ok(_) => Outcome::Worker,
                Err(_) => Outcome::Stopped,
            };
        }
        Ok(Some(plan)) => Ok(plan),
        Err(e) => Err(e),
    };
    let pool = thread_pool(scene.simulation.threads).map_err(|e| e.to_string());
    let mine = match (&plan, &pool) {
        (Ok(plan), Ok(pool)) => Ok(Digest::of(
            plan,
            scene.simulation.seed,
            pool.current_num_threads(),
        )),
        (Err(e), _) | (_, Err(e)) => Err(e.clone()),
    };
    if agree(world, rank, &mine).is_err() {
        return Outcome::Stopped;
    }
    let (Ok(plan), Ok(pool)) = (plan, pool) else {
        unreachable_after_agreement(world)
    };
    match catch_unwind(AssertUnwindSafe(|| serve(world, rank, size, &plan, &pool))) {
        Ok(()) => Outcome::Worker,
        Err(_) => abort(
            world,
            &format!("a panic on rank {rank} (its message is above)"),
        ),
    }
}

/// Rank 0's Monte Carlo: its own batches on its threads, the others' received, all folded in
/// batch order.
fn gather(
    world: &SimpleCommunicator,
    size: usize,
    plan: &Plan,
    pool: &rayon::ThreadPool,
    total_threads: usize,
) -> Result<McResult, String> {
    let started = Instant::now();
    let batches = plan.batches();
    let mut fold = plan.fold();
    // Rank 0 traces `own` batches of each chunk at once (a few per thread, within the memory
    // limit, as a single process does); the chunk spans the same count from every rank.
    let own = group_len(plan, pool);
    let chunk = own * size;
    let mut start = 0;
    while start < batches {
        let end = (start + chunk).min(batches);
        let mine: Vec<usize> = (start..end).filter(|b| b % size == 0).collect();
        let traced: Vec<BatchTally> =
            pool.install(|| mine.par_iter().map(|&b| plan.trace_batch(b)).collect());
        let mut traced = traced.into_iter();
        for b in start..end {
            let batch = if b % size == 0 {
                traced
                    .next()
                    .ok_or_else(|| format!("rank 0 lost its batch {b}"))?
            } else {
                receive(world, b % size, b, plan.channels())?
            };
            fold.add(batch).map_err(|e| e.to_string())?;
        }
        start = end;
    }
    fold.finish(started.elapsed().as_secs_f64(), total_threads)
        .map_err(|e| e.to_string())
}

/// Another rank's Monte Carlo: its batches (b mod K = rank), in groups on its threads, each
/// sent to rank 0 in batch order.
fn serve(
    world: &SimpleCommunicator,
    rank: usize,
    size: usize,
    plan: &Plan,
    pool: &rayon::ThreadPool,
) {
    let mine: Vec<usize> = (rank..plan.batches()).step_by(size).collect();
    let root = world.process_at_rank(0);
    for group in mine.chunks(group_len(plan, pool)) {
        let traced: Vec<BatchTally> =
            pool.install(|| group.par_iter().map(|&b| plan.trace_batch(b)).collect());
        for t in &traced {
            let s = &t.stats;
            let head: [u64; HEAD_LEN] = [
                t.index as u64,
                s.photons,
                s.collisions,
                s.surface_reflections,
                s.local_estimates,
                s.roulette_kills,
                s.cut,
                s.escaped,
                s.zero_weight,
                s.splits,
            ];
            root.send(&head[..]);
            root.send(&t.bins[..]);
            let flux: Vec<f64> = t.flux.parts().into_iter().flatten().copied().collect();
            root.send(&flux[..]);
        }
    }
}

/// Values of a batch's header: its index and the nine counters of [`RunStats`].
const HEAD_LEN: usize = 10;

/// Receive batch `expected` from rank `from` (the three messages [`serve`] sends).
fn receive(
    world: &SimpleCommunicator,
    from: usize,
    expected: usize,
    channels: usize,
) -> Result<BatchTally, String> {
    let p = world.process_at_rank(from as i32);
    let (head, _) = p.receive_vec::<u64>();
    let (bins, _) = p.receive_vec::<f64>();
    let (flux, _) = p.receive_vec::<f64>();
    if head.len() != HEAD_LEN || head[0] != expected as u64 || flux.len() != 4 * channels {
        return Err(format!(
            "rank {from} sent a malformed batch (header {head:?}, {} flux values) where batch \
             {expected} with {} flux values was expected",
            flux.len(),
            4 * channels
        ));
    }
    let part = |i: usize| flux[i * channels..(i + 1) * channels].to_vec();
    Ok(BatchTally {
        index: expected,
        bins,
        flux: Flux {
            up: part(0),
            down: part(1),
            absorbed: part(2),
            cut: part(3),
        },
        jacobian: Vec::new(),
        stats: RunStats {
            photons: head[1],
            collisions: head[2],
            surface_reflections: head[3],
            local_estimates: head[4],
            roulette_kills: head[5],
            cut: head[6],
            escaped: head[7],
            zero_weight: head[8],
            splits: head[9],
        },
    })
}

/// Batches a rank traces at once: a few per thread, within the memory limit on live tallies
/// (as [`crate::transport::run_plan`] does). The size does not change the numbers.
fn group_len(plan: &Plan, pool: &rayon::ThreadPool) -> usize {
    (4 * pool.current_num_threads())
        .min(crate::limits::MAX_LIVE_TALLY_VALUES / plan.tally_len().max(1))
        .max(1)
}

fn thread_pool(threads: usize) -> Result<rayon::ThreadPool, TransportError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| TransportError::Threads(threads, e.to_string()))
}

/// The plan a rank built: what every rank must agree on, and its worker threads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Digest {
    threads: u64,
    batches: u64,
    photons_per_batch: u64,
    tally_len: u64,
    channels: u64,
    seed: u64,
}

impl Digest {
    /// No Monte Carlo (0 photons).
    const NONE: Digest = Digest {
        threads: 0,
        batches: 0,
        photons_per_batch: 0,
        tally_len: 0,
        channels: 0,
        seed: 0,
    };

    fn of(plan: &Plan, seed: u64, threads: usize) -> Self {
        Digest {
            threads: threads as u64,
            batches: plan.batches() as u64,
            photons_per_batch: plan.photons_per_batch(),
            tally_len: plan.tally_len() as u64,
            channels: plan.channels() as u64,
            seed,
        }
    }

    /// Status (0 built, 1 failed) and the digest, as one all-gathered record.
    fn encode(mine: &Result<Digest, String>) -> [u64; 7] {
        let d = mine.as_ref().copied().unwrap_or(Digest::NONE);
        let failed = u64::from(mine.is_err());
        [
            failed,
            d.threads,
            d.batches,
            d.photons_per_batch,
            d.tally_len,
            d.channels,
            d.seed,
        ]
    }

    /// Everything but the thread count, which may differ between ranks.
    fn plan_part(r: &[u64]) -> &[u64] {
        &r[2..]
    }
}

/// The one collective before the exchange: every rank says whether its set-up succeeded and
/// which plan it built. Returns the total worker threads over the ranks if all built the same
/// plan; else the failures, `(rank, message)` — with the messages on rank 0, which receives
/// each failed rank's text; every rank decides alike, so none waits for another.
fn agree(
    world: &SimpleCommunicator,
    rank: usize,
    mine: &Result<Digest, String>,
) -> Result<usize, Vec<(usize, String)>> {
    let size = world.size() as usize;
    let record = Digest::encode(mine);
    let mut all = vec![0u64; 7 * size];
    world.all_gather_into(&record[..], &mut all[..]);
    let records: Vec<&[u64]> = all.chunks(7).collect();
    let failed: Vec<usize> = (0..size).filter(|&r| records[r][0] != 0).collect();
    // Failed ranks send their messages to rank 0, which alone reports them.
    if let (1.., Err(message)) = (rank, mine) {
        world.process_at_rank(0).send(message.as_bytes());
    }
    let mut failures: Vec<(usize, String)> = Vec::new();
    for &r in &failed {
        let text = match (rank, r, mine) {
            (0, 0, Err(m)) => m.clone(),
            (0, _, _) => {
                let (bytes, _) = world.process_at_rank(r as i32).receive_vec::<u8>();
                String::from_utf8_lossy(&bytes).into_owned()
            }
            _ => String::new(),
        };
        failures.push((r, text));
    }
    if failed.is_empty() {
        let root = records[0];
        for (r, rec) in records.iter().enumerate().skip(1) {
            if Digest::plan_part(rec) != Digest::plan_part(root) {
                failures.push((
                    r,
                    format!(
                        "it planned (batches, photons per batch, tally values, channels, \
                         seed) = {:?} where rank 0 planned {:?}: every rank must run the same \
                         scene and options with the same lidarsim",
                        Digest::plan_part(rec),
                        Digest::plan_part(root)
                    ),
                ));
            }
        }
    }
    if failures.is_empty() {
        Ok(records.iter().map(|r| r[1] as usize).sum())
    } else {
        Err(failures)
    }
}

/// One message for rank 0 to print: the first failure, then every other distinct message with
/// its rank.
fn report(failures: &[(usize, String)]) -> String {
    let mut seen: Vec<&str> = Vec::new();
    let mut out = String::new();
    for (r, m) in failures {
        if seen.contains(&m.as_str()) {
            continue;
        }
        if out.is_empty() {
            out = if *r == 0 {
                m.clone()
            } else {
                format!("on rank {r}: {m}")
            };
        } else {
            out.push_str(&format!("\n  and on rank {r}: {m}"));
        }
        seen.push(m);
    }
    out
}

/// A failure during the exchange: print it and end every rank.
fn abort(world: &SimpleCommunicator, message: &str) -> ! {
    eprintln!(
        "lidarsim: error on rank {} of {}: {message}; aborting every rank",
        world.rank(),
        world.size()
    );
    world.abort(ABORT_STATUS)
}

/// After an agreement every rank's set-up succeeded; should that ever not hold, abort rather than
/// leave rank 0 waiting.
fn unreachable_after_agreement(world: &SimpleCommunicator) -> ! {
    abort(
        world,
        "internal error: set-up failed after the ranks agreed it had not",
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn report_names_each_distinct_failure_once() {
        let f = vec![
            (0, "bad scene".to_string()),
            (1, "bad scene".to_string()),
            (2, "no memory".to_string()),
        ];
        assert_eq!(report(&f), "bad scene\n  and on rank 2: no memory");
        let f = vec![(3, "x".to_string())];
        assert_eq!(report(&f), "on rank 3: x");
    }
}
