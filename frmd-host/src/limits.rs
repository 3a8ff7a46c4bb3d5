//! The bounds every run config is checked against before any work (`validate()` on the configs
//! of [`crate::train::recipe`], [`crate::eval`], [`crate::data::collect`], [`crate::equiv`],
//! [`crate::quickstart`]), and the one error type of those checks, [`OptionError`], which names
//! the option, the value given and what was expected.
//!
//! The counts are bounded to what one machine can hold and finish: far above any sensible run,
//! far below what would exhaust memory (an episode record is ~100 bytes, a training window of the
//! built-in tasks ~1 kB, a batch row a few kB of activations).

/// Most evaluation (or collection) episodes of one run.
pub const MAX_EPISODES: usize = 1_000_000;
/// Most gradient steps of one training run.
pub const MAX_TRAIN_STEPS: usize = 10_000_000;
/// Largest training batch.
pub const MAX_BATCH: usize = 65_536;
/// Most steps an episode end is padded by (`train::padding`).
pub const MAX_PAD_END: usize = 10_000;
/// Most sampling steps of a teacher or DP sampler.
pub const MAX_SAMPLER_STEPS: usize = 1_000;
/// Longest observation history.
pub const MAX_HISTORY: usize = 64;
/// Longest prediction horizon.
pub const MAX_HORIZON: usize = 1_024;
/// Most ProDMP basis functions.
pub const MAX_NUM_BASIS: usize = 256;
/// Longest noise embedding.
pub const MAX_EMBED_DIM: usize = 4_096;
/// Most open-loop inputs or random cases of a check.
pub const MAX_CHECKS: usize = 10_000_000;

/// A run option out of range, or options that do not go together.
#[derive(Clone, Debug, PartialEq)]
pub enum OptionError {
    /// `--option value`: expected `expected`.
    Range {
        option: &'static str,
        value: String,
        expected: String,
    },
    /// `--option` cannot be used with `with` (`reason`).
    Conflict {
        option: &'static str,
        with: String,
        reason: String,
    },
}

impl std::fmt::Display for OptionError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            OptionError::Range {
                option,
                value,
                expected,
            } => write!(f, "--{option} {value}: expected {expected}"),
            OptionError::Conflict {
                option,
                with,
                reason,
            } => write!(f, "--{option} cannot be used with {with}: {reason}"),
        }
    }
}

impl std::error::Error for OptionError {}

/// Shorthand for an out-of-range option.
pub fn range(
    option: &'static str,
    value: impl std::fmt::Display,
    expected: impl Into<String>,
) -> OptionError {
    OptionError::Range {
        option,
        value: value.to_string(),
        expected: expected.into(),
    }
}

/// Shorthand for options that conflict.
pub fn conflict(
    option: &'static str,
    with: impl Into<String>,
    reason: impl Into<String>,
) -> OptionError {
    OptionError::Conflict {
        option,
        with: with.into(),
        reason: reason.into(),
    }
}

/// `value` in `min..=max`.
pub fn count(
    option: &'static str,
    value: usize,
    min: usize,
    max: usize,
) -> Result<(), OptionError> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(range(option, value, format!("{min} to {max}")))
    }
}

/// A probability or fraction in [0, 1].
pub fn probability(option: &'static str, value: f64) -> Result<(), OptionError> {
    if (0.0..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(range(option, value, "a number in [0, 1]"))
    }
}

/// An EMA decay in [0, 1).
pub fn decay(option: &'static str, value: f64) -> Result<(), OptionError> {
    if (0.0..1.0).contains(&value) {
        Ok(())
    } else {
        Err(range(option, value, "a decay in [0, 1)"))
    }
}

/// A finite number > 0.
pub fn positive(option: &'static str, value: f64) -> Result<(), OptionError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(range(option, value, "a finite number > 0"))
    }
}

/// A finite number >= 0.
pub fn non_negative(option: &'static str, value: f64) -> Result<(), OptionError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(range(option, value, "a finite number >= 0"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checks_name_the_option_and_the_expected_range() {
        assert_eq!(
            count("episodes", 0, 1, 10).unwrap_err().to_string(),
            "--episodes 0: expected 1 to 10"
        );
        assert!(probability("aug-prob", f64::NAN).is_err());
        assert!(probability("aug-prob", 2.0).is_err());
        assert!(probability("aug-prob", 1.0).is_ok());
        assert!(positive("lr", -1.0).is_err());
        assert!(positive("lr", f64::INFINITY).is_err());
        assert!(decay("ema", 1.0).is_err());
        assert!(non_negative("weight-decay", 0.0).is_ok());
    }
}
