//! FRMD host side: float models and training (candle), built-in tasks, datasets, closed-loop
//! evaluation, the bit-accuracy harness, benchmarks and the `frmd` CLI.
pub mod cli;
pub mod data;
pub mod eval;
pub mod diffusion;
pub mod models;
pub mod rng;
pub mod train;
pub mod checkpoint;
