//! Every kind of schema mistake gets a diagnostic naming the file, the line, what is wrong and
//! how to fix it.

use std::path::Path;

use aer_codegen::diagnostic::{Diagnostic, Severity};

const HEADER: &str = "VERSION \"\"\n\nNS_ :\n\tCM_\n\nBS_:\n\nBU_: ECU\n\n";

/// Lines of `HEADER`, so tests can give line numbers relative to their own text.
fn header_lines() -> usize {
    HEADER.lines().count()
}

/// Loads and validates `body` (appended to a minimal header); returns every diagnostic.
fn diagnose(body: &str) -> Vec<Diagnostic> {
    let text = format!("{HEADER}{body}");
    let path = Path::new("car.dbc");
    match aer_codegen::parse_dbc(path, text, &[]) {
        Ok((_, warnings)) => warnings,
        Err(d) => d.0,
    }
}

/// Asserts one diagnostic with `code` at `line` (of `body`, 1-based) whose message contains
/// every fragment, and returns it.
fn expect(body: &str, code: &str, line: usize, fragments: &[&str]) -> Diagnostic {
    let diags = diagnose(body);
    let d = diags
        .iter()
        .find(|d| d.code == code)
        .unwrap_or_else(|| panic!("no {code} in {diags:#?}"))
        .clone();
    assert_eq!(d.line, header_lines() + line, "line of {d:#?}");
    assert_eq!(d.file, Path::new("car.dbc"));
    for f in fragments {
        assert!(d.message.contains(f), "{f:?} not in {:?}", d.message);
    }
    assert!(!d.help.is_empty(), "a diagnostic must say how to fix it");
    let shown = d.to_string();
    assert!(shown.contains(&format!("car.dbc:{}", d.line)), "{shown}");
    assert!(shown.contains(&format!("[{code}]")), "{shown}");
    d
}

#[test]
fn syntax_errors_point_at_the_line() {
    let d = expect(
        "BO_ 100 M: 8 ECU\n SG_ A : 0|8@1+ (1,0) [0|1 \"\" ECU\n",
        "E0003",
        2,
        &["DBC syntax is invalid"],
    );
    assert_eq!(d.severity, Severity::Error);
}

#[test]
fn standard_id_above_11_bits() {
    expect(
        "BO_ 2048 M: 8 ECU\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" ECU\n",
        "E0101",
        1,
        &["standard id 0x800", "11-bit"],
    );
}

#[test]
fn extended_id_above_29_bits() {
    expect(
        "BO_ 4294967295 M: 8 ECU\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" ECU\n",
        "E0101",
        1,
        &["extended id 0x7FFFFFFF", "29-bit"],
    );
}

#[test]
fn duplicate_ids() {
    expect(
        "BO_ 100 A: 8 ECU\n SG_ X : 0|8@1+ (1,0) [0|0] \"\" ECU\n\nBO_ 100 B: 8 ECU\n SG_ Y : 0|8@1+ (1,0) [0|0] \"\" ECU\n",
        "E0102",
        4,
        &["`B` reuses id 0x64", "line 10"],
    );
}

#[test]
fn duplicate_message_names() {
    expect(
        "BO_ 100 Same: 8 ECU\n SG_ X : 0|8@1+ (1,0) [0|0] \"\" ECU\n\nBO_ 101 Same: 8 ECU\n SG_ Y : 0|8@1+ (1,0) [0|0] \"\" ECU\n",
        "E0103",
        4,
        &["`Same` is already used"],
    );
}

#[test]
fn frames_longer_than_can_fd() {
    expect(
        "BO_ 100 M: 65 ECU\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" ECU\n",
        "E0104",
        1,
        &["65 bytes"],
    );
}

#[test]
fn signal_lengths_outside_1_to_64() {
    expect(
        "BO_ 100 M: 8 ECU\n SG_ Zero : 0|0@1+ (1,0) [0|0] \"\" ECU\n",
        "E0105",
        2,
        &["`Zero`", "0 bits"],
    );
    expect(
        "BO_ 100 M: 64 ECU\n SG_ Huge : 0|65@1+ (1,0) [0|0] \"\" ECU\n",
        "E0105",
        2,
        &["65 bits"],
    );
}

