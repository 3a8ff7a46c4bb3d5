//! [`PolicyDims`]: the sizes of a policy, known at run time (a blob's descriptor, a baked module's
//! constants) and checked against the fixed capacities of the buffers that hold them.

/// Sizes of a policy: observation history `m`, observation dimension `o`, action dimension
/// (DoF) `k`, horizon `n`, ProDMP parameters per DoF `p = num_basis + 1`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PolicyDims {
    /// Observation history length `m`.
    pub history: usize,
    /// Observation dimension `o`.
    pub obs_dim: usize,
    /// Action dimension `k`.
    pub action_dim: usize,
    /// Horizon `n` (actions per chunk).
    pub horizon: usize,
    /// ProDMP parameters per DoF `p`.
    pub params_per_dof: usize,
}

impl PolicyDims {
    /// `m o`: values of the observation history; `None` on overflow.
    pub fn history_len(&self) -> Option<usize> {
        self.history.checked_mul(self.obs_dim)
    }

    /// `n k`: values of one trajectory (positions or velocities); `None` on overflow.
    pub fn trajectory_len(&self) -> Option<usize> {
        self.horizon.checked_mul(self.action_dim)
    }

    /// `k p`: ProDMP parameters of the network output; `None` on overflow.
    pub fn params_len(&self) -> Option<usize> {
        self.action_dim.checked_mul(self.params_per_dof)
    }

    /// Whether every size is positive and at most the capacity `[M, O, K, N, P]`.
    pub fn fits(&self, capacity: [usize; 5]) -> bool {
        let sizes = [
            self.history,
            self.obs_dim,
            self.action_dim,
            self.horizon,
            self.params_per_dof,
        ];
        sizes
            .iter()
            .zip(capacity)
            .all(|(size, cap)| *size > 0 && *size <= cap)
    }
}

/// `values` as `N` rows of `L` (for capacities equal to the run-time sizes, so that loops over
/// the rows and within them have constant trip counts); `None` for any other length.
pub(crate) fn fixed_rows<const N: usize, const L: usize>(
    values: &[f32],
) -> Option<impl Iterator<Item = &[f32]> + Clone> {
    let table: &[[f32; L]; N] = values.as_chunks::<L>().0.try_into().ok()?;
    Some(table.iter().map(|row| &row[..]))
}

/// Whether every value of a chunk's positions and velocities is finite.
#[inline(always)]
pub(crate) fn all_finite(positions: &[f32], velocities: &[f32]) -> bool {
    positions
        .iter()
        .chain(velocities.iter())
        .all(|v| v.is_finite())
}

/// Rows of two buffers, side by side (see [`fixed_rows`]).
pub(crate) fn fixed_row_pairs<'a, const N: usize, const L: usize>(
    a: &'a mut [f32],
    b: &'a mut [f32],
) -> Option<impl Iterator<Item = (&'a mut [f32], &'a mut [f32])>> {
    let a: &mut [[f32; L]; N] = a.as_chunks_mut::<L>().0.try_into().ok()?;
    let b: &mut [[f32; L]; N] = b.as_chunks_mut::<L>().0.try_into().ok()?;
    Some(
        a.iter_mut()
            .zip(b.iter_mut())
            .map(|(a, b)| (&mut a[..], &mut b[..])),
    )
}
