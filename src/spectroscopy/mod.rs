//! Gas absorption line by line from HITRAN line lists.
//!
//! Consumes line lists (HITRAN .par records or the built-in CO2 band model) and atmospheric
//! [`Profile`](crate::atmosphere::Profile)s; produces monochromatic cross-sections and layer
//! optical depths per channel, in a table that can be saved and loaded.