#[test]
fn bits_outside_the_frame_intel_and_motorola() {
    expect(
        "BO_ 100 M: 2 ECU\n SG_ Ok : 0|8@1+ (1,0) [0|0] \"\" ECU\n SG_ Past : 12|8@1+ (1,0) [0|0] \"\" ECU\n",
        "E0106",
        3,
        &["`Past`", "outside the 2-byte frame"],
    );
    // Motorola 16 bits from bit 0: the MSB is bit 0 of byte 0, so it runs into byte 2.
    let d = expect(
        "BO_ 100 M: 2 ECU\n SG_ Moto : 0|16@0+ (1,0) [0|0] \"\" ECU\n",
        "E0106",
        2,
        &["`Moto`", "(0|16@0)"],
    );
    assert!(d.help.contains("sawtooth"), "{}", d.help);
}

#[test]
fn overlapping_signals() {
    expect(
        "BO_ 100 M: 8 ECU\n SG_ A : 0|12@1+ (1,0) [0|0] \"\" ECU\n SG_ B : 8|8@1+ (1,0) [0|0] \"\" ECU\n",
        "E0107",
        3,
        &["`A` and `B`", "[8, 9, 10, 11]"],
    );
}

/// Three signals and one laid over all of them.
const WIDE: &str = "BO_ 100 M: 8 ECU\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" ECU\n SG_ B : 8|8@1+ (1,0) [0|0] \"\" ECU\n SG_ C : 16|8@1+ (1,0) [0|0] \"\" ECU\n SG_ Wide : 0|32@1+ (1,0) [0|0] \"\" ECU\n";

/// A signal laid over several others is one finding naming every one, not only the first.
#[test]
fn a_signal_over_several_others_names_them_all() {
    let d = expect(
        WIDE,
        "E0107",
        5,
        &[
            "`Wide` of message `M` overlaps 3 signals",
            "`A` in bit(s) [0, 1, 2, 3, 4, 5, 6, 7]",
            "`B` in bit(s) [8,",
            "`C` in bit(s) [16,",
        ],
    );
    let findings = diagnose(WIDE).iter().filter(|d| d.code == "E0107").count();
    assert_eq!(findings, 1, "{d}");
}

#[test]
fn multiplexed_alternatives_may_share_bits() {
    let diags = diagnose(
        "BO_ 100 M: 8 ECU\n SG_ Sel M : 0|8@1+ (1,0) [0|0] \"\" ECU\n SG_ A m0 : 8|8@1+ (1,0) [0|0] \"\" ECU\n SG_ B m1 : 8|16@1+ (1,0) [0|0] \"\" ECU\n",
    );
    assert!(diags.is_empty(), "{diags:#?}");
}

#[test]
fn duplicate_signal_names() {
    expect(
        "BO_ 100 M: 8 ECU\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" ECU\n SG_ A : 8|8@1+ (1,0) [0|0] \"\" ECU\n",
        "E0108",
        3,
        // The first definition is the line before.
        &[
            "`A` is defined twice",
            &format!("(first on line {})", header_lines() + 2),
        ],
    );
}

#[test]
fn ieee_float_of_the_wrong_length() {
    expect(
        "BO_ 100 M: 8 ECU\n SG_ F : 0|16@1- (1,0) [0|0] \"\" ECU\n\nSIG_VALTYPE_ 100 F : 1;\n",
        "E0112",
        4,
        &["IEEE float (32 bits)", "16 bits long"],
    );
}

#[test]
fn zero_factor() {
    expect(
        "BO_ 100 M: 8 ECU\n SG_ Z : 0|8@1+ (0,0) [0|0] \"\" ECU\n",
        "E0113",
        2,
        &["factor 0"],
    );
}

