fn main() {
    if std::env::var_os("CARGO_FEATURE_FIRMWARE").is_some() {
        println!("cargo:rustc-link-arg-bins=-Tt4link.x");
    }
}
