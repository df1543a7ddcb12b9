//! A tier that was not updated after a schema change fails to compile instead of mis-decoding:
//! a new telemetry field must be filled by the firmware, a topic only takes its own payload type,
//! and code using a removed signal stops building. (`TRYBUILD=overwrite` refreshes the expected
//! compiler output after an intended change.)

#[test]
fn stale_code_does_not_compile() {
    let cases = trybuild::TestCases::new();
    cases.compile_fail("tests/compile_fail/*.rs");
}