#[test]
fn multiplexed_signal_without_multiplexor() {
    expect(
        "BO_ 100 M: 8 ECU\n SG_ A m1 : 8|8@1+ (1,0) [0|0] \"\" ECU\n",
        "E0114",
        2,
        &["no multiplexor"],
    );
}

#[test]
fn extended_multiplexing_naming_an_unknown_multiplexor() {
    expect(
        "BO_ 100 M: 8 ECU\n SG_ Sel M : 0|8@1+ (1,0) [0|0] \"\" ECU\n SG_ A m1 : 8|8@1+ (1,0) [0|0] \"\" ECU\n\nSG_MUL_VAL_ 100 A Nope 1-1;\n",
        "E0114",
        5,
        &["`Nope`"],
    );
}

#[test]
fn minimum_above_maximum() {
    expect(
        "BO_ 100 M: 8 ECU\n SG_ R : 0|8@1+ (1,0) [10|5] \"\" ECU\n",
        "E0115",
        2,
        &["minimum 10 above its maximum 5"],
    );
}

#[test]
fn multiplexor_values_it_cannot_take() {
    expect(
        "BO_ 100 M: 8 ECU\n SG_ Sel M : 0|2@1+ (1,0) [0|0] \"\" ECU\n SG_ A m7 : 8|8@1+ (1,0) [0|0] \"\" ECU\n",
        "E0116",
        3,
        &["values 7-7", "2-bit multiplexor"],
    );
}

#[test]
fn f32_requested_for_a_wide_signal() {
    expect(
        "BO_ 100 M: 8 ECU\n SG_ W : 0|32@1+ (0.1,0) [0|0] \"\" ECU\n\nBA_DEF_ SG_ \"AerPhysType\" STRING ;\nBA_ \"AerPhysType\" SG_ 100 W \"f32\";\n",
        "E0118",
        5,
        &["f32", "24-bit mantissa"],
    );
}

#[test]
fn warnings_for_what_vendor_files_get_wrong() {
    let keyword = expect(
        "BO_ 100 M: 8 ECU\n SG_ type : 0|8@1+ (1,0) [0|0] \"\" ECU\n",
        "W0201",
        2,
        &["`type_`"],
    );
    assert_eq!(keyword.severity, Severity::Warning);
    expect(
        "BO_ 100 M: 8 ECU\n SG_ Pct : 0|8@1+ (1,0) [0|300] \"%\" ECU\n",
        "W0202",
        2,
        &["[0|300]", "[0|255]"],
    );
    expect(
        "BO_ 100 M: 8 ECU\n SG_ E : 0|2@1+ (1,0) [0|0] \"\" ECU\n\nVAL_ 100 E 9 \"NINE\" 1 \"ONE\" ;\n",
        "W0203",
        4,
        &["value 9 (`NINE`)"],
    );
    expect(
        "BO_ 100 M: 8 ECU\n SG_ FooBar : 0|8@1+ (1,0) [0|0] \"\" ECU\n SG_ foo_bar : 8|8@1+ (1,0) [0|0] \"\" ECU\n",
        "W0204",
        3,
        &["`foo_bar`"],
    );
}

#[test]
fn the_car_schema_denies_warnings() {
    let dir = tempfile::tempdir().expect("temp dir");
    std::fs::write(
        dir.path().join("aer.dbc"),
        format!("{HEADER}BO_ 100 M: 8 ECU\n SG_ type : 0|8@1+ (1,0) [0|0] \"\" ECU\n"),
    )
    .expect("write");
    let err = aer_codegen::generate_contract(dir.path(), &dir.path().join("out"))
        .expect_err("a warning must fail the car's build");
    let text = err.to_string();
    assert!(text.contains("warnings are denied"), "{text}");
    assert!(text.contains("W0201"), "{text}");
    assert!(
        !dir.path().join("out").exists(),
        "nothing may be written for a rejected schema"
    );
}

