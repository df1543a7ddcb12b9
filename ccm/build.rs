//! Links the firmware images, turns `calibration.toml` (the car's measured sensor
//! calibration) into `MEASURED`, the constant the firmware images start with, and reads the
//! team's XCP secret (`xcp-secret.key`, never committed) into `XCP_SECRET`.

use std::fmt::Write as _;
use std::path::Path;

fn main() {
    if std::env::var_os("CARGO_FEATURE_FIRMWARE").is_some() {
        println!("cargo:rustc-link-arg-bins=-Tt4link.x");
    }
    println!("cargo:rerun-if-changed=calibration.toml");
    let out = std::env::var_os("OUT_DIR").map(std::path::PathBuf::from);
    let Some(out) = out else {
        fail("OUT_DIR is not set");
    };
    match measured(Path::new("calibration.toml")) {
        Ok(code) => {
            if let Err(error) = std::fs::write(out.join("measured_calibration.rs"), code) {
                fail(&format!("writing measured_calibration.rs: {error}"));
            }
        }
        Err(error) => fail(&format!("ccm/calibration.toml: {error}")),
    }
    let code = match xcp_secret() {
        Ok(code) => code,
        Err(error) => fail(&error),
    };
    if let Err(error) = std::fs::write(out.join("xcp_secret.rs"), code) {
        fail(&format!("writing xcp_secret.rs: {error}"));
    }
}

/// The team's secret for the XCP seed and key: 64 hex digits in the file `AER_XCP_SECRET_FILE`
/// names, or `xcp-secret.key` beside this script (ignored by git). Without one the images are
/// built locked: they measure, but no key unlocks calibration.
fn xcp_secret() -> Result<String, String> {
    println!("cargo:rerun-if-env-changed=AER_XCP_SECRET_FILE");
    let path = std::env::var_os("AER_XCP_SECRET_FILE")
        .map_or_else(|| Path::new("xcp-secret.key").to_path_buf(), Into::into);
    // Cargo takes a missing file as changed on every build: watch the folder it would appear
    // in instead, so a build without a secret is fresh the second time.
    let watched = if path.exists() {
        path.clone()
    } else {
        match path.parent() {
            Some(parent) if !parent.as_os_str().is_empty() => parent.to_path_buf(),
            _ => Path::new(".").to_path_buf(),
        }
    };
    println!("cargo:rerun-if-changed={}", watched.display());
    let text = match std::fs::read_to_string(&path) {
        Ok(text) => text,
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => {
            if std::env::var_os("CARGO_FEATURE_FIRMWARE").is_some() {
                println!(
                    "cargo:warning=no XCP secret ({}): this image measures but can never be unlocked for calibration (docs/calibration.md, \"The secret\")",
                    path.display()
                );
            }
            return Ok(
                "/// No secret was given at build time: calibration stays locked.\n\
                       pub const XCP_SECRET: Option<[u8; 32]> = None;\n"
                    .into(),
            );
        }
        Err(error) => return Err(format!("{}: {error}", path.display())),
    };
    let hex = text.trim();
    if hex.len() != 64 || !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(format!(
            "{}: expected 64 hex digits (32 bytes), e.g. from `openssl rand -hex 32`",
            path.display()
        ));
    }
    let mut bytes = String::new();
    for pair in hex.as_bytes().chunks(2) {
        let digits = std::str::from_utf8(pair).map_err(|error| error.to_string())?;
        let byte = u8::from_str_radix(digits, 16).map_err(|error| error.to_string())?;
        let _ = write!(bytes, "0x{byte:02X}, ");
    }
    Ok(format!(
        "/// The team's secret, from {} at build time.\npub const XCP_SECRET: Option<[u8; 32]> = Some([{bytes}]);\n",
        path.display()
    ))
}

fn fail(message: &str) -> ! {
    println!("cargo:warning={message}");
    eprintln!("{message}");
    std::process::exit(1);
}

