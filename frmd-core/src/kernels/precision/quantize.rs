//! The per-precision kernel hooks (`sealed::Quantize`): which loops a layer of each activation
//! precision runs on each target. The portable hooks are not `#[inline]` on hosts, so that the
//! generic layer code that calls them (instantiated in whichever crate names the precision, at
//! that crate's optimization level: `opt-level = 1` for frmd-host in the dev profile) reaches
//! loops compiled once here, with frmd-core's own optimization.

use super::sealed;
use crate::kernels::input::LayerInput;
use crate::kernels::lut::LutTable;
use crate::kernels::lut16::Lut16Table;

#[allow(private_interfaces)]
impl sealed::Quantize for i8 {
    #[cfg_attr(target_os = "none", inline(always))]
    fn forward_portable(
        fc: &crate::kernels::FullyConnected<'_, i32>,
        requant: &crate::kernels::FcRequant<'_, i8>,
        table: Option<&LutTable>,
        input: LayerInput<'_>,
        output: &mut [i8],
    ) {
        fc.requantize_activated(requant, table, input, output);
    }

    /// The int8 AVX2 kernels (requantized in registers), then the table.
    #[cfg(target_arch = "x86_64")]
    #[inline]
    fn forward_x86(
        fc: &crate::kernels::FullyConnected<'_, i32>,
        avx2: crate::kernels::x86::Avx2,
        requant: &crate::kernels::FcRequant<'_, i8>,
        table: Option<&LutTable>,
        input: LayerInput<'_>,
        output: &mut [i8],
    ) {
        fc.forward_avx2(avx2, requant, input, output);
        if let Some(table) = table {
            avx2.apply_table(table, output);
        }
    }
}

#[allow(private_interfaces)]
impl sealed::Quantize for i16 {
    #[cfg_attr(target_os = "none", inline(always))]
    fn forward_portable(
        fc: &crate::kernels::FullyConnected<'_, i64>,
        requant: &crate::kernels::FcRequant<'_, i16>,
        table: Option<&Lut16Table>,
        input: LayerInput<'_>,
        output: &mut [i16],
    ) {
        fc.requantize_activated(requant, table, input, output);
    }

    /// The int64-accumulating AVX2 kernels with requantization and table in registers (from
    /// the packed weights where the layer has them and the CPU runs them).
    #[cfg(target_arch = "x86_64")]
    #[inline]
    fn forward_x86(
        fc: &crate::kernels::FullyConnected<'_, i64>,
        avx2: crate::kernels::x86::Avx2,
        requant: &crate::kernels::FcRequant<'_, i16>,
        table: Option<&Lut16Table>,
        input: LayerInput<'_>,
        output: &mut [i16],
    ) {
        if let Some(packed) = fc.packed.filter(|p| p.serves(fc, input)) {
            if avx2.requantize_packed_wide(&packed, fc, requant, table, input, output) {
                return;
            }
        }
        fc.forward_avx2_wide(avx2, requant, table, input, output);
    }

    #[cfg(frmd_arm_dsp)]
    #[inline(always)]
    fn forward_dsp(
        fc: &crate::kernels::FullyConnected<'_, i64>,
        requant: &crate::kernels::FcRequant<'_, i16>,
        table: Option<&Lut16Table>,
        input: LayerInput<'_>,
        output: &mut [i16],
    ) -> bool {
        match input {
            LayerInput::Int8(values) => {
                crate::kernels::dsp::requantize_rows_wide(fc, requant, table, values, output)
            }
            LayerInput::Int16(values) => {
                crate::kernels::dsp::requantize_rows_wide(fc, requant, table, values, output)
            }
        }
    }
}