#[test]
fn the_cli_prints_the_same_diagnostics_and_fails() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("bad.dbc");
    std::fs::write(
        &path,
        format!("{HEADER}BO_ 100 M: 2 ECU\n SG_ Past : 12|8@1+ (1,0) [0|0] \"\" ECU\n"),
    )
    .expect("write");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_aer-codegen"))
        .arg("check")
        .arg(&path)
        .output()
        .expect("run aer-codegen");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let expected = aer_codegen::load_dbc(&path)
        .expect_err("invalid")
        .to_string();
    assert!(stderr.contains(&expected), "{stderr}\n---\n{expected}");
    assert!(
        stderr.contains(&format!("{}:{}", path.display(), header_lines() + 2)),
        "{stderr}"
    );
}

#[test]
fn a_file_without_messages_is_a_warning_and_the_cars_schema_refuses_it() {
    let diags = diagnose("");
    assert_eq!(diags.len(), 1, "{diags:#?}");
    assert_eq!(diags[0].code, "W0206");
    assert_eq!(diags[0].severity, Severity::Warning);

    let dir = tempfile::tempdir().expect("temp dir");
    std::fs::write(dir.path().join("aer.dbc"), HEADER).expect("dbc");
    match aer_codegen::CarSchema::load(dir.path()) {
        Err(aer_codegen::Error::DeniedWarnings(warnings)) => {
            assert!(warnings.iter().any(|w| w.code == "W0206"), "{warnings:#?}");
        }
        Err(other) => panic!("expected the warning denied, got {other}"),
        Ok(_) => panic!("an empty schema must not load as the car's"),
    }
}

/// A DBC with a node that declares its id in its messages' CAN ids (`NodeIdInCanId` 0x41) and
/// `messages` between it and a node without one.
fn with_node_id(messages: &str) -> Vec<Diagnostic> {
    let text = format!(
        "VERSION \"\"\n\nNS_ :\n\tCM_\n\nBS_:\n\nBU_: CCM DTI\n\n{messages}\n\
         BA_DEF_ BU_  \"NodeIdInCanId\" INT 0 255;\nBA_DEF_DEF_  \"NodeIdInCanId\" 0;\n\
         BA_ \"NodeIdInCanId\" BU_ DTI 65;\n"
    );
    let path = Path::new("car.dbc");
    match aer_codegen::parse_dbc(path, text, &[]) {
        Ok((_, warnings)) => warnings,
        Err(d) => d.0,
    }
}

#[test]
fn an_extended_id_without_its_nodes_declared_id_is_refused() {
    // 0x80000000 + 0x2442: packet 0x24 of node 0x42 sent by DTI, and a command to DTI with
    // node 0x65 in it, where DTI declares 0x41.
    // And a command written without the extended flag: a standard 0x141 would never reach it.
    let diags = with_node_id(
        "BO_ 2147492930 Flags: 8 DTI\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" CCM\n\n\
         BO_ 2147486821 Enable: 1 CCM\n SG_ B : 0|8@1+ (1,0) [0|0] \"\" DTI\n\n\
         BO_ 321 Current: 2 CCM\n SG_ C : 0|16@1+ (1,0) [0|0] \"\" DTI\n",
    );
    let refused: Vec<_> = diags.iter().filter(|d| d.code == "E0119").collect();
    assert_eq!(refused.len(), 3, "{diags:#?}");
    assert!(
        refused[2]
            .message
            .contains("`Current` has the standard id 0x141, but node `DTI` declares"),
        "{diags:#?}"
    );
    assert_eq!(refused[0].severity, Severity::Error);
    assert!(
        refused[0]
            .message
            .contains("`Flags` (id 0x2442) carries node id 0x42")
    );
    assert!(
        refused[0]
            .message
            .contains("node `DTI` declares NodeIdInCanId 0x41")
    );
    assert!(
        refused[1]
            .message
            .contains("`Enable` (id 0xC65) carries node id 0x65")
    );
}

