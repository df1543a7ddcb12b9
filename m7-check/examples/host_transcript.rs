//! Prints the host's transcript of the portable firmware checks, the one `cargo xtask
//! m7-check` compares with the Cortex-M7's under QEMU: `cargo run -p aer-m7-check --example
//! host_transcript`.

fn main() {
    let mut out = String::new();
    if aer_m7_check::run(&mut out).is_err() {
        eprintln!("the host run failed");
        std::process::exit(1);
    }
    print!("{out}");
}
