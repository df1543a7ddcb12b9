//! The CCM's calibration as people read it, the same on the Pi (the gateway's record) and the
//! pit (the dashboard's Tune page): values written as the tools write them, and why the CCM's
//! slave refused a change, in a tuner's words.

use aer::calibration::{ChangeWhen, Parameter};
use aer_xcp::protocol::err;

/// A value as people write it: `0.02`, not `0.019999999552965164` (every parameter is an
/// `f32` on the CCM).
pub fn number(value: f64) -> String {
    let single = value as f32;
    if f64::from(single) == value {
        format!("{single}")
    } else {
        format!("{value}")
    }
}

/// When a parameter may change, as the Tune page says it.
pub fn when(change: ChangeWhen) -> &'static str {
    match change {
        ChangeWhen::Driving => "any time",
        ChangeWhen::Standstill => "at standstill",
        ChangeWhen::TractiveOff => "at standstill, tractive system off",
    }
}

/// Why the slave refused, with XCP error `code`, for `parameter` when one was written with
/// value `new`.
pub fn refusal_text(code: u8, parameter: Option<&Parameter>, new: Option<f64>) -> String {
    match (code, parameter) {
        (err::ACCESS_LOCKED, _) => "calibration is locked (unlock with seed and key first)".into(),
        (err::WRITE_PROTECTED, Some(p)) => match p.change {
            ChangeWhen::Standstill => "only at standstill".into(),
            ChangeWhen::TractiveOff => "only at standstill with the tractive system off".into(),
            // Such a value is refused only with another of the same write.
            ChangeWhen::Driving => "refused with the write's other values".into(),
        },
        (err::WRITE_PROTECTED, None) => {
            "not in this vehicle state: it changes values that may change only at standstill".into()
        }
        (err::OUT_OF_RANGE, Some(p)) => match new {
            Some(value) if !(p.min..=p.max).contains(&value) => {
                format!("out of range {}-{}", number(p.min), number(p.max))
            }
            Some(_) if p.increasing => {
                "refused: each point must lie above the one before, and the sensor checks must pass"
                    .into()
            }
            Some(_) => "refused by the sensor cross-checks".into(),
            None => format!("out of range {}-{}", number(p.min), number(p.max)),
        },
        (err::OUT_OF_RANGE, None) => "out of range".into(),
        (err::ACCESS_DENIED, _) => "not in the calibration page".into(),
        (err::SEQUENCE, _) => "a block download out of sequence".into(),
        (err::PAGE_NOT_VALID, _) => "no such page".into(),
        (err::MODE_NOT_VALID, _) => "no such page mode".into(),
        (err::SEGMENT_NOT_VALID, _) => "no such segment".into(),
        (err::GENERIC, _) => "the CCM could not do it (saving to flash failed)".into(),
        (code, _) => format!("refused (XCP error 0x{code:02X})"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use aer::calibration::PARAMETERS;

    #[test]
    fn values_read_as_written_and_refusals_name_the_limits() {
        assert_eq!(number(f64::from(0.02f32)), "0.02");
        assert_eq!(number(0.1), "0.1");
        let threshold = PARAMETERS
            .iter()
            .find(|p| p.name == "traction_slip_threshold")
            .expect("in the schema");
        assert_eq!(
            refusal_text(err::OUT_OF_RANGE, Some(threshold), Some(0.75)),
            "out of range 0.02-0.5"
        );
        assert_eq!(refusal_text(0x99, None, None), "refused (XCP error 0x99)");
    }
}
