//! Generates, for each benchmarked DBC file, our codec, dbc-codegen 0.4.0's code and cantools'
//! C for the same file, plus small per-message harnesses for the peers (their getters and
//! constructors are per message, so there is no generic way to call them). The C comes from the
//! cantools in the project's venv (`tools/cantools_c_peer.py`; `AER_PYTHON` overrides the
//! interpreter) and is compiled with gcc -O2, harness and codec in one translation unit.

use std::fmt::Write as _;

use heck::{ToSnakeCase, ToUpperCamelCase};
use std::path::{Path, PathBuf};

/// (module name, DBC path relative to this crate).
const DBCS: [(&str, &str); 2] = [
    ("aer", "../schema/aer.dbc"),
    ("vehicle", "../../shared/dbc-corpus/cantools/vehicle.dbc"),
];

fn main() {
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    let mut index = String::new();
    for (name, path) in DBCS {
        println!("cargo::rerun-if-changed={path}");
        let (db, _) = aer_codegen::load_dbc(Path::new(path)).unwrap_or_else(|e| panic!("{e}"));

        let ours = out.join(format!("ours_{name}"));
        std::fs::create_dir_all(&ours).expect("out dir");
        // The codec modules exactly as a generated crate carries them.
        let files = aer_codegen::codec_files(&db, path, "Bench codec.", name).expect("renders");
        for file in files.iter().filter(|f| ["runtime.rs", "can.rs"].contains(&f.path.to_str().unwrap_or_default())) {
            std::fs::write(ours.join(&file.path), &file.content).expect("write");
        }

        let text = aer_codegen::decode_dbc_text(&std::fs::read(path).expect("read DBC"))
            .expect("text");
        let peer = out.join(format!("peer_{name}.rs"));
        dbc_codegen::Config::builder()
            .dbc_name(name)
            .dbc_content(&text)
            .build()
            .write_to_file(&peer)
            .expect("dbc-codegen generates");

        let harness = out.join(format!("peer_harness_{name}.rs"));
        std::fs::write(&harness, peer_harness(&db)).expect("write harness");
        let c = cantools_c(name, path, &out);
        // `#[path]` (not `include!`) so the files keep their inner doc comments and attributes.
        writeln!(
            index,
            "pub mod {name} {{\n  pub mod ours {{\n    #[path = {:?}] pub mod runtime;\n    #[path = {:?}] pub mod can;\n  }}\n  #[path = {:?}] pub mod peer;\n  #[path = {:?}] pub mod peer_harness;\n{c}}}",
            ours.join("runtime.rs"),
            ours.join("can.rs"),
            peer,
            harness
        )
        .expect("write to string");
    }
    std::fs::write(out.join("codecs.rs"), index).expect("write index");
}

/// cantools' C for `dbc`, with its harness, compiled into a static library; declares the
/// harness's functions in `module`.
fn cantools_c(name: &str, dbc: &str, out: &Path) -> String {
    let python = std::env::var("AER_PYTHON").unwrap_or_else(|_| "../.venv/bin/python".to_owned());
    println!("cargo::rerun-if-env-changed=AER_PYTHON");
    println!("cargo::rerun-if-changed=../tools/cantools_c_peer.py");
    let dir = out.join(format!("c_{name}"));
    let status = std::process::Command::new(&python)
        .args(["../tools/cantools_c_peer.py", dbc, name])
        .arg(&dir)
        .status()
        .unwrap_or_else(|e| panic!("running {python} (the project's venv, made by .ci/run: python3 -m venv .venv && .venv/bin/pip install -r tools/requirements.txt): {e}"));
    assert!(status.success(), "cantools could not generate C for {dbc}");
    cc::Build::new()
        .file(dir.join(format!("{name}_harness.c")))
        .include(&dir)
        .opt_level(2)
        // As C users build it: `cc` compiles position-independent code, and with -fPIC gcc may
        // not inline cantools' non-static per-signal functions (another definition could
        // interpose them), so every signal's decode was a call. A static binary or firmware
        // has no interposition; this flag says so while keeping the code linkable into Rust's
        // PIE binaries (which `pic(false)` is not).
        .flag("-fno-semantic-interposition")
        .warnings(false)
        .compile(&format!("cantools_{name}"));
    format!(
        "  pub mod c {{
    unsafe extern \"C\" {{
      pub fn {name}_c_decode(id: u32, extended: i32, data: *const u8, len: usize, sink: *mut f64) -> i32;
      pub fn {name}_c_values(id: u32, extended: i32, data: *const u8, len: usize, values: *mut f64, cap: usize) -> i32;
      pub fn {name}_c_encode(id: u32, extended: i32, values: *const f64, out: *mut u8, size: usize) -> i32;
    }}
    pub use {name}_c_decode as decode;
    pub use {name}_c_values as values;
    pub use {name}_c_encode as encode;
  }}
"
    )
}

/// dbc-codegen's field naming: heck snake case, prefixed with `x` for keywords and names not
/// starting with a letter.
fn peer_name(name: &str, camel: bool) -> String {
    let cased = if camel {
        name.to_upper_camel_case()
    } else {
        name.to_snake_case()
    };
    if !name.starts_with(|c: char| c.is_ascii_alphabetic()) || KEYWORDS.contains(&name) {
        format!("x{cased}")
    } else {
        cased
    }
}

const KEYWORDS: [&str; 5] = ["type", "match", "move", "ref", "self"];

/// `decode(id, data)`: parse and call every getter; `prepare(id, data)`: a closure that builds
/// the message from its physical values with `new` (what encoding is, for dbc-codegen).
fn peer_harness(db: &aer_codegen::model::Database) -> String {
    let mut decode = String::new();
    let mut prepare = String::new();
    for m in db
        .messages
        .iter()
        .filter(|m| m.signals.iter().all(|s| s.mux.is_none()))
    {
        let ty = peer_name(&m.name, true);
        let getters: Vec<String> = m
            .signals
            .iter()
            .map(|s| format!("m.{}()", peer_name(&s.name, false)))
            .collect();
        let _ = writeln!(
            decode,
            "      Ok(super::peer::Messages::{ty}(m)) => {{ {} }}",
            getters
                .iter()
                .map(|g| format!("black_box({g});"))
                .collect::<String>()
        );
        let args: Vec<String> = (0..getters.len()).map(|i| format!("v.{i}")).collect();
        let _ = writeln!(
            prepare,
            "      Ok(super::peer::Messages::{ty}(m)) => {{ let v = ({},); Some(Box::new(move |out: &mut [u8]| match super::peer::{ty}::new({}) {{ Ok(x) => {{ out[..x.raw().len()].copy_from_slice(x.raw()); x.raw().len() }} Err(_) => 0 }})) }}",
            getters.join(", "),
            args.join(", ")
        );
    }
    format!(
        "    use core::hint::black_box;\n    pub fn decode(id: embedded_can::Id, data: &[u8]) {{\n      match super::peer::Messages::from_can_message(id, data) {{\n{decode}      _ => {{}}\n      }}\n    }}\n    #[allow(clippy::type_complexity)]\n    pub fn prepare(id: embedded_can::Id, data: &[u8]) -> Option<Box<dyn Fn(&mut [u8]) -> usize>> {{\n      match super::peer::Messages::from_can_message(id, data) {{\n{prepare}      _ => None,\n      }}\n    }}\n"
    )
}