/// The file as Rust: the source text and the calibration. The values' bands are checked by
/// the library (`SensorCalibration::check`), in the firmware images at compile time.
fn measured(path: &Path) -> Result<String, String> {
    let text = std::fs::read_to_string(path).map_err(|error| error.to_string())?;
    let table: toml::Table = text.parse().map_err(|error| format!("{error}"))?;
    let known = ["source", "pedals", "brakes", "shocks"];
    if let Some(key) = table.keys().find(|key| !known.contains(&key.as_str())) {
        return Err(format!("unknown key `{key}` (expected {known:?})"));
    }
    let source = match table.get("source") {
        Some(toml::Value::String(source)) => source.clone(),
        Some(_) => return Err("`source` must be a string".into()),
        None => return Err("`source` is missing: say where the values came from".into()),
    };
    let pedals = section(&table, "pedals", &["apps1", "apps2"])?;
    let brakes = section(&table, "brakes", &["front_zero_v", "rear_zero_v"])?;
    let corners = ["fl", "fr", "rl", "rr"];
    let shocks = section(&table, "shocks", &corners)?;
    let pedal = |name: &str| -> Result<(f64, f64), String> {
        let point = match pedals.get(name) {
            Some(toml::Value::Table(point)) => point,
            _ => {
                return Err(format!(
                    "[pedals] `{name}` must be {{ rest_v = .., full_v = .. }}"
                ));
            }
        };
        if let Some(key) = point
            .keys()
            .find(|key| !["rest_v", "full_v"].contains(&key.as_str()))
        {
            return Err(format!("[pedals] {name}: unknown key `{key}`"));
        }
        Ok((
            volts(point, "rest_v", &format!("[pedals] {name}"))?,
            volts(point, "full_v", &format!("[pedals] {name}"))?,
        ))
    };
    let (apps1, apps2) = (pedal("apps1")?, pedal("apps2")?);
    let front = volts(brakes, "front_zero_v", "[brakes]")?;
    let rear = volts(brakes, "rear_zero_v", "[brakes]")?;
    let mut extended = Vec::new();
    let mut compressed = Vec::new();
    for corner in corners {
        let place = format!("[shocks] {corner}");
        let ends = match shocks.get(corner) {
            Some(toml::Value::Table(ends)) => ends,
            _ => {
                return Err(format!(
                    "{place} must be {{ extended_v = .., compressed_v = .. }}"
                ));
            }
        };
        if let Some(key) = ends
            .keys()
            .find(|key| !["extended_v", "compressed_v"].contains(&key.as_str()))
        {
            return Err(format!("{place}: unknown key `{key}`"));
        }
        extended.push(volts(ends, "extended_v", &place)? as f32);
        compressed.push(volts(ends, "compressed_v", &place)? as f32);
    }
    let mut code = String::new();
    let _ = write!(
        code,
        "/// Where `MEASURED` came from (`calibration.toml`'s `source`).\n\
         pub const SOURCE: &str = {source:?};\n\
         /// The car's measured sensor calibration (`calibration.toml`).\n\
         pub const MEASURED: SensorCalibration = SensorCalibration {{\n    \
         pedals: AppsCalibration {{\n        \
         apps1: ({:?}, {:?}),\n        apps2: ({:?}, {:?}),\n    }},\n    \
         brakes: BrakeCalibration {{\n        \
         front_zero_v: {:?},\n        rear_zero_v: {:?},\n    }},\n    \
         shocks: ShockCalibration {{\n        \
         extended_v: {extended:?},\n        compressed_v: {compressed:?},\n    }},\n}};\n",
        apps1.0 as f32, apps1.1 as f32, apps2.0 as f32, apps2.1 as f32, front as f32, rear as f32
    );
    Ok(code)
}

fn section<'a>(
    table: &'a toml::Table,
    name: &str,
    keys: &[&str],
) -> Result<&'a toml::Table, String> {
    let Some(toml::Value::Table(section)) = table.get(name) else {
        return Err(format!("the [{name}] section is missing"));
    };
    if let Some(key) = section.keys().find(|key| !keys.contains(&key.as_str())) {
        return Err(format!("[{name}]: unknown key `{key}` (expected {keys:?})"));
    }
    Ok(section)
}

fn volts(table: &toml::Table, key: &str, place: &str) -> Result<f64, String> {
    match table.get(key) {
        Some(toml::Value::Float(volts)) if volts.is_finite() => Ok(*volts),
        Some(toml::Value::Integer(volts)) => Ok(*volts as f64),
        Some(_) => Err(format!("{place} `{key}` must be a number of volts")),
        None => Err(format!("{place} `{key}` is missing")),
    }
}
