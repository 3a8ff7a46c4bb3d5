//! An MLP network's weights packed for the host kernels ([`crate::kernels::packed`]): the
//! host sizes a buffer ([`QuantMlpNetwork::packed_len`]), fills it once
//! ([`QuantMlpNetwork::pack_weights`]) and hands it back
//! ([`QuantMlpNetwork::use_packed_weights`]), which checks every layer's part against its
//! weights. The network then runs the packed copies where this CPU can
//! ([`crate::kernels::packed::runs_here`]), with the same results.

use super::{QuantMlpNetwork, MAX_HIDDEN_LAYERS};
use crate::kernels::packed::{pack, PackedKind, PackedWeights};
use crate::kernels::{Accumulator, FullyConnected, KernelError};
use crate::model::mlp::{InputPrecision, MlpPrecision, ModelError};
use crate::policy::PolicyError;

/// A kernel error as a policy error.
fn kernel(error: KernelError) -> PolicyError {
    PolicyError::Model(ModelError::Kernel(error))
}

impl<'a, P: MlpPrecision, const WIDTH: usize> QuantMlpNetwork<'a, P, WIDTH> {
    /// Every layer (hidden layers, then the output layer) with the packed kind of its input:
    /// the first layer's by the input precision (none for two planes, whose fine plane runs
    /// separately), the activation codes' for the others; none for a layer of int64
    /// accumulators wider than one column chunk (the kernels sum one chunk per row) or one the
    /// layout does not take (wider than `kernels::packed::MAX_PACKED_COLUMNS`).
    fn packed_layers(
        &self,
    ) -> impl Iterator<Item = (&FullyConnected<'a, P::Acc>, Option<PackedKind>)> {
        let first = match self.precision {
            InputPrecision::Int8 => Some(PackedKind::Bytes),
            InputPrecision::Int16 => Some(PackedKind::Words),
            InputPrecision::TwoPlane => None,
        };
        let codes = if P::BITS == 8 {
            PackedKind::Bytes
        } else {
            PackedKind::Words
        };
        let hidden = self.layers.hidden.iter().map(|layer| &layer.fc);
        hidden
            .chain([&self.layers.output.fc])
            .enumerate()
            .map(move |(index, fc)| {
                let kind = if index == 0 { first } else { Some(codes) };
                let packable = |kind: &PackedKind| {
                    let len = kind.packed_len(fc.in_features, fc.out_features);
                    fc.in_features <= P::Acc::CHUNK && len.is_some()
                };
                (fc, kind.filter(packable))
            })
    }

