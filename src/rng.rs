//! Random-number streams tied to work, not to threads.
//!
//! Every stream is a Xoshiro256++ generator (Blackman & Vigna 2021). A stream family is chosen
//! by a long jump (2^192 steps) per [`Stream`] from the user's seed, and its i-th unit of work
//! (a Monte Carlo batch) starts i ordinary jumps (2^128 steps each) further on, so units never
//! overlap and a unit gets the same numbers whichever thread runs it (OpenMC's scheme of seeding
//! a particle from its index, with jumps instead of an LCG skip-ahead).

use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// The generator used everywhere.
pub type Rng = Xoshiro256PlusPlus;

/// Independent purposes, so that e.g. instrument noise never shifts transport numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stream {
    /// Photon transport.
    Transport = 0,
    /// Instrument noise.
    Instrument = 1,
    /// Atmospheric ensembles.
    Ensemble = 2,
    /// Ensemble studies: one instrument-noise seed per profile.
    Study = 3,
}

/// Generators for work units `0..count` of a stream: unit i is the stream start jumped i times.
pub fn streams(seed: u64, stream: Stream, count: usize) -> Vec<Rng> {
    let mut base = Rng::seed_from_u64(seed);
    for _ in 0..=(stream as u32) {
        base.long_jump();
    }
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        out.push(base.clone());
        base.jump();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::RngExt;

    #[test]
    fn units_and_streams_differ_and_repeat() {
        let a = streams(7, Stream::Transport, 3);
        let b = streams(7, Stream::Transport, 3);
        let c = streams(7, Stream::Instrument, 1);
        let first = |r: &Rng| r.clone().random::<u64>();
        assert_eq!(first(&a[2]), first(&b[2]));
        assert_ne!(first(&a[0]), first(&a[1]));
        assert_ne!(first(&a[0]), first(&c[0]));
    }
}
