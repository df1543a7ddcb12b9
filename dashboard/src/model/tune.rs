//! The Tune page's state: the CCM's calibration as the page last read it, what the tuner has
//! typed, and what came of each request. Every parameter, its limits, default and change
//! condition come from the generated schema (`aer::calibration::PARAMETERS`); the values from
//! the CCM.

use crate::tune_worker::{Event, Request};
use aer::calibration::{Calibration, ElementType, PAGE_LEN, PARAMETERS, Parameter};
use aer::can::VehicleState;
use aer::telemetry::Telemetry;
use aer_host::calibration::number;
use std::collections::BTreeMap;

/// Parameter index (into `PARAMETERS`) and element.
pub type Element = (usize, usize);

/// The session with the CCM.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Session {
    /// None: why (empty before the first attempt).
    Closed(String),
    /// A request to connect is out.
    Connecting,
    Open {
        locked: bool,
        ecu_page: u8,
    },
}

/// What came of the last request on an element.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Written; the value read back.
    Written(Option<f64>),
    /// Refused by the CCM, why.
    Refused(String),
    /// Never sent: why (not a number).
    NotSent(String),
}

/// The page's state.
#[derive(Debug, Clone, PartialEq)]
pub struct Tune {
    pub gateway: String,
    pub session: Session,
    /// The working page as last read.
    page: Option<[u8; PAGE_LEN]>,
    /// What the tuner typed, per element.
    edits: BTreeMap<Element, String>,
    outcomes: BTreeMap<Element, Outcome>,
    /// The last page-wide result (unlock, revert, save): good or not, and what.
    pub note: Option<(bool, String)>,
    /// A request is out; the buttons wait.
    pub busy: bool,
}

impl Tune {
    /// Nothing read yet, for the gateway at `gateway`.
    pub fn new(gateway: &str) -> Self {
        Self {
            gateway: gateway.to_owned(),
            session: Session::Closed(String::new()),
            page: None,
            edits: BTreeMap::new(),
            outcomes: BTreeMap::new(),
            note: None,
            busy: false,
        }
    }

    /// Element `element` of parameter `parameter` as the CCM has it.
    pub fn value(&self, (parameter, element): Element) -> Option<f64> {
        let page = self.page.as_ref()?;
        PARAMETERS.get(parameter)?.value(page, element)
    }

    /// The schema's default (the reference page).
    pub fn default_value((parameter, element): Element) -> Option<f64> {
        PARAMETERS
            .get(parameter)?
            .value(&Calibration::DEFAULT.to_page(), element)
    }

    /// What the tuner typed for an element.
    pub fn edit(&self, element: Element) -> &str {
        self.edits.get(&element).map_or("", String::as_str)
    }

    /// What came of the last request on an element.
    pub fn outcome(&self, element: Element) -> Option<&Outcome> {
        self.outcomes.get(&element)
    }

    pub fn set_edit(&mut self, element: Element, text: String) {
        self.edits.insert(element, text);
    }

    /// The write request for the parameter of `at`: every element the tuner typed, the
    /// others as the CCM has them, written at once; or why there is none (shown at the
    /// element).
    pub fn write_request(&mut self, at: Element) -> Option<Request> {
        let parameter = at.0;
        let p = PARAMETERS.get(parameter)?;
        let mut values = Vec::with_capacity(p.count);
        let mut edited = Vec::new();
        for element in 0..p.count {
            let text = self.edit((parameter, element)).trim().to_owned();
            if text.is_empty() {
                match self.value((parameter, element)) {
                    Some(value) => values.push(value as f32),
                    None => return self.not_sent(at, "not read from the CCM yet".into()),
                }
                continue;
            }
            match text.parse::<f32>() {
                Ok(value) if value.is_finite() => {
                    values.push(value);
                    edited.push(element);
                }
                _ => {
                    return self
                        .not_sent((parameter, element), format!("`{text}` is not a number"));
                }
            }
        }
        if edited.is_empty() {
            return self.not_sent(at, "type a value first".into());
        }
        Some(Request::Write {
            parameter,
            values,
            edited,
        })
    }

    fn not_sent(&mut self, at: Element, why: String) -> Option<Request> {
        self.outcomes.insert(at, Outcome::NotSent(why));
        None
    }

    /// A request went out.
    pub fn sent(&mut self, request: &Request) {
        self.busy = true;
        if *request == Request::Connect {
            self.session = Session::Connecting;
        }
    }

    /// What the worker answered.
    pub fn apply(&mut self, event: Event) {
        self.busy = false;
        match event {
            Event::Ready(_) => {}
            Event::Connected {
                page,
                ecu_page,
                locked,
            } => {
                self.page = Some(*page);
                self.session = Session::Open { locked, ecu_page };
                self.outcomes.clear();
                self.note = Some((true, format!("connected: page read, {}", lock_text(locked))));
            }
            Event::Unlocked => {
                if let Session::Open { locked, .. } = &mut self.session {
                    *locked = false;
                }
                self.note = Some((true, "calibration unlocked".into()));
            }
            Event::Written {
                parameter,
                edited,
                values,
            } => {
                self.store(parameter, &values);
                for element in edited {
                    self.edits.remove(&(parameter, element));
                    let value = values.get(element).copied().flatten();
                    self.outcomes
                        .insert((parameter, element), Outcome::Written(value));
                }
            }
            Event::Reverted { page } => {
                self.page = Some(*page);
                self.outcomes.clear();
                self.note = Some((true, "reverted to the reference page (the defaults)".into()));
            }
            Event::Saved => {
                self.note = Some((true, "saved to flash: the CCM starts with this page".into()));
            }
            Event::Refused {
                request,
                reason,
                values_now,
            } => match request {
                Request::Write {
                    parameter, edited, ..
                } => {
                    self.store(parameter, &values_now);
                    for element in edited {
                        self.outcomes
                            .insert((parameter, element), Outcome::Refused(reason.clone()));
                    }
                }
                _ => self.note = Some((false, format!("{}: {reason}", action(&request)))),
            },
            Event::Disconnected(why) => {
                self.session = Session::Closed(why);
            }
        }
    }