    /// The packed length of each layer (0 for one that is not packed).
    fn packed_lens(&self) -> impl Iterator<Item = usize> + '_ {
        self.packed_layers().map(|(fc, kind)| {
            kind.and_then(|kind| kind.packed_len(fc.in_features, fc.out_features))
                .unwrap_or(0)
        })
    }

    /// Bytes of the packed copy of every layer's weights.
    pub fn packed_len(&self) -> usize {
        self.packed_lens().fold(0, usize::saturating_add)
    }

    /// Writes the packed copy of every layer's weights, back to back, into `out` of
    /// [`Self::packed_len`] bytes.
    pub fn pack_weights(&self, out: &mut [u8]) -> Result<(), PolicyError> {
        if out.len() != self.packed_len() {
            return Err(kernel(KernelError::OutputLength));
        }
        let mut rest = out;
        for ((fc, kind), len) in self.packed_layers().zip(self.packed_lens()) {
            let (part, tail) = rest
                .split_at_mut_checked(len)
                .ok_or(kernel(KernelError::OutputLength))?;
            if let Some(kind) = kind {
                pack(fc, kind, part).map_err(kernel)?;
            }
            rest = tail;
        }
        Ok(())
    }

    /// Lets every layer run its packed copy from `bytes` (what [`Self::pack_weights`] wrote for
    /// this network). Each layer's part is checked against its weights first; on any
    /// difference the network is left as it was and `KernelError::WeightsLength` returned.
    /// Empty `bytes` (a host that does not pack: [`crate::kernels::packed::runs_here`] is
    /// false) leave the network on its row-major weights.
    pub fn use_packed_weights(&mut self, bytes: &'a [u8]) -> Result<(), PolicyError> {
        if bytes.is_empty() {
            return Ok(());
        }
        if bytes.len() != self.packed_len() {
            return Err(kernel(KernelError::WeightsLength));
        }
        let mut views: heapless::Vec<Option<PackedWeights<'a>>, { MAX_HIDDEN_LAYERS + 1 }> =
            heapless::Vec::new();
        let mut rest = bytes;
        for ((fc, kind), len) in self.packed_layers().zip(self.packed_lens()) {
            let (part, tail) = rest
                .split_at_checked(len)
                .ok_or(kernel(KernelError::WeightsLength))?;
            let view = kind
                .map(|kind| PackedWeights::new(fc, kind, part))
                .transpose()
                .map_err(kernel)?;
            views.push(view).map_err(|_| PolicyError::TooManyLayers)?;
            rest = tail;
        }
        let layers = &mut self.layers;
        let fcs = layers
            .hidden
            .iter_mut()
            .map(|layer| &mut layer.fc)
            .chain([&mut layers.output.fc]);
        for (fc, view) in fcs.zip(views) {
            fc.packed = view;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use crate::blob::LoadedMlp;
    use crate::kernels::KernelError;
    use crate::model::mlp::ModelError;
    use crate::policy::{AlignedBytes, Network, PolicyError};
    use std::vec::Vec;

    macro_rules! sample {
        () => {
            include_bytes!(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/tests/data/sample_policy.blob"
            ))
        };
    }
    static BLOB: AlignedBytes<{ sample!().len() }> = AlignedBytes(*sample!());

    /// Every output of every noise variant, bit for bit.
    fn outputs(network: &mut impl Network) -> Vec<u32> {
        let input: Vec<f32> = (0..network.input_width())
            .map(|i| (i as f32 * 0.37).sin())
            .collect();
        let mut all = Vec::new();
        for variant in 0..network.num_noise_variants().max(1) {
            let mut out = std::vec![0.0_f32; network.output_width()];
            network.forward(variant, &input, &mut out).unwrap();
            all.extend(out.iter().map(|v| v.to_bits()));
        }
        all
    }

    #[test]
    fn packed_weights_give_the_same_outputs_and_are_checked() {
        let loaded = LoadedMlp::load(&BLOB.0).unwrap();
        let mut plain = loaded.network::<64>().unwrap();
        let want = outputs(&mut plain);
        let len = plain.packed_len();
        assert!(len > 0);
        let mut bytes = std::vec![0_u8; len];
        plain.pack_weights(&mut bytes).unwrap();
        assert!(plain.pack_weights(&mut std::vec![0; len + 1]).is_err());
        let mut bad = bytes.clone();
        bad[len / 2] ^= 0x10;

        // Packed (run with whatever level this CPU has): the same bits.
        let mut packed = loaded.network::<64>().unwrap();
        packed.use_packed_weights(&bytes).unwrap();
        assert!(packed
            .layers()
            .0
            .iter()
            .all(|layer| layer.fc.packed.is_some()));
        assert_eq!(outputs(&mut packed), want);

        // No bytes: nothing changes (a host that does not pack).
        let mut unpacked = loaded.network::<64>().unwrap();
        unpacked.use_packed_weights(&[]).unwrap();
        assert!(unpacked
            .layers()
            .0
            .iter()
            .all(|layer| layer.fc.packed.is_none()));

        // A changed byte or a short buffer is refused and leaves the network as it was.
        let refused = Err(PolicyError::Model(ModelError::Kernel(
            KernelError::WeightsLength,
        )));
        assert_eq!(unpacked.use_packed_weights(&bad), refused);
        assert_eq!(unpacked.use_packed_weights(&bytes[..len - 1]), refused);
        assert!(unpacked
            .layers()
            .0
            .iter()
            .all(|layer| layer.fc.packed.is_none()));
        assert_eq!(outputs(&mut unpacked), want);
    }
}
