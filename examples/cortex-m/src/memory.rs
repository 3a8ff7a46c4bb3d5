//! Flash and RAM use of the running image, from cortex-m-rt's linker symbols, and peak stack by
//! stack painting.
//!
//! Flash image = vector table + `.text` + `.rodata` + the load image of `.data`.
//! Static RAM = `.data` + `.bss` + `.uninit` (`__sdata` .. `_stack_end`). The stack grows down from
//! `_stack_start` (end of RAM) towards `_stack_end`; [`StackProbe::paint`] fills the unused part with
//! a pattern and [`StackProbe::peak_bytes`] finds the lowest word the program has overwritten since.

use core::ptr::addr_of;

// Addresses placed by cortex-m-rt's link.x; only their addresses are used, never their contents.
extern "C" {
    static __vector_table: u32;
    static __stext: u32;
    static __etext: u32;
    static __srodata: u32;
    static __erodata: u32;
    static __sdata: u32;
    static __edata: u32;
    static __sidata: u32;
    static _stack_end: u32;
    static _stack_start: u32;
}

/// Section sizes of the linked image, in bytes.
#[derive(Clone, Copy, Debug)]
pub struct ImageSizes {
    /// Vector table + `.text` + `.rodata` + `.data` load image.
    pub flash: usize,
    pub text: usize,
    pub rodata: usize,
    /// `.data` + `.bss` + `.uninit`.
    pub ram_static: usize,
}

impl ImageSizes {
    pub fn of_this_image() -> Self {
        let vector_table = addr_of!(__vector_table) as usize;
        let data = addr_of!(__edata) as usize - addr_of!(__sdata) as usize;
        Self {
            flash: addr_of!(__sidata) as usize - vector_table + data,
            text: addr_of!(__etext) as usize - addr_of!(__stext) as usize,
            rodata: addr_of!(__erodata) as usize - addr_of!(__srodata) as usize,
            ram_static: addr_of!(_stack_end) as usize - addr_of!(__sdata) as usize,
        }
    }
}

const PAINT: u32 = 0x5AFE_C0DE;
/// Bytes left unpainted below the stack pointer of the painting function.
const PAINT_MARGIN: usize = 256;

/// Peak stack measurement by painting the free stack region.
pub struct StackProbe {
    bottom: usize,
    top: usize,
}

impl StackProbe {
    /// Paints the free stack (from `_stack_end` up to just below the current stack pointer).
    #[inline(never)]
    pub fn paint() -> Self {
        let bottom = addr_of!(_stack_end) as usize;
        let top = addr_of!(_stack_start) as usize;
        let paint_end = (cortex_m::register::msp::read() as usize).saturating_sub(PAINT_MARGIN);
        let mut address = bottom;
        while address + 4 <= paint_end {
            // SAFETY: `address` is word aligned (linker asserts `_stack_end % 4 == 0`), lies in RAM
            // between the end of static data and PAINT_MARGIN below the live stack pointer, so it
            // is memory that no live object occupies.
            unsafe { core::ptr::write_volatile(address as *mut u32, PAINT) };
            address += 4;
        }
        Self { bottom, top }
    }

    /// Bytes of stack used at the deepest point since [`Self::paint`] (from the top of RAM).
    pub fn peak_bytes(&self) -> usize {
        let mut address = self.bottom;
        while address < self.top {
            // SAFETY: word-aligned RAM address inside the stack region, read only.
            let word = unsafe { core::ptr::read_volatile(address as *const u32) };
            if word != PAINT {
                break;
            }
            address += 4;
        }
        self.top - address
    }
}
