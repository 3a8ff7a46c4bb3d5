//! Diffusion on top of the networks: EDM preconditioning (from `frmd_core::sigma`), the teacher
//! loss, ODE samplers for the teacher, consistency sampling for the student, and the DDPM/DDIM
//! machinery of the DP baseline.
pub mod ddpm;
pub mod loss;
pub mod precond;
pub mod samplers;

/// Maps a `frmd_core::sigma` error into an `anyhow` error naming the quantity.
pub(crate) fn sigma_err(what: &str) -> impl Fn(frmd_core::sigma::SigmaError) -> anyhow::Error + '_ {
    move |e| anyhow::anyhow!("{what}: {e}")
}
