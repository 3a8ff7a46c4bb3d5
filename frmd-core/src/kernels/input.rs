//! The input vector of a layer: int8 or int16 codes.

/// The input vector of a fully connected layer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerInput<'a> {
    /// int8 codes (every hidden layer, and a first layer with int8 input).
    Int8(&'a [i8]),
    /// int16 codes of the 16-bit input plane (`model::mlp::InputPrecision::Int16`).
    Int16(&'a [i16]),
}

impl LayerInput<'_> {
    /// Number of input values.
    pub fn len(&self) -> usize {
        match self {
            Self::Int8(values) => values.len(),
            Self::Int16(values) => values.len(),
        }
    }

    /// Whether there are no input values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}
