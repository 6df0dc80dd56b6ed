//! The validator itself: a description's checks are its methods, in `validate*.rs`, each
//! naming its errors through the scene's [`Source`].

use std::ops::Deref;

use super::source::Source;

/// Checks a description against the rules of a scene; its errors are named by the source.
pub(super) struct Validator<'a> {
    pub src: &'a Source,
}

impl Deref for Validator<'_> {
    type Target = Source;
    fn deref(&self) -> &Source {
        self.src
    }
}
