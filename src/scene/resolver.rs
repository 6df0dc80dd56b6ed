//! The resolver itself: the reading and building of a validated description are its methods,
//! in `resolve*.rs` and `reuse.rs`.

use std::ops::Deref;
use std::path::Path;

use super::source::Source;

/// Resolves a validated description; relative paths are anchored at `base_dir`.
pub(super) struct Resolver<'a> {
    pub src: &'a Source,
    pub base_dir: &'a Path,
}

impl<'a> Deref for Resolver<'a> {
    type Target = Source;
    fn deref(&self) -> &Source {
        self.src
    }
}
