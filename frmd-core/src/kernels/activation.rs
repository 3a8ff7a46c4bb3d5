//! The f32 activation functions: one definition each, used to build int8 LUTs, by the f32
//! reference forward passes and (through frmd-core) by the host models' equivalence checks.
//!
//! All use `libm`, which is pure software (correctly rounded `sqrt` aside) and therefore gives the
//! same bits on every target.

/// Softplus `ln(1 + e^x)`, evaluated stably as `max(x, 0) + ln(1 + e^-|x|)`.
#[inline]
pub fn softplus(x: f32) -> f32 {
    x.max(0.0) + libm::log1pf(libm::expf(-x.abs()))
}

/// SiLU (swish) `x * sigmoid(x) = x / (1 + e^-x)`; for `x < 0` evaluated as `x e^x / (1 + e^x)`
/// so that `e^-x` never overflows.
#[inline]
pub fn silu(x: f32) -> f32 {
    if x >= 0.0 {
        x / (1.0 + libm::expf(-x))
    } else {
        let e = libm::expf(x);
        x * e / (1.0 + e)
    }
}

/// Mish `x * tanh(softplus(x))` (Misra 2019).
#[inline]
pub fn mish(x: f32) -> f32 {
    x * libm::tanhf(softplus(x))
}

/// GELU, exact form `0.5 x (1 + erf(x / sqrt(2)))` (PyTorch `nn.GELU()` default, candle
/// `gelu_erf`).
#[inline]
pub fn gelu(x: f32) -> f32 {
    0.5 * x * (1.0 + libm::erff(x * core::f32::consts::FRAC_1_SQRT_2))
}

/// GELU, tanh approximation `0.5 x (1 + tanh(sqrt(2/pi) (x + 0.044715 x^3)))` (PyTorch
/// `approximate="tanh"`, candle `gelu`).
#[inline]
pub fn gelu_tanh(x: f32) -> f32 {
    const SQRT_2_OVER_PI: f32 = 0.797_884_6;
    0.5 * x * (1.0 + libm::tanhf(SQRT_2_OVER_PI * (x + 0.044_715 * x * x * x)))
}

/// GELU, sigmoid approximation `x sigmoid(1.702 x)` (Hendrycks & Gimpel 2016), the transformer
/// backbone's activation (`frmd-host` `models::act::gelu_sigmoid`). Evaluated as
/// `x / (1 + e^(-1.702 x))` for `x >= 0` and `x e^(1.702 x) / (1 + e^(1.702 x))` otherwise, so
/// the exponential never overflows.
#[inline]
pub fn gelu_sigmoid(x: f32) -> f32 {
    const SLOPE: f32 = 1.702;
    let s = SLOPE * x;
    if s >= 0.0 {
        x / (1.0 + libm::expf(-s))
    } else {
        let e = libm::expf(s);
        x * e / (1.0 + e)
    }
}

/// A pointwise activation, named so that configs, the exporter and the f32 reference paths agree
/// on which function a layer uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Activation {
    /// `x` (no activation).
    Identity,
    /// `max(x, 0)`.
    Relu,
    /// [`silu`].
    Silu,
    /// [`mish`].
    Mish,
    /// [`gelu`] (erf form).
    Gelu,
    /// [`gelu_tanh`] (tanh approximation).
    GeluTanh,
    /// [`gelu_sigmoid`] (sigmoid approximation, the transformer's feed-forward).
    GeluSigmoid,
}

impl Activation {
    /// Applies the activation to one value.
    #[inline]
    pub fn apply(self, x: f32) -> f32 {
        match self {
            Self::Identity => x,
            Self::Relu => x.max(0.0),
            Self::Silu => silu(x),
            Self::Mish => mish(x),
            Self::Gelu => gelu(x),
            Self::GeluTanh => gelu_tanh(x),
            Self::GeluSigmoid => gelu_sigmoid(x),
        }
    }

    /// Applies the activation to every element of `values`.
    pub fn apply_in_place(self, values: &mut [f32]) {
        if self != Self::Identity {
            for v in values.iter_mut() {
                *v = self.apply(*v);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn silu64(x: f64) -> f64 {
        x / (1.0 + (-x).exp())
    }
    fn softplus64(x: f64) -> f64 {
        x.max(0.0) + (-x.abs()).exp().ln_1p()
    }
    fn mish64(x: f64) -> f64 {
        x * softplus64(x).tanh()
    }

    #[test]
    fn match_f64_definitions() {
        let mut x = -30.0_f32;
        while x <= 30.0 {
            let xd = f64::from(x);
            let tol = |v: f64| 2e-6 * v.abs().max(1.0);
            assert!(
                (f64::from(silu(x)) - silu64(xd)).abs() <= tol(xd),
                "silu {x}"
            );
            assert!(
                (f64::from(mish(x)) - mish64(xd)).abs() <= tol(xd),
                "mish {x}"
            );
            assert!(
                (f64::from(softplus(x)) - softplus64(xd)).abs() <= tol(xd),
                "softplus {x}"
            );
            x += 0.0137;
        }
    }

    #[test]
    fn gelu_sigmoid_matches_f64_definition() {
        let mut x = -60.0_f32;
        while x <= 60.0 {
            let xd = f64::from(x);
            let want = xd / (1.0 + (-1.702 * xd).exp());
            let got = f64::from(gelu_sigmoid(x));
            assert!(
                (got - want).abs() <= 2e-6 * xd.abs().max(1.0),
                "{x}: {got} vs {want}"
            );
            x += 0.0173;
        }
        assert_eq!(gelu_sigmoid(0.0), 0.0);
        assert!(gelu_sigmoid(-1e30).abs() < 1e-3 && gelu_sigmoid(1e30) == 1e30);
    }

    #[test]
    fn enum_dispatches_to_the_functions() {
        for x in [-3.0_f32, -0.5, 0.0, 0.7, 4.0] {
            assert_eq!(Activation::Identity.apply(x), x);
            assert_eq!(Activation::Relu.apply(x), x.max(0.0));
            assert_eq!(Activation::Silu.apply(x), silu(x));
            assert_eq!(Activation::Mish.apply(x), mish(x));
            assert_eq!(Activation::Gelu.apply(x), gelu(x));
            assert_eq!(Activation::GeluTanh.apply(x), gelu_tanh(x));
            assert_eq!(Activation::GeluSigmoid.apply(x), gelu_sigmoid(x));
        }
        let mut v = [-1.0_f32, 2.0];
        Activation::Relu.apply_in_place(&mut v);
        assert_eq!(v, [0.0, 2.0]);
    }

    #[test]
    fn known_values_and_extremes() {
        assert_eq!(silu(0.0), 0.0);
        assert_eq!(mish(0.0), 0.0);
        assert_eq!(gelu(0.0), 0.0);
        assert!((gelu(1.0) - 0.841_344_7).abs() < 1e-6);
        assert!((gelu(-1.0) + 0.158_655_25).abs() < 1e-6);
        assert!((gelu_tanh(1.0) - 0.841_192).abs() < 1e-5);
        assert!((silu(1.0) - 0.731_058_6).abs() < 1e-6);
        assert!((mish(1.0) - 0.865_098_4).abs() < 1e-6);
        // No overflow to NaN at the ends of the f32 range.
        for f in [silu, mish, gelu, gelu_tanh, softplus] {
            assert!(f(-1e30).is_finite() && f(-1e30).abs() < 1e-3);
            assert!((f(1e30) - 1e30).abs() <= 1e24);
        }
    }
}
