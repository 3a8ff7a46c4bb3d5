//! Forward passes of the firmware networks over borrowed (typically `&'static` baked) weights:
//! one [`linear`] layer in f32 and int8 forms, and the two backbones built from it.

#[cfg(test)]
pub(crate) mod fixture;
pub mod linear;
pub mod mlp;
pub mod transformer;