#[test]
fn ids_that_carry_the_declared_node_id_pass_and_other_messages_are_not_checked() {
    // Packet 0x24 from DTI and packet 0x0C to it, both with 0x41; messages between nodes that
    // declare nothing (standard or extended) are not the rule's business.
    let diags = with_node_id(
        "BO_ 2147492929 Flags: 8 DTI\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" CCM\n\n\
         BO_ 2147486785 Enable: 1 CCM\n SG_ B : 0|8@1+ (1,0) [0|0] \"\" DTI\n\n\
         BO_ 100 Status: 8 CCM\n SG_ C : 0|8@1+ (1,0) [0|0] \"\" Vector__XXX\n\n\
         BO_ 2147483904 Other: 8 CCM\n SG_ D : 0|8@1+ (1,0) [0|0] \"\" Vector__XXX\n",
    );
    assert!(
        diags.iter().all(|d| d.severity != Severity::Error),
        "{diags:#?}"
    );
}

/// `messages` with the counter, checksum and send-type attributes defined.
fn with_integrity(messages: &str, values: &str) -> Vec<Diagnostic> {
    let text = format!(
        "VERSION \"\"\n\nNS_ :\n\tCM_\n\nBS_:\n\nBU_: CCM INV\n\n{messages}\n\
         BA_DEF_ SG_  \"ChecksumAlgorithm\" ENUM  \"None\",\"SumXorFF\",\"Crc8SaeJ1850\";\n\
         BA_DEF_ SG_  \"CounterStep\" INT 0 255;\n\
         BA_DEF_ BO_  \"GenMsgCycleTime\" INT 0 65535;\n\
         BA_DEF_ BO_  \"GenMsgSendType\" ENUM  \"Cyclic\",\"NoMsgSendType\";\n\
         BA_DEF_DEF_  \"ChecksumAlgorithm\" \"None\";\nBA_DEF_DEF_  \"CounterStep\" 0;\n\
         BA_DEF_DEF_  \"GenMsgCycleTime\" 0;\nBA_DEF_DEF_  \"GenMsgSendType\" \"Cyclic\";\n{values}"
    );
    let path = Path::new("car.dbc");
    match aer_codegen::parse_dbc(path, text, &[]) {
        Ok((_, warnings)) => warnings,
        Err(d) => d.0,
    }
}

const INTEGRITY_MESSAGES: &str = "BO_ 257 Cmd: 8 CCM\n SG_ Torque : 0|8@1+ (1,0) [0|255] \"\" INV\n \
     SG_ Counter : 8|4@1+ (1,0) [0|15] \"\" INV\n SG_ Wide : 16|12@1+ (1,0) [0|0] \"\" INV\n \
     SG_ Scaled : 28|4@1+ (2,0) [0|30] \"\" INV\n SG_ Sum : 56|8@1+ (1,0) [0|255] \"\" INV\n \
     SG_ Split : 36|8@1+ (1,0) [0|255] \"\" INV\n";

#[test]
fn counters_and_checksums_the_codec_can_keep_pass() {
    let diags = with_integrity(
        INTEGRITY_MESSAGES,
        "BA_ \"CounterStep\" SG_ 257 Counter 1;\nBA_ \"ChecksumAlgorithm\" SG_ 257 Sum 1;\n",
    );
    assert!(diags.is_empty(), "{diags:#?}");
    // The model carries them: the counter's signal and step, the checksum's byte.
    let text = format!(
        "VERSION \"\"\n\nNS_ :\n\tCM_\n\nBS_:\n\nBU_: CCM INV\n\n{INTEGRITY_MESSAGES}\n\
        BA_DEF_ SG_  \"ChecksumAlgorithm\" STRING ;\nBA_DEF_ SG_  \"CounterStep\" INT 0 255;\n\
        BA_DEF_DEF_  \"ChecksumAlgorithm\" \"None\";\nBA_DEF_DEF_  \"CounterStep\" 0;\n\
        BA_ \"CounterStep\" SG_ 257 Counter 3;\nBA_ \"ChecksumAlgorithm\" SG_ 257 Sum \"Crc8SaeJ1850\";\n"
    );
    let path = Path::new("car.dbc");
    let (db, _) = aer_codegen::parse_dbc(path, text, &[]).expect("valid");
    let m = &db.messages[0];
    let counter = m.counter.expect("counter");
    assert_eq!(
        (m.signals[counter.signal].name.as_str(), counter.step),
        ("Counter", 3)
    );
    let checksum = m.checksum.expect("checksum");
    assert_eq!(checksum.byte, 7);
    assert_eq!(
        checksum.algorithm,
        aer_codegen::model::ChecksumAlgorithm::Crc8SaeJ1850,
        "a STRING attribute names the algorithm too"
    );
}

