//! The one digest of the crate: FNV-1a, 64 bit (Fowler, Noll and Vo; draft-eastlake-fnv).
//!
//! It names things, it does not protect them: the keys of the Mie and gas optical-depth
//! caches, the fingerprints of line lists and profiles, the scene digest and the checksum of
//! shard files. It is stable across machines and Rust versions (std's `DefaultHasher` is not),
//! and a change of any single byte changes it (each step is a bijection of the state). It is
//! not a cryptographic hash: anyone can make two inputs collide on purpose.

use std::fmt;

/// FNV-1a 64-bit hash state.
#[derive(Debug, Clone, Copy)]
pub struct Fnv(pub(crate) u64);

impl Default for Fnv {
    fn default() -> Self {
        Self::new()
    }
}

impl Fnv {
    /// A fresh hash (the FNV-1a 64 offset basis).
    pub fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }

    /// Hash bytes.
    pub fn update(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 = (self.0 ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    /// Hash the bit pattern of an f64 (little-endian bytes).
    pub fn f64(&mut self, v: f64) {
        self.update(&v.to_bits().to_le_bytes());
    }

    /// The hash value.
    pub fn finish(&self) -> u64 {
        self.0
    }
}

/// Writing text into the hash hashes its UTF-8 bytes (for `write!(h, "{value:?}")`).
impl fmt::Write for Fnv {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        self.update(s.as_bytes());
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fmt::Write;

    /// FNV-1a 64 test vectors (Fowler, Noll and Vo; draft-eastlake-fnv).
    #[test]
    fn fnv_matches_its_published_vectors() {
        for (text, want) in [
            ("", 0xcbf2_9ce4_8422_2325u64),
            ("a", 0xaf63_dc4c_8601_ec8c),
            ("foobar", 0x8594_4171_f739_67e8),
        ] {
            let mut h = Fnv::new();
            h.update(text.as_bytes());
            assert_eq!(h.finish(), want, "{text:?}");
            let mut w = Fnv::new();
            write!(w, "{text}").unwrap();
            assert_eq!(w.finish(), want, "{text:?} written");
        }
    }

    /// An f64 hashes as its eight little-endian bytes.
    #[test]
    fn an_f64_hashes_as_its_bytes() {
        let v = -1.25e-7_f64;
        let mut a = Fnv::new();
        a.f64(v);
        let mut b = Fnv::new();
        b.update(&v.to_bits().to_le_bytes());
        assert_eq!(a.finish(), b.finish());
    }
}