    /// Keeps the values read back in the page (`None`: not read, left as it was).
    fn store(&mut self, parameter: usize, values: &[Option<f64>]) {
        let (Some(page), Some(p)) = (self.page.as_mut(), PARAMETERS.get(parameter)) else {
            return;
        };
        for (element, value) in values.iter().enumerate().take(p.count) {
            let Some(value) = value else { continue };
            let at = p.offset + element * p.element.size();
            let bytes = match p.element {
                ElementType::F32 => (*value as f32).to_le_bytes(),
            };
            if let Some(slot) = page.get_mut(at..at + bytes.len()) {
                slot.copy_from_slice(&bytes);
            }
        }
    }

    /// Whether saving may be asked for: not while the telemetry says the car moves or the
    /// tractive system is live (the CCM refuses then); unknown telemetry leaves it to the CCM.
    pub fn save_allowed(telemetry: Option<&Telemetry>) -> bool {
        telemetry.is_none_or(|t| {
            t.motor_speed.abs() < 1.0
                && matches!(
                    t.vehicle_state,
                    VehicleState::Off | VehicleState::Standby | VehicleState::Fault
                )
        })
    }
}

fn lock_text(locked: bool) -> &'static str {
    if locked {
        "calibration locked"
    } else {
        "calibration unlocked"
    }
}

fn action(request: &Request) -> &'static str {
    match request {
        Request::Connect => "connect",
        Request::Unlock => "unlock",
        Request::Write { .. } => "write",
        Request::Revert => "revert",
        Request::Save => "save",
        Request::Disconnect => "disconnect",
    }
}

/// An element's name: `traction_kp`, `launch_slip_target[2]`.
pub fn element_name(parameter: &Parameter, element: usize) -> String {
    if parameter.count > 1 {
        format!("{}[{element}]", parameter.name)
    } else {
        parameter.name.to_owned()
    }
}

/// A value with its unit (`650 Nm`, `0.1`).
pub fn with_unit(value: Option<f64>, unit: &str) -> String {
    match value {
        Some(v) if unit.is_empty() || unit == "1" => number(v),
        Some(v) => format!("{} {unit}", number(v)),
        None => "-".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kp() -> usize {
        PARAMETERS
            .iter()
            .position(|p| p.name == "traction_kp")
            .expect("in the schema")
    }

    #[test]
    fn a_write_read_back_or_refused_shows_at_its_element_and_in_the_page() {
        let mut tune = Tune::new("127.0.0.1:5555");
        tune.apply(Event::Connected {
            page: Box::new(Calibration::DEFAULT.to_page()),
            ecu_page: 0,
            locked: true,
        });
        assert_eq!(tune.value((kp(), 0)), Tune::default_value((kp(), 0)));
        tune.set_edit((kp(), 0), " 650 ".into());
        let request = tune.write_request((kp(), 0)).expect("a number");
        assert_eq!(
            request,
            Request::Write {
                parameter: kp(),
                values: vec![650.0],
                edited: vec![0],
            }
        );
        tune.apply(Event::Written {
            parameter: kp(),
            edited: vec![0],
            values: vec![Some(650.0)],
        });
        assert_eq!(tune.value((kp(), 0)), Some(650.0));
        assert_eq!(tune.edit((kp(), 0)), "");
        tune.apply(Event::Refused {
            request,
            reason: "only at standstill".into(),
            values_now: vec![Some(650.0)],
        });
        assert_eq!(
            tune.outcome((kp(), 0)),
            Some(&Outcome::Refused("only at standstill".into()))
        );
    }

    #[test]
    fn a_curve_is_written_whole_with_the_points_not_typed_as_the_ccm_has_them() {
        let ramp = PARAMETERS
            .iter()
            .position(|p| p.name == "pump_ramp_degc")
            .expect("in the schema");
        let mut tune = Tune::new("127.0.0.1:5555");
        tune.apply(Event::Connected {
            page: Box::new(Calibration::DEFAULT.to_page()),
            ecu_page: 0,
            locked: false,
        });
        tune.set_edit((ramp, 1), "80".into());
        let current = Tune::default_value((ramp, 0)).expect("a default") as f32;
        assert_eq!(
            tune.write_request((ramp, 1)),
            Some(Request::Write {
                parameter: ramp,
                values: vec![current, 80.0],
                edited: vec![1],
            })
        );
    }

    #[test]
    fn text_that_is_not_a_number_is_never_sent() {
        let mut tune = Tune::new("127.0.0.1:5555");
        tune.set_edit((kp(), 0), "6OO".into());
        assert_eq!(tune.write_request((kp(), 0)), None);
        assert_eq!(
            tune.outcome((kp(), 0)),
            Some(&Outcome::NotSent("`6OO` is not a number".into()))
        );
    }

    #[test]
    fn saving_waits_for_standstill_with_the_tractive_system_off() {
        let parked = Telemetry {
            vehicle_state: VehicleState::Standby,
            ..Telemetry::zeroed()
        };
        let driving = Telemetry {
            vehicle_state: VehicleState::Driving,
            motor_speed: 1000.0,
            ..Telemetry::zeroed()
        };
        assert!(Tune::save_allowed(Some(&parked)));
        assert!(!Tune::save_allowed(Some(&driving)));
        assert!(Tune::save_allowed(None));
    }
}