#[test]
fn counters_the_codec_cannot_keep_are_refused() {
    let line_of = |signal: &str| {
        INTEGRITY_MESSAGES
            .lines()
            .position(|l| l.contains(&format!("SG_ {signal} ")))
            .expect("signal")
            + 1
            + header_lines()
    };
    for (values, signal, fragment) in [
        (
            "BA_ \"CounterStep\" SG_ 257 Wide 1;\n",
            "Wide",
            "12 bits wide",
        ),
        (
            "BA_ \"CounterStep\" SG_ 257 Scaled 1;\n",
            "Scaled",
            "factor 1",
        ),
        (
            "BA_ \"CounterStep\" SG_ 257 Counter 16;\n",
            "Counter",
            "step 16 does not fit its 4 bits",
        ),
        (
            "BA_ \"CounterStep\" SG_ 257 Counter 1;\nBA_ \"CounterStep\" SG_ 257 Torque 1;\n",
            "Counter",
            "second rolling counter",
        ),
    ] {
        let diags = with_integrity(INTEGRITY_MESSAGES, values);
        let d = diags
            .iter()
            .find(|d| d.code == "E0120")
            .unwrap_or_else(|| panic!("no E0120 for {values}: {diags:#?}"));
        assert!(
            d.message.contains(fragment),
            "{fragment:?} not in {:?}",
            d.message
        );
        assert_eq!(d.severity, Severity::Error);
        if !fragment.starts_with("second") {
            assert_eq!(d.line, line_of(signal), "{d:#?}");
        }
    }
}

#[test]
fn checksums_the_codec_cannot_compute_are_refused() {
    for (values, fragment) in [
        (
            "BA_ \"ChecksumAlgorithm\" SG_ 257 Split 1;\n",
            "not one whole byte",
        ),
        (
            "BA_ \"ChecksumAlgorithm\" SG_ 257 Counter 1;\n",
            "not one whole byte",
        ),
        ("BA_ \"ChecksumAlgorithm\" SG_ 257 Scaled 2;\n", "factor 1"),
        (
            "BA_ \"ChecksumAlgorithm\" SG_ 257 Sum 1;\nBA_ \"ChecksumAlgorithm\" SG_ 257 Torque 1;\n",
            "second checksum",
        ),
    ] {
        let diags = with_integrity(INTEGRITY_MESSAGES, values);
        let d = diags
            .iter()
            .find(|d| d.code == "E0121")
            .unwrap_or_else(|| panic!("no E0121 for {values}: {diags:#?}"));
        assert!(
            d.message.contains(fragment),
            "{fragment:?} not in {:?}",
            d.message
        );
    }
    // An algorithm the generator does not know (an ENUM index past the list).
    let diags = with_integrity(
        INTEGRITY_MESSAGES,
        "BA_ \"ChecksumAlgorithm\" SG_ 257 Sum 7;\n",
    );
    let d = diags
        .iter()
        .find(|d| d.code == "E0121")
        .unwrap_or_else(|| panic!("no E0121: {diags:#?}"));
    assert!(d.message.contains("algorithm `#7`"), "{}", d.message);
    assert!(d.help.contains("SumXorFF, Crc8SaeJ1850"), "{}", d.help);
}

