//! Studies built on the pipeline stages: line selection for CO2 IPDA (`select-lines`).

pub mod select;
