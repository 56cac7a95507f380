//! rtloop core: a small physically based ray tracer and a differential-evolution engine for
//! rendering-in-the-loop scene fitting. This crate knows nothing of Python; the optional
//! `python` feature adds a thin PyO3 layer (`rust/python/`).

pub mod error;
pub mod fit;
pub mod fitness;
pub mod geometry;
pub mod params;
pub mod photo;
pub mod render;
pub mod scene;
pub mod search;
pub mod stage;
pub mod uncertainty;

#[cfg(feature = "python")]
mod python;

/// The Python extension allocates through mimalloc, which keeps the memory a fit frees for the next one:
/// glibc's malloc hands a fit's multi-megabyte buffers back to the system and faults them in again, some
/// 1000-2000 page faults per fit (benches/fit_overhead.py, "--fixed-malloc").
#[cfg(feature = "python")]
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

pub use error::{Error, Result};
pub use fitness::{Fitness, FitnessSpec, LossKind, Norm, Projection, Space};
pub use params::ParamLayout;
pub use render::{render, GBuffer, Image};
pub use scene::Scene;
pub use search::{
    DeConfig, DeResult, GenerationReport, Method, Objective, SearchResult, StopReason,
};
pub use stage::{run_stage, StageResult};
