//! Whether this CPU has the instructions the build was compiled for.
//!
//! `.cargo/config.toml` builds for x86-64-v3 (AVX2, FMA, BMI1/2: every x86-64
//! server CPU since 2013-2015). On a CPU without them the first such
//! instruction would kill the process with SIGILL and no word of why; this
//! check runs first in `main`, says what the build needs and how to build
//! for the CPU instead, and exits 1. It asks for exactly what the build
//! enabled (`cfg!(target_feature)`, up to x86-64-v4's AVX-512), so a build
//! for an older level asks for less, and one for `target-cpu=native` on an
//! AVX-512 CPU for that too (checked by hand: such a build under
//! `qemu-x86_64 -cpu max`, which has no AVX-512, gives the message).
//!
//! It must itself run on the older CPU: the whole crate is compiled for the
//! build's level, and a `Vec` or a `format!` here was compiled to AVX moves
//! (seen under `qemu-x86_64 -cpu Nehalem`). So it is flag tests and a
//! static message written by one system call, nothing the compiler could
//! put in vector registers; `tests/cpu_level.rs` runs it under qemu.

/// The message for a CPU that lacks an extension the build uses.
const UNSUPPORTED: &str = "error: this build of looming uses CPU instructions this CPU lacks: \
it was built for x86-64-v3 (AVX, AVX2, BMI1, BMI2, F16C, FMA, LZCNT, MOVBE; \
.cargo/config.toml) or for the CPU that RUSTFLAGS named. Build it for this CPU with \
RUSTFLAGS=\"-C target-cpu=native\" cargo build --release (x86-64-v2 or x86-64 \
for a binary that runs on older CPUs too).\n";

/// Whether the CPU lacks an x86-64 extension, up to x86-64-v4, that the
/// build was compiled to use: its CPUID flags against the build's, as masks
/// (`std::is_x86_feature_detected!` answers true, without asking the CPU,
/// for every extension the build enables).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn lacks_a_compiled_extension() -> bool {
    use std::arch::x86_64::{__cpuid, __cpuid_count};
    // The build's extensions at their CPUID bits (Intel SDM vol. 2A, CPUID).
    const fn bit(enabled: bool, at: u32) -> u32 {
        if enabled { 1 << at } else { 0 }
    }
    const LEAF_1_ECX: u32 = bit(cfg!(target_feature = "sse3"), 0)
        | bit(cfg!(target_feature = "ssse3"), 9)
        | bit(cfg!(target_feature = "fma"), 12)
        | bit(cfg!(target_feature = "cmpxchg16b"), 13)
        | bit(cfg!(target_feature = "sse4.1"), 19)
        | bit(cfg!(target_feature = "sse4.2"), 20)
        | bit(cfg!(target_feature = "movbe"), 22)
        | bit(cfg!(target_feature = "popcnt"), 23)
        | bit(cfg!(target_feature = "xsave"), 26)
        | bit(cfg!(target_feature = "avx"), 28)
        | bit(cfg!(target_feature = "f16c"), 29);
    const LEAF_7_EBX: u32 = bit(cfg!(target_feature = "bmi1"), 3)
        | bit(cfg!(target_feature = "avx2"), 5)
        | bit(cfg!(target_feature = "bmi2"), 8)
        | bit(cfg!(target_feature = "avx512f"), 16)
        | bit(cfg!(target_feature = "avx512dq"), 17)
        | bit(cfg!(target_feature = "avx512cd"), 28)
        | bit(cfg!(target_feature = "avx512bw"), 30)
        | bit(cfg!(target_feature = "avx512vl"), 31);
    const EXTENDED_ECX: u32 = bit(cfg!(target_feature = "lzcnt"), 5);
    // (A leaf above the highest the CPU reports is not asked.)
    let highest_leaf = __cpuid(0).eax;
    let leaf_1_ecx = __cpuid(1).ecx;
    if leaf_1_ecx & LEAF_1_ECX != LEAF_1_ECX {
        return true;
    }
    if LEAF_7_EBX != 0 && (highest_leaf < 7 || __cpuid_count(7, 0).ebx & LEAF_7_EBX != LEAF_7_EBX) {
        return true;
    }
    if EXTENDED_ECX != 0 {
        let highest = __cpuid(0x8000_0000).eax;
        if highest < 0x8000_0001 || __cpuid(0x8000_0001).ecx & EXTENDED_ECX != EXTENDED_ECX {
            return true;
        }
    }
    // AVX also needs the OS to save its registers: OSXSAVE set, and XCR0's
    // SSE and AVX state bits (and AVX-512's three, for a build that uses
    // it: x86-64-v4, or `target-cpu=native` on such a CPU).
    const XCR0: u32 = if cfg!(target_feature = "avx512f") {
        0b1110_0110
    } else {
        0b110
    };
    if cfg!(target_feature = "avx") {
        if leaf_1_ecx & (1 << 27) == 0 {
            return true;
        }
        let xcr0_low: u32;
        // SAFETY: `xgetbv` exists where OSXSAVE is set (tested above); XCR0
        // is readable at any privilege level.
        unsafe {
            std::arch::asm!("xgetbv", in("ecx") 0, out("eax") xcr0_low, out("edx") _,
                options(nomem, nostack, preserves_flags));
        }
        if xcr0_low & XCR0 != XCR0 {
            return true;
        }
    }
    false
}

#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn lacks_a_compiled_extension() -> bool {
    false
}

/// Ends the process with [`UNSUPPORTED`] and exit code 1 where the CPU
/// lacks an extension the build uses; returns otherwise.
#[inline(never)]
pub fn exit_unless_supported() {
    if !lacks_a_compiled_extension() {
        return;
    }
    #[cfg(unix)]
    // SAFETY: writes a static buffer of its own length to stderr and ends
    // the process; no Rust state is shared with either call.
    unsafe {
        libc::write(2, UNSUPPORTED.as_ptr().cast(), UNSUPPORTED.len());
        libc::_exit(1);
    }
    #[cfg(not(unix))]
    {
        eprint!("{UNSUPPORTED}");
        std::process::exit(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_machine_that_runs_the_tests_runs_its_own_build() {
        assert!(!lacks_a_compiled_extension());
        exit_unless_supported();
    }

    #[test]
    fn the_message_names_the_level_and_the_fix() {
        assert!(UNSUPPORTED.contains("x86-64-v3"));
        assert!(UNSUPPORTED.contains("RUSTFLAGS=\"-C target-cpu=native\""));
        assert!(UNSUPPORTED.ends_with('\n'));
    }
}
