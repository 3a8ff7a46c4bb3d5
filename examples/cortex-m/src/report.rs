//! Where the firmware's `key: value` lines go and how it stops.
//!
//! Default: ARM semihosting (QEMU `-semihosting-config enable=on,target=native` prints to the host's
//! stdout; `debug::exit` ends QEMU with status 0 or 1). With the `defmt` feature: defmt over RTT for
//! a real probe (probe-rs), stopping on a breakpoint (success) or an undefined instruction (failure),
//! since semihosting calls halt a core that has no debugger attached.

/// Prints one `key: value` line. The format arguments follow `core::fmt` without the `defmt`
/// feature and defmt's syntax with it, so call sites stick to `{}` on primitives and `&str`.
#[cfg(not(feature = "defmt"))]
macro_rules! report {
    ($($arg:tt)*) => { cortex_m_semihosting::hprintln!($($arg)*) };
}

#[cfg(feature = "defmt")]
macro_rules! report {
    ($($arg:tt)*) => { defmt::println!($($arg)*) };
}

pub(crate) use report;

/// Prints a 64-bit value as 16 lowercase hex digits under `key`.
pub fn hex64(key: &str, value: u64) {
    #[cfg(not(feature = "defmt"))]
    cortex_m_semihosting::hprintln!("{}: {:016x}", key, value);
    #[cfg(feature = "defmt")]
    defmt::println!("{=str}: {=u64:016x}", key, value);
}

/// Prints `whole.fraction` with three fractional digits, from a value in thousandths.
pub fn milli(key: &str, thousandths: u64) {
    let whole = thousandths / 1000;
    let fraction = thousandths % 1000;
    #[cfg(not(feature = "defmt"))]
    cortex_m_semihosting::hprintln!("{}: {}.{:03}", key, whole, fraction);
    #[cfg(feature = "defmt")]
    defmt::println!("{=str}: {=u64}.{=u64:03}", key, whole, fraction);
}

/// Ends the run successfully.
pub fn exit_success() -> ! {
    #[cfg(not(feature = "defmt"))]
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_SUCCESS);
    #[cfg(feature = "defmt")]
    cortex_m::asm::bkpt();
    loop {
        cortex_m::asm::wfi();
    }
}

/// Ends the run with a failure after printing `error: <what>`.
pub fn exit_failure(what: &dyn core::fmt::Display) -> ! {
    #[cfg(not(feature = "defmt"))]
    {
        cortex_m_semihosting::hprintln!("error: {}", what);
        cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
    }
    #[cfg(feature = "defmt")]
    {
        defmt::error!("error: {}", defmt::Display2Format(what));
        cortex_m::asm::udf();
    }
    #[allow(unreachable_code)]
    loop {
        cortex_m::asm::wfi();
    }
}

#[cfg(not(feature = "defmt"))]
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    cortex_m_semihosting::hprintln!("panic: {}", info);
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

#[cfg(feature = "defmt")]
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    cortex_m::asm::udf()
}
