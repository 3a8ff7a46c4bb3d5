//! The process-wide switch of an optional kernel level (x86-64: AVX2, AVX-VNNI, AVX-512 VNNI;
//! aarch64: NEON, `SDOT`): on when the CPU has the level, probed once at first use, and
//! switchable off (or back on, if supported) for A/B measurements and agreement checks. Every
//! level gives the same bits, so a switch only chooses speed.

use core::sync::atomic::{AtomicU8, Ordering};

/// Not yet probed.
const UNKNOWN: u8 = 0;
/// Supported and enabled.
const ACTIVE: u8 = 1;
/// Unsupported, or switched off.
const INACTIVE: u8 = 2;

/// One level's switch (a `static`).
pub(crate) struct KernelSwitch {
    state: AtomicU8,
    supported: fn() -> bool,
}

impl KernelSwitch {
    /// A level that is on at first use if `supported()` says this CPU has it.
    pub(crate) const fn probed(supported: fn() -> bool) -> Self {
        Self {
            state: AtomicU8::new(UNKNOWN),
            supported,
        }
    }

    /// A level every CPU of the target has (or a choice between levels): on until switched off.
    pub(crate) const fn baseline() -> Self {
        fn always() -> bool {
            true
        }
        Self {
            state: AtomicU8::new(ACTIVE),
            supported: always,
        }
    }

    /// Whether the level is on (the first call probes the CPU).
    #[inline]
    pub(crate) fn active(&self) -> bool {
        match self.state.load(Ordering::Relaxed) {
            ACTIVE => true,
            INACTIVE => false,
            _ => {
                let supported = (self.supported)();
                self.store(supported);
                supported
            }
        }
    }

    /// Switches the level on (if this CPU supports it) or off; returns whether it is on.
    pub(crate) fn set(&self, enabled: bool) -> bool {
        let active = enabled && (self.supported)();
        self.store(active);
        active
    }

    /// Whether this CPU has the level (whatever the switch says).
    pub(crate) fn supported(&self) -> bool {
        (self.supported)()
    }

    fn store(&self, active: bool) {
        let state = if active { ACTIVE } else { INACTIVE };
        self.state.store(state, Ordering::Relaxed);
    }
}
