//! `cargo xtask pins`: the boards' pin maps from `aer-boards`, the description the firmware
//! itself is checked against, one line per signal.

use aer_boards::{Pin, ccm, pcc};

/// The default boards, by the name each line starts with.
fn boards() -> [(&'static str, &'static [Pin]); 2] {
    const CCM: [Pin; ccm::PIN_COUNT] = ccm::COMP_CAR.pins();
    const PCC: [Pin; 8] = pcc::COMP_CAR.pins();
    [("ccm", &CCM), ("pcc", &PCC)]
}

/// `<board> <pin> <signal> <mode>` per line.
pub fn listing() -> String {
    let mut out = String::new();
    for (board, pins) in boards() {
        for pin in pins {
            out.push_str(&format!(
                "{board} {} {} {}\n",
                pin.number,
                pin.signal,
                pin.mode.label()
            ));
        }
    }
    out
}

/// The Markdown table in docs/firmware.md: the listing plus each pin's source.
pub fn markdown() -> String {
    let mut out = String::from("| Board | Pin | Signal | Mode | Source |\n|---|---|---|---|---|\n");
    for (board, pins) in boards() {
        for pin in pins {
            out.push_str(&format!(
                "| {board} | {} | {} | {} | {}{} |\n",
                pin.number,
                pin.signal,
                pin.mode.label(),
                if pin.source.is_assumed() { "**" } else { "" },
                pin.source.text().replace('|', "/"),
            ));
        }
    }
    // Bold assumed sources, closed.
    out.lines()
        .map(|line| {
            if line.contains("| **") {
                format!("{}** |", line.trim_end_matches(" |"))
            } else {
                line.to_owned()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
        + "\n"
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn docs_firmware_md_carries_the_generated_table() {
        let docs = include_str!("../../docs/firmware.md");
        assert!(
            docs.contains(&markdown()),
            "docs/firmware.md's pin table is stale: paste `cargo xtask pins --markdown`"
        );
    }

    #[test]
    fn the_listing_has_one_line_per_pin_in_four_fields() {
        let listing = listing();
        assert_eq!(listing.lines().count(), ccm::PIN_COUNT + 8);
        assert!(listing.lines().all(|line| line.split(' ').count() == 4));
        assert!(listing.contains("pcc 11 air-plus-close output-pulldown\n"));
        assert!(listing.contains("ccm 31 vehicle-can-tx can3-tx\n"));
    }
}
