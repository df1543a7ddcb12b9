//! Checks the XCP slave's settings in `calibration.yaml`: its messages in the DBC (on the bus,
//! 8 bytes, standard ids, a cycle time that is the slave's frame budget), its DAQ limits, its
//! session limits (idle time-out, the delay after wrong keys) and its event channels.

use std::collections::HashSet;

use serde_saphyr::Spanned;

use super::names::{check_item_name, line_of};
use crate::diagnostic::{Code, Reporter};
use crate::load::calibration::{EventSpec, XcpSpec};
use crate::model::{Database, Message, Xcp, XcpEvent};

/// Bytes of an XCP on CAN frame: the slave's messages always carry 8 (MAX_DLC_REQUIRED).
const XCP_FRAME_LEN: usize = 8;

/// The largest ODT entry a DAQ packet carries: MAX_DTO (8) less the absolute PID byte.
const MAX_ODT_ENTRY_SIZE: f64 = 7.0;

/// DAQ lists the absolute identification field can tell apart: PIDs 0..=0xFB, one ODT each
/// at least.
const MAX_DAQ_LISTS: f64 = 252.0;

/// The XCP slave's settings: its messages in `db`, its limits, its session limits and its
/// events.
pub(crate) fn check(r: &mut Reporter<'_>, xcp: &Spanned<XcpSpec>, db: &Database) -> Option<Xcp> {
    let spec = &xcp.value;
    let bus = spec.bus.as_ref();
    let command = xcp_message(r, db, bus, &spec.command_message, "command");
    let response = xcp_message(r, db, bus, &spec.response_message, "response");
    if spec.command_message.value == spec.response_message.value {
        r.report(
            Code::XcpMessage,
            line_of(&spec.response_message),
            format!(
                "`{}` is both the command and the response message",
                spec.response_message.value
            ),
            "XCP on CAN needs one id for each direction: give the response its own message",
        );
    }
    let cycle = response.and_then(|m| {
        let cycle = m.cycle_time_ms.filter(|&c| c > 0);
        if cycle.is_none() {
            r.report(
                Code::XcpMessage,
                line_of(&spec.response_message),
                format!("response message `{}` has no cycle time", m.name),
                "give it a GenMsgCycleTime: the slave's frame budget (4 ms: at most 250 frames/s)",
            );
        }
        cycle
    });
    if db.bit_rate.is_none() {
        r.report(
            Code::XcpMessage,
            line_of(&spec.command_message),
            "the DBC gives no bit rate for the XCP messages' bus".to_owned(),
            "declare the database attribute Baudrate (the car's buses: 500000)",
        );
    }
    let tcp_port = xcp_number(r, &spec.tcp_port, "tcp_port", (1.0, 65535.0), "a TCP port");
    let max_daq = xcp_number(
        r,
        &spec.max_daq,
        "max_daq",
        (1.0, MAX_DAQ_LISTS),
        "DAQ lists the absolute PIDs can tell apart",
    );
    let odt_entries = xcp_number(
        r,
        &spec.odt_entries,
        "odt_entries",
        (1.0, 65535.0),
        "ODT entries over all DAQ lists",
    );
    let entry_size = xcp_number(
        r,
        &spec.max_odt_entry_size,
        "max_odt_entry_size",
        (4.0, MAX_ODT_ENTRY_SIZE),
        "bytes: an entry holds the widest measured value (an f32) and fits a DAQ packet after its PID",
    );
    if let (Some(daq), Some(entries)) = (max_daq, odt_entries) {
        if entries < daq {
            r.report(
                Code::XcpSetting,
                line_of(&spec.odt_entries),
                format!("odt_entries {entries} is below max_daq {daq}"),
                "every DAQ list needs an entry at least: allow as many entries as lists or more",
            );
        }
    }
    let idle_timeout_s = xcp_number(
        r,
        &spec.idle_timeout_s,
        "idle_timeout_s",
        (1.0, 3_600.0),
        "seconds without a command before the slave ends a session (or, with DAQ running, takes back its unlock)",
    );
    let unlock_delay_s = xcp_number(
        r,
        &spec.unlock_delay_s,
        "unlock_delay_s",
        (1.0, 60.0),
        "seconds GET_SEED is refused after a wrong key",
    );
    let unlock_delay_max_s = xcp_number(
        r,
        &spec.unlock_delay_max_s,
        "unlock_delay_max_s",
        (1.0, 3_600.0),
        "the longest delay, after many wrong keys in a row",
    );
    if let (Some(delay), Some(max)) = (unlock_delay_s, unlock_delay_max_s) {
        if max < delay {
            r.report(
                Code::XcpSetting,
                line_of(&spec.unlock_delay_s),
                format!("unlock_delay_max_s {max} is below unlock_delay_s {delay}"),
                "the delay doubles with each wrong key up to the maximum: give a maximum at least the first delay",
            );
        }
    }
    let events = check_events(r, &spec.events);
    Some(Xcp {
        bus: bus.map(|b| b.value.clone()),
        command_message: command?.name.clone(),
        response_message: response?.name.clone(),
        can_id_master: command?.id,
        can_id_slave: response?.id,
        bit_rate: db.bit_rate?,
        response_cycle_ms: cycle?,
        tcp_port: u16::try_from(tcp_port?).ok()?,
        max_daq: u16::try_from(max_daq?).ok()?,
        odt_entries: u16::try_from(odt_entries?).ok()?,
        max_odt_entry_size: u8::try_from(entry_size?).ok()?,
        idle_timeout_ms: idle_timeout_s?.checked_mul(1_000)?,
        unlock_delay_ms: unlock_delay_s?.checked_mul(1_000)?,
        unlock_delay_max_ms: unlock_delay_max_s?.checked_mul(1_000)?,
        events: events?,
    })
}

