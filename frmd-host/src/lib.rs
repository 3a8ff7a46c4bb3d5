//! FRMD host side: float models and training (candle), built-in tasks, datasets, closed-loop
//! evaluation, the bit-accuracy harness, benchmarks and the `frmd` CLI.
pub mod checkpoint;
pub mod cli;
pub mod data;
pub mod diffusion;
pub mod equiv;
pub mod bench;
pub mod eval;
pub mod models;
pub mod policy;
pub mod prodmp_vectors;
pub mod rng;
pub mod serve;
pub mod tasks;
pub mod train;
