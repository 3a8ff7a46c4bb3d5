//! Diffusion on top of the networks: EDM preconditioning (from `frmd_core::sigma`), the teacher
//! loss, ODE samplers for the teacher, consistency sampling for the student, and the DDPM/DDIM
//! machinery of the DP baseline.
/// The command-line names of a settings enum's variants, written once: `parse` (also under
/// `FromStr`, with optional aliases) and `Display` (the first name), so that a flag and the
/// default its help shows use the same spelling.
macro_rules! variant_names {
    ($ty:ident, $what:literal, { $($variant:ident = $name:literal $(| $alias:literal)*),+ $(,)? }) => {
        impl $ty {
            /// Parses a variant's name.
            pub fn parse(text: &str) -> anyhow::Result<Self> {
                match text {
                    $($name $(| $alias)* => Ok($ty::$variant),)+
                    other => anyhow::bail!("unknown {} `{other}` ({})", $what, [$($name),+].join(", ")),
                }
            }
        }

        impl std::str::FromStr for $ty {
            type Err = anyhow::Error;

            fn from_str(text: &str) -> anyhow::Result<Self> {
                Self::parse(text)
            }
        }

        impl std::fmt::Display for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(match self {
                    $($ty::$variant => $name,)+
                })
            }
        }
    };
}

pub mod consistency;
pub mod ddpm;
pub mod loss;
pub mod precond;
pub mod samplers;

/// Wraps a `frmd_core::sigma` error (its source kept) in the context naming the quantity.
pub(crate) fn sigma_err(what: &str) -> impl Fn(frmd_core::sigma::SigmaError) -> anyhow::Error + '_ {
    move |e| anyhow::Error::new(e).context(what.to_string())
}
