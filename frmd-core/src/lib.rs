//! FRMD core: the firmware side of a one-step ProDMP consistency policy.
//!
//! `#![no_std]` and no `alloc`: every buffer is a fixed-size array or a caller-owned slice whose
//! size is known at compile time. No function on an input path panics; errors are small enums.
#![no_std]
#![warn(missing_docs)]
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented
    )
)]

#[cfg(any(test, feature = "alloc"))]
extern crate alloc;

pub mod blob;
pub mod hash;
pub mod kernels;
pub mod model;
pub mod policy;
pub mod prodmp;
pub mod quant;
pub mod rng;
pub mod sigma;
