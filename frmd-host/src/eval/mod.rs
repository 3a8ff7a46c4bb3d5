//! Closed-loop evaluation: any policy (expert, float models, the int8 core) against the built-in
//! tasks, with the metrics of DESIGN.md section 6.
pub mod policy;
