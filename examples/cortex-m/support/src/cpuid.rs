//! The Cortex-M core named by a CPUID register (the firmware's `core:` report line and the PIL
//! image's hello message, decoded by frmd-host).

/// The core a CPUID register value names (from its part number), `"unknown"` for others.
pub fn core_name(cpuid: u32) -> &'static str {
    match (cpuid >> 4) & 0xFFF {
        0xC20 => "cortex-m0",
        0xC60 => "cortex-m0+",
        0xC24 => "cortex-m4",
        0xC27 => "cortex-m7",
        0xD21 => "cortex-m33",
        0xD22 => "cortex-m55",
        _ => "unknown",
    }
}
