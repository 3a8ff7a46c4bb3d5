//! FRMD host side: float models and training (candle), built-in tasks, datasets, closed-loop
//! evaluation, export of students, the bit-accuracy harness, benchmarks, the quick start, and
//! the `frmd` CLI on top ([`cli`] parses arguments and calls the other modules; nothing calls
//! into it).
//!
//! What a program calls, one module per `frmd` command:
//! [`train`] (teacher, student, DP baseline), [`export`](mod@export) (a student into an int8 blob and baked
//! module, through `frmd_export`), [`eval`] (closed-loop success and smoothness of any
//! [`tasks::Policy`]), [`serve`] (a policy over the binary protocol), [`bench`](mod@bench) (latency per
//! chunk), [`equiv`] (the bit-accuracy harness), [`quickstart`] (the whole pipeline), and
//! [`tasks`] (the built-in tasks and their scripted experts). What they are made of is public
//! where the tests and examples build on it: [`data`] (demonstrations, windows),
//! [`checkpoint`], [`policy`] (float and int8 policies), [`models`] and [`diffusion`] (candle
//! networks, preconditioning, samplers), [`rng`], [`firmware`] (processor in the loop) and
//! [`prodmp_vectors`] (the decoder's reference check). The rest is crate-private.
pub mod bench;
pub mod checkpoint;
pub mod cli;
pub mod data;
pub mod diffusion;
pub mod equiv;
pub mod eval;
pub mod export;
pub mod firmware;
pub(crate) mod limits;
pub mod models;
pub mod policy;
pub mod prodmp_vectors;
pub(crate) mod progress;
pub mod quickstart;
pub mod rng;
pub mod serve;
pub mod tasks;
pub mod train;
