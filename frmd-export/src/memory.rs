//! RAM and flash figures of an exported policy, in the same terms for every backbone.
use frmd_core::policy::PolicyDims;

/// RAM and flash figures of a policy (bytes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryFigures {
    /// Widest layer (input, hidden or output) of an MLP, the width of a transformer.
    pub scratch_width: usize,
    /// Forward-pass scratch: the MLP's two int8 activation rows and one int32 accumulator row
    /// of the widest layer; the transformer's exact int8 scratch.
    pub scratch_bytes: usize,
    /// Sampler working memory and policy state (history, chunk buffers, input vector), f32.
    pub state_bytes: usize,
    /// int8 weights and int32 biases (incl. bias variants), with the MLP weight file's padding.
    pub weights_bytes: usize,
    /// Constant tables: requantization, LUTs, scales, norms, tokens, ProDMP, normalization, steps.
    pub table_bytes: usize,
}

impl MemoryFigures {
    /// Total read-only bytes (weights plus tables).
    pub fn flash_bytes(&self) -> usize {
        self.weights_bytes + self.table_bytes
    }

    /// Scratch plus state.
    pub fn ram_bytes(&self) -> usize {
        self.scratch_bytes + self.state_bytes
    }
}

/// The RAM and flash lines `frmd export` prints.
impl std::fmt::Display for MemoryFigures {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "  RAM    scratch {} B (width {}) + state {} B = {} B",
            self.scratch_bytes,
            self.scratch_width,
            self.state_bytes,
            self.ram_bytes()
        )?;
        write!(
            f,
            "  flash  weights {} B + tables {} B = {} B",
            self.weights_bytes,
            self.table_bytes,
            self.flash_bytes()
        )
    }
}

/// The policy's f32 state in bytes for a model input of `input_width` values: the history ring
/// and its ordered copy, noisy and noise chunks, three trajectories (decoded, normalized, chunk)
/// of positions and velocities, the input vector, the parameters, the previous action and rate.
pub(crate) fn state_bytes(d: &PolicyDims, input_width: usize) -> usize {
    let (m, o, k, n, p) = (
        d.history,
        d.obs_dim,
        d.action_dim,
        d.horizon,
        d.params_per_dof,
    );
    4 * (2 * m * o + 2 * n * k + 6 * n * k + input_width + k * p + 2 * k)
}

/// Flash bytes of the tables every policy has: the ProDMP decoder (`[n][p]` position and
/// velocity tables plus four `[n]` rows), the normalization bounds and the step constants.
pub(crate) fn policy_table_bytes(d: &PolicyDims, steps: usize) -> usize {
    let (n, p) = (d.horizon, d.params_per_dof);
    4 * n * (2 * p + 4) + 8 * (d.obs_dim + d.action_dim) + 24 * steps
}
