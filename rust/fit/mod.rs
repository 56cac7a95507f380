//! A whole fit's search on a scene and a photo, as a plain Rust API: [`run_passes`] builds the fitness
//! ([`crate::FitnessSpec`]), runs the search method, and with interreflection repeats it with the bounce
//! held at the light the previous pass found (`passes.rs`). The Python binding converts its arguments and
//! calls it.

pub mod outlines;
pub mod passes;

pub use passes::{run_passes, PassOptions};
