//! Both codecs for each benchmarked DBC file, generated at build time (see build.rs): nothing
//! generated here is committed.
#![allow(clippy::all, dead_code, unused_imports, non_camel_case_types)]

include!(concat!(env!("OUT_DIR"), "/codecs.rs"));
