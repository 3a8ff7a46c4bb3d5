//! Policies backed by models: the float (candle) teacher, student and DP baseline.
pub mod float;
pub mod int8;