#[test]
fn a_cycle_time_on_a_message_sent_on_demand_is_a_warning() {
    let diags = with_integrity(
        INTEGRITY_MESSAGES,
        "BA_ \"GenMsgCycleTime\" BO_ 257 20;\nBA_ \"GenMsgSendType\" BO_ 257 1;\n",
    );
    let d = diags
        .iter()
        .find(|d| d.code == "W0209")
        .unwrap_or_else(|| panic!("no W0209: {diags:#?}"));
    assert_eq!(d.severity, Severity::Warning);
    assert!(
        d.message.contains("`Cmd` is sent on demand"),
        "{}",
        d.message
    );
    assert_eq!(d.line, header_lines() + 1);
    // Cyclic with a cycle time, or on demand without one: nothing to say.
    for values in [
        "BA_ \"GenMsgCycleTime\" BO_ 257 20;\n",
        "BA_ \"GenMsgSendType\" BO_ 257 1;\n",
    ] {
        let diags = with_integrity(INTEGRITY_MESSAGES, values);
        assert!(
            diags.iter().all(|d| d.code != "W0209"),
            "{values}: {diags:#?}"
        );
    }
}

#[test]
fn a_bus_the_schema_overloads_is_a_warning_naming_its_load() {
    // Three 8-byte frames every millisecond: 3 x 135 bits x 1,000 /s = 405 kbit/s of 500.
    let messages = "BO_ 1 A: 8 CCM\n SG_ a : 0|8@1+ (1,0) [0|255] \"\" INV\n\n\
                    BO_ 2 B: 8 CCM\n SG_ b : 0|8@1+ (1,0) [0|255] \"\" INV\n\n\
                    BO_ 3 C: 8 CCM\n SG_ c : 0|8@1+ (1,0) [0|255] \"\" INV\n";
    let cycles = "BA_ \"GenMsgCycleTime\" BO_ 1 1;\nBA_ \"GenMsgCycleTime\" BO_ 2 1;\n\
                  BA_ \"GenMsgCycleTime\" BO_ 3 1;\n";
    let diags = with_integrity(messages, cycles);
    let d = diags
        .iter()
        .find(|d| d.code == "W0210")
        .unwrap_or_else(|| panic!("no W0210: {diags:#?}"));
    assert_eq!(d.severity, Severity::Warning);
    assert!(
        d.message.contains("bus `CAN` is 81 % loaded") && d.message.contains("405.0 kbit/s"),
        "{}",
        d.message
    );
    // Spread over two buses (AerBus), or at 10 ms, neither is above 50 %.
    let spread = format!(
        "{cycles}BA_DEF_ BO_  \"AerBus\" STRING ;\nBA_DEF_DEF_  \"AerBus\" \"\";\n\
         BA_ \"AerBus\" BO_ 1 \"one\";\nBA_ \"AerBus\" BO_ 2 \"two\";\nBA_ \"AerBus\" BO_ 3 \"two\";\n"
    );
    let diags = with_integrity(messages, &spread);
    let d = diags
        .iter()
        .find(|d| d.code == "W0210")
        .unwrap_or_else(|| panic!("no W0210: {diags:#?}"));
    assert!(
        d.message.contains("bus `two` is 54 % loaded"),
        "{}",
        d.message
    );
    assert_eq!(
        diags.iter().filter(|d| d.code == "W0210").count(),
        1,
        "{diags:#?}"
    );
    let relaxed = cycles.replace(" 1;\n", " 10;\n");
    let diags = with_integrity(messages, &relaxed);
    assert!(diags.iter().all(|d| d.code != "W0210"), "{diags:#?}");
    // A faster bus (the Baudrate attribute) carries the 1 ms frames.
    let fast = format!(
        "{cycles}BA_DEF_  \"Baudrate\" INT 1 1000000;\nBA_DEF_DEF_  \"Baudrate\" 500000;\n\
         BA_ \"Baudrate\" 1000000;\n"
    );
    let diags = with_integrity(messages, &fast);
    assert!(diags.iter().all(|d| d.code != "W0210"), "{diags:#?}");
}
