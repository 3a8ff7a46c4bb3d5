//! Instruction counting with SysTick (QEMU) and cycle counting with DWT CYCCNT (real hardware).
//!
//! Under QEMU `-icount shift=0` every executed instruction advances virtual time by 2^0 = 1 ns, and
//! the mps2 boards clock SysTick's "core" source at 25 MHz, so one SysTick count is 40 ns = 40
//! instructions. The firmware does not take that factor on trust: [`calibrate`] times two runs of
//! a two-instruction assembly loop and derives instructions per tick from their difference
//! (QEMU 7.2, both boards: exactly 40.000). On real hardware SysTick counts core cycles instead, and
//! DWT CYCCNT (which reads 0 under QEMU) gives cycles directly.
//!
//! SysTick is a 24-bit down-counter reloaded with 0xFF_FFFF; an interval is
//! `(start - end) mod 2^24` ticks, valid for intervals shorter than 2^24 ticks (671 M instructions
//! under QEMU), far above anything measured here.

use cortex_m::peripheral::{syst::SystClkSource, DCB, DWT, SYST};

/// SysTick reload value and counter mask (24 bits).
pub const SYSTICK_MASK: u32 = 0x00FF_FFFF;

/// A free-running SysTick down-counter on the core clock.
pub struct TickCounter {
    _syst: SYST,
}

impl TickCounter {
    /// Starts SysTick on the core clock, reload 0xFF_FFFF, no interrupt.
    pub fn start(mut syst: SYST) -> Self {
        syst.disable_counter();
        syst.disable_interrupt();
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(SYSTICK_MASK);
        syst.clear_current();
        syst.enable_counter();
        Self { _syst: syst }
    }

    /// Current counter value (counts down).
    #[inline(always)]
    pub fn now(&self) -> u32 {
        SYST::get_current()
    }

    /// Ticks from `start` to `end`, both read with [`Self::now`], across at most one wrap.
    #[inline(always)]
    pub fn elapsed(start: u32, end: u32) -> u32 {
        start.wrapping_sub(end) & SYSTICK_MASK
    }
}

/// DWT cycle counter, if the core has one (not Armv6-M). Reads 0 under QEMU, which does not
/// model the DWT.
pub struct CycleCounter;

impl CycleCounter {
    #[cfg(not(frmd_armv6m))]
    pub fn start(dcb: &mut DCB, dwt: &mut DWT) -> Self {
        dcb.enable_trace();
        DWT::unlock(); // Cortex-M7 locks DWT writes behind its lock access register
        dwt.set_cycle_count(0);
        dwt.enable_cycle_counter();
        Self
    }

    #[cfg(frmd_armv6m)]
    pub fn start(_: &mut DCB, _: &mut DWT) -> Self {
        Self
    }

    #[inline(always)]
    pub fn now(&self) -> u32 {
        #[cfg(not(frmd_armv6m))]
        return DWT::cycle_count();
        #[cfg(frmd_armv6m)]
        return 0;
    }
}

/// Executes exactly `2 * iterations` instructions (`subs` + `bne` per iteration), `iterations >= 1`.
#[inline(never)]
fn spin(iterations: u32) {
    let iterations = iterations.max(1);
    // SAFETY: register-only arithmetic and a local branch; no memory, stack or flag state escapes.
    unsafe {
        core::arch::asm!(
            "2:",
            "subs {n}, {n}, #1",
            "bne 2b",
            n = inout(reg) iterations => _,
            options(nomem, nostack),
        );
    }
}

/// SysTick-to-instruction conversion measured on this machine.
#[derive(Clone, Copy, Debug)]
pub struct Calibration {
    /// Instructions of the longer spin minus the shorter one.
    pub instructions: u64,
    /// SysTick ticks of the longer spin minus the shorter one.
    pub ticks: u64,
}

impl Calibration {
    /// Instructions per tick in thousandths (40_000 under QEMU mps2 with `-icount shift=0`).
    pub fn milli_instructions_per_tick(&self) -> u64 {
        (self.instructions * 1000 + self.ticks / 2) / self.ticks.max(1)
    }

    /// Converts a tick count to instructions, rounded to nearest.
    pub fn instructions(&self, ticks: u64) -> u64 {
        (ticks * self.instructions + self.ticks / 2) / self.ticks.max(1)
    }
}

/// Shorter and longer calibration loops: 0.2 M and 2.2 M instructions, 50_000 ticks apart at 40/tick.
const SHORT_SPIN: u32 = 100_000;
const LONG_SPIN: u32 = 1_100_000;

/// Times two spins of known length; their difference cancels the cost of reading the counter.
pub fn calibrate(counter: &TickCounter) -> Calibration {
    let time = |iterations: u32| {
        let start = counter.now();
        spin(iterations);
        let end = counter.now();
        TickCounter::elapsed(start, end)
    };
    let short = time(SHORT_SPIN);
    let long = time(LONG_SPIN);
    Calibration {
        instructions: 2 * u64::from(LONG_SPIN - SHORT_SPIN),
        ticks: u64::from(long.saturating_sub(short)),
    }
}
