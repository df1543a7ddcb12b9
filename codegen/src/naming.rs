//! Turning schema names into Rust identifiers. DBC names are C identifiers in any case style;
//! Rust wants `CamelCase` types and `snake_case` fields, and some names collide with keywords.

/// Words that cannot be used as plain identifiers (strict and reserved keywords, 2024 edition).
const KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum", "extern",
    "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut",
    "pub", "ref", "return", "self", "Self", "static", "struct", "super", "trait", "true", "type",
    "unsafe", "use", "where", "while", "abstract", "become", "box", "do", "final", "macro",
    "override", "priv", "try", "typeof", "unsized", "virtual", "yield",
];

pub(crate) fn is_keyword(ident: &str) -> bool {
    KEYWORDS.contains(&ident)
}

/// Splits a name into lower-case words at underscores, case changes and letter/digit borders
/// that follow a lower-case letter (`MCU1_MainState` -> `mcu1`, `main`, `state`).
fn words(name: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut current = String::new();
    let chars: Vec<char> = name.chars().collect();
    for (i, &c) in chars.iter().enumerate() {
        if !c.is_ascii_alphanumeric() {
            if !current.is_empty() {
                words.push(std::mem::take(&mut current));
            }
            continue;
        }
        let prev = i.checked_sub(1).and_then(|p| chars.get(p)).copied();
        let next = chars.get(i + 1).copied();
        let boundary = match prev {
            Some(p) if c.is_ascii_uppercase() => {
                p.is_ascii_lowercase()
                    // `MCU1State` splits after the digit; `12V` stays one word.
                    || (p.is_ascii_digit() && !current.chars().all(|x| x.is_ascii_digit()))
                    || (p.is_ascii_uppercase() && next.is_some_and(|n| n.is_ascii_lowercase()))
            }
            _ => false,
        };
        if boundary && !current.is_empty() {
            words.push(std::mem::take(&mut current));
        }
        current.push(c.to_ascii_lowercase());
    }
    if !current.is_empty() {
        words.push(current);
    }
    words
}

/// `snake_case` field or function name; keywords get a trailing underscore, a leading digit a
/// leading `_`-free prefix so the result is always a valid identifier.
pub(crate) fn snake(name: &str) -> String {
    let mut s = words(name).join("_");
    if s.is_empty() {
        s.push_str("unnamed");
    }
    if s.starts_with(|c: char| c.is_ascii_digit()) {
        s.insert(0, 'n');
    }
    if is_keyword(&s) {
        s.push('_');
    }
    s
}

/// `CamelCase` type or variant name.
pub(crate) fn camel(name: &str) -> String {
    let mut s: String = words(name)
        .iter()
        .map(|w| {
            let mut cs = w.chars();
            match cs.next() {
                Some(first) => first.to_ascii_uppercase().to_string() + cs.as_str(),
                None => String::new(),
            }
        })
        .collect();
    if s.is_empty() {
        s.push_str("Unnamed");
    }
    if s.starts_with(|c: char| c.is_ascii_digit()) {
        s.insert(0, 'V');
    }
    if is_keyword(&s) {
        s.push('_');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_dbc_style_names() {
        assert_eq!(snake("MCU1_MainState"), "mcu1_main_state");
        assert_eq!(snake("VCU_TorqueReq"), "vcu_torque_req");
        assert_eq!(snake("DC_LowVoltWarning"), "dc_low_volt_warning");
        assert_eq!(snake("12V_LowVoltWarning"), "n12v_low_volt_warning");
        assert_eq!(snake("MCU_12V_LowVoltWarning"), "mcu_12v_low_volt_warning");
        assert_eq!(snake("MCU1State"), "mcu1_state");
        assert_eq!(snake("BMSState"), "bms_state");
        assert_eq!(camel("VCU1"), "Vcu1");
        assert_eq!(camel("ExampleMessage"), "ExampleMessage");
        assert_eq!(camel("ignition off"), "IgnitionOff");
        assert_eq!(camel("3rd gear"), "V3rdGear");
    }

    #[test]
    fn keywords_become_valid_identifiers() {
        assert_eq!(snake("type"), "type_");
        assert_eq!(snake("Self"), "self_");
        assert_eq!(camel("self"), "Self_");
        assert!(is_keyword("match"));
        assert!(!is_keyword("matches"));
    }
}
