//! FRMD host side: float models and training (candle), built-in tasks, datasets, closed-loop
//! evaluation, export of students, the bit-accuracy harness, benchmarks, the quick start, and
//! the `frmd` CLI on top ([`cli`] parses arguments and calls the other modules; nothing calls
//! into it).
pub mod bench;
pub mod checkpoint;
pub mod cli;
pub mod data;
pub mod diffusion;
pub mod equiv;
pub mod eval;
pub mod export;
pub mod firmware;
pub mod limits;
pub mod models;
pub mod policy;
pub mod prodmp_vectors;
pub mod progress;
pub mod quickstart;
pub mod rng;
pub mod serve;
pub mod tasks;
pub mod train;
