//! rtloop core: a small physically based ray tracer and a differential-evolution engine for
//! rendering-in-the-loop scene fitting. This crate knows nothing of Python; the optional
//! `python` feature adds a thin PyO3 layer (`rust/python/`).

pub mod error;
pub mod fitness;
pub mod params;
pub mod photo;
pub mod render;
pub mod scene;
pub mod search;
pub mod stage;
pub mod uncertainty;

#[cfg(feature = "python")]
mod python;

pub use error::{Error, Result};
pub use fitness::{Fitness, LossKind, Norm, Projection, Space};
pub use params::ParamLayout;
pub use render::{render, GBuffer, Image};
pub use scene::Scene;
pub use search::{
    DeConfig, DeResult, GenerationReport, Method, Objective, SearchResult, StopReason,
};
pub use stage::{run_stage, StageResult};
