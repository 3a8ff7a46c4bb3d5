//! Demonstration datasets: the safetensors format of DESIGN.md section 4, validation, training
//! windows and [-1, 1] normalization.
pub mod windows;