/// The DBC message an XCP direction uses: present, on the bus, 8 bytes, a standard id.
fn xcp_message<'db>(
    r: &mut Reporter<'_>,
    db: &'db Database,
    bus: Option<&Spanned<String>>,
    name: &Spanned<String>,
    direction: &str,
) -> Option<&'db Message> {
    let line = line_of(name);
    let Some(message) = db.messages.iter().find(|m| m.name == name.value) else {
        r.report(
            Code::XcpMessage,
            line,
            format!(
                "the XCP {direction} message `{}` is not in the DBC",
                name.value
            ),
            "name a message of schema/aer.dbc (the car's: XCP_Cmd, XCP_Res)",
        );
        return None;
    };
    let mut ok = true;
    if let Some(bus) = bus {
        if !message.buses.contains(&bus.value) {
            r.report(
                Code::XcpMessage,
                line_of(bus),
                format!(
                    "the XCP {direction} message `{}` is not sent on bus `{}`",
                    message.name, bus.value
                ),
                "give the message that AerBus, or name the bus it is on",
            );
            ok = false;
        }
    }
    if message.len != XCP_FRAME_LEN || message.fd {
        r.report(
            Code::XcpMessage,
            line,
            format!(
                "the XCP {direction} message `{}` is {} bytes",
                message.name, message.len
            ),
            "XCP on classic CAN sends every packet in 8 bytes (MAX_DLC_REQUIRED): make it 8",
        );
        ok = false;
    }
    if message.extended {
        r.report(
            Code::XcpMessage,
            line,
            format!(
                "the XCP {direction} message `{}` has an extended id",
                message.name
            ),
            "give it a standard (11-bit) id, as the slave filters and the A2L states",
        );
        ok = false;
    }
    ok.then_some(message)
}

/// A whole number within `low..=high`, or `None` with `key` reported.
fn xcp_number(
    r: &mut Reporter<'_>,
    value: &Spanned<f64>,
    key: &str,
    (low, high): (f64, f64),
    what: &str,
) -> Option<u32> {
    let v = value.value;
    if v.fract() == 0.0 && (low..=high).contains(&v) {
        // Whole and within u16's range: the cast is exact.
        return Some(v as u32);
    }
    r.report(
        Code::XcpSetting,
        line_of(value),
        format!("{key} {v} is not a whole number in {low}..={high}"),
        format!("give {low} to {high} ({what})"),
    );
    None
}

/// The event channels: at least one, each named, described and with a period an A2L event
/// can state.
fn check_events(
    r: &mut Reporter<'_>,
    events: &Spanned<Vec<Spanned<EventSpec>>>,
) -> Option<Vec<XcpEvent>> {
    if events.value.is_empty() {
        r.report(
            Code::XcpEvent,
            line_of(events),
            "the XCP slave has no events".to_owned(),
            "list the points where DAQ lists are sampled under `events:` (the car's: control, sensors)",
        );
        return None;
    }
    let mut seen = HashSet::new();
    let mut checked = Vec::new();
    let mut ok = true;
    for spanned in &events.value {
        let spec = &spanned.value;
        let name = spec.name.value.as_str();
        ok &= check_item_name(r, Code::XcpEvent, "event", &spec.name, &mut seen);
        if spec
            .description
            .as_deref()
            .is_none_or(|t| t.trim().is_empty())
        {
            r.report(
                Code::XcpEvent,
                line_of(spanned),
                format!("event `{name}` has no description"),
                "add `description:` (the calibration tool shows it)",
            );
            ok = false;
        }
        let period_us = spec.period_ms.value * 1000.0;
        let whole = period_us.fract() == 0.0 && (1.0..=f64::from(u32::MAX)).contains(&period_us);
        // Whole and within u32's range: the cast is exact.
        let period = whole.then_some(period_us as u32);
        match period.filter(|&p| crate::model::time_cycle(p).is_some()) {
            Some(period_us) => checked.push(XcpEvent {
                name: name.to_owned(),
                period_us,
                description: spec.description.clone().unwrap_or_default(),
            }),
            None => {
                r.report(
                    Code::XcpEvent,
                    line_of(&spec.period_ms),
                    format!(
                        "event `{name}`'s period_ms {} is not a period an A2L event states",
                        spec.period_ms.value
                    ),
                    "give a period above 0 that is at most 255 times 1 us, 10 us, ... or 1 s (10 ms, 1 ms, 0.5 ms)",
                );
                ok = false;
            }
        }
    }
    ok.then_some(checked)
}
