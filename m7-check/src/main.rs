//! Prints the check transcript: to stdout on the host, through semihosting on the Cortex-M7
//! (QEMU: `-semihosting-config enable=on,target=native`), exiting non-zero on failure.
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
    use cortex_m_rt::entry;
    use cortex_m_semihosting::{debug, hio};

    #[entry]
    fn main() -> ! {
        let ok = match hio::hstdout() {
            Ok(mut stdout) => aer_m7_check::run(&mut stdout).is_ok(),
            Err(()) => false,
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
            use core::fmt::Write;
            let _ = writeln!(stderr, "panic: {info}");
        }
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    }
}
