//! Prints the check transcript: to stdout on the host, through semihosting on the Cortex-M7
//! (QEMU: `-semihosting-config enable=on,target=native`), exiting non-zero on failure.
//!
//! The emulated run also prints `cost` lines: instructions per operation, measured with
//! SysTick under QEMU's instruction counting (`-icount shift=0`: one instruction = 1 ns of
//! virtual time), calibrated against a loop of known length, with each operation's set-up
//! subtracted. The host run has no such
//! lines; `cargo xtask m7-check` compares everything else.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(not(target_os = "none"))]
fn main() -> std::process::ExitCode {
    let mut transcript = String::new();
    if aer_m7_check::run(&mut transcript).is_err() {
        return std::process::ExitCode::FAILURE;
    }
    print!("{transcript}");
    std::process::ExitCode::SUCCESS
}

#[cfg(target_os = "none")]
mod cortex_m7 {
    use core::fmt::Write;
    use core::sync::atomic::{AtomicU32, Ordering};
    use cortex_m::peripheral::{SYST, syst::SystClkSource};
    use cortex_m_rt::{entry, exception};
    use cortex_m_semihosting::{debug, hio};

    const RELOAD: u32 = 0x00FF_FFFF;
    static WRAPS: AtomicU32 = AtomicU32::new(0);

    #[exception]
    fn SysTick() {
        WRAPS.fetch_add(1, Ordering::Relaxed);
    }

    /// SysTick ticks since start (24-bit counter plus counted wraps).
    fn ticks() -> u64 {
        loop {
            let before = WRAPS.load(Ordering::Relaxed);
            let current = SYST::get_current();
            if WRAPS.load(Ordering::Relaxed) == before {
                return u64::from(before) * u64::from(RELOAD + 1) + u64::from(RELOAD - current);
            }
        }
    }

    /// A loop of exactly two instructions per iteration.
    fn spin(iterations: u32) {
        if iterations == 0 {
            return;
        }
        // SAFETY: counts a register down to zero; touches no memory.
        unsafe {
            core::arch::asm!(
                "2:",
                "subs {0}, {0}, #1",
                "bne 2b",
                inout(reg) iterations => _,
                options(nomem, nostack),
            );
        }
    }

    fn measure(run: impl FnOnce()) -> u64 {
        let start = ticks();
        run();
        ticks() - start
    }

    fn costs(out: &mut impl Write) -> core::fmt::Result {
        const CALIBRATION: u32 = 2_000_000;
        let calibration_ticks = measure(|| spin(CALIBRATION));
        if calibration_ticks == 0 {
            return writeln!(out, "cost unavailable (SysTick does not advance)");
        }
        let instructions_per_tick = f64::from(2 * CALIBRATION) / calibration_ticks as f64;
        for cost in &aer_m7_check::COSTS {
            // The same run with no iterations is the set-up alone (a CCM driven into
            // DRIVING, say): only the difference is the operation's cost.
            let elapsed =
                measure(|| (cost.run)(cost.iterations)).saturating_sub(measure(|| (cost.run)(0)));
            let per_op = elapsed as f64 * instructions_per_tick / f64::from(cost.iterations);
            writeln!(out, "cost {}: {:.0} instructions", cost.name, per_op)?;
        }
        Ok(())
    }

    #[entry]
    fn main() -> ! {
        let ok = match (hio::hstdout(), cortex_m::Peripherals::take()) {
            (Ok(mut stdout), Some(mut peripherals)) => {
                peripherals.SYST.set_clock_source(SystClkSource::Core);
                peripherals.SYST.set_reload(RELOAD);
                peripherals.SYST.clear_current();
                peripherals.SYST.enable_interrupt();
                peripherals.SYST.enable_counter();
                aer_m7_check::run(&mut stdout).is_ok() && costs(&mut stdout).is_ok()
            }
            _ => false,
        };
        debug::exit(if ok {
            debug::EXIT_SUCCESS
        } else {
            debug::EXIT_FAILURE
        });
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        if let Ok(mut stderr) = hio::hstderr() {
            let _ = writeln!(stderr, "panic: {info}");
        }
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    }
}
