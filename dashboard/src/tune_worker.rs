//! The Tune page's XCP master: a worker thread that holds one XCP session with the CCM through
//! the Pi's gateway ([`aer_host::link::xcp_master`]) and carries out the page's requests one at a
//! time, answering each with an [`Event`]. Blocking I/O stays off the UI thread; the page
//! only sends [`Request`]s and applies events ([`crate::model::tune`]).

use crate::config::TuneConfig;
use aer::calibration::xcp::CALIBRATION_ADDRESS;
use aer::calibration::{ElementType, PAGE_LEN, PARAMETERS};
use aer_host::calibration::refusal_text;
use aer_host::link::xcp_master::{Master, MasterError};
use aer_xcp::seed_key::{SECRET_LEN, parse_secret};
use iced::futures::channel::mpsc;
use iced::futures::{SinkExt, Stream, StreamExt};
use std::net::SocketAddr;
use std::time::Duration;

/// Where and how the worker reaches the CCM.
#[derive(Clone, PartialEq, Eq, Hash)]
pub struct Settings {
    pub gateway: SocketAddr,
    /// The team's secret, if the configuration names one that reads.
    pub secret: Option<[u8; SECRET_LEN]>,
    /// Why there is no secret (for the page), when there is none.
    pub no_secret: String,
    pub timeout: Duration,
}

impl std::fmt::Debug for Settings {
    // Never the secret.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Settings")
            .field("gateway", &self.gateway)
            .field("secret", &self.secret.map(|_| "(set)"))
            .field("timeout", &self.timeout)
            .finish()
    }
}

impl Settings {
    /// From the configuration (checked: the gateway parses); a secret file that cannot be read
    /// leaves calibration locked, and says why.
    pub fn from_config(config: &TuneConfig) -> Self {
        let (secret, no_secret) = match &config.secret_file {
            None => (None, "no secret_file in [tune]".to_owned()),
            Some(path) => match std::fs::read_to_string(path) {
                Ok(text) => match parse_secret(&text) {
                    Some(secret) => (Some(secret), String::new()),
                    None => (None, format!("{}: not 64 hex digits", path.display())),
                },
                Err(error) => (None, format!("{}: {error}", path.display())),
            },
        };
        Self {
            gateway: config
                .gateway
                .parse()
                .unwrap_or(SocketAddr::from(([127, 0, 0, 1], 5555))),
            secret,
            no_secret,
            timeout: Duration::from_millis(config.timeout_ms),
        }
    }
}

/// What the page asks of the CCM.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    Connect,
    Unlock,
    /// Parameter `parameter` (an index into `PARAMETERS`) to `values`, every element at once,
    /// so the CCM checks a curve whole (its points must rise); `edited` are the elements the
    /// tuner typed.
    Write {
        parameter: usize,
        values: Vec<f32>,
        edited: Vec<usize>,
    },
    /// The reference page (the schema's defaults) over the working page.
    Revert,
    /// The working page to flash, for the next start.
    Save,
    Disconnect,
}

/// What came of a request.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// The worker runs: how to send it requests.
    Ready(Control),
    /// A session with the CCM: the working page, the page the car runs on, the lock.
    Connected {
        page: Box<[u8; PAGE_LEN]>,
        ecu_page: u8,
        locked: bool,
    },
    Unlocked,
    /// A parameter written and read back (every element), `edited` as the request said.
    Written {
        parameter: usize,
        edited: Vec<usize>,
        values: Vec<Option<f64>>,
    },
    /// The working page after a revert.
    Reverted {
        page: Box<[u8; PAGE_LEN]>,
    },
    Saved,
    /// The CCM refused `request`: why, and (for a write) the parameter's values now.
    Refused {
        request: Request,
        reason: String,
        values_now: Vec<Option<f64>>,
    },
    /// The session ended (asked for, or the connection failed).
    Disconnected(String),
}

/// The page's side of the worker.
#[derive(Debug, Clone)]
pub struct Control(std::sync::mpsc::Sender<Request>);

impl PartialEq for Control {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl Control {
    /// A control and the receiving end (tests check what the page asked for).
    pub fn channel() -> (Self, std::sync::mpsc::Receiver<Request>) {
        let (sender, receiver) = std::sync::mpsc::channel();
        (Self(sender), receiver)
    }

    /// Asks the worker for `request`; false if it has ended.
    pub fn send(&self, request: Request) -> bool {
        self.0.send(request).is_ok()
    }
}

/// The worker as an iced subscription stream: [`Event::Ready`] first, then one event per
/// request.
pub fn stream(settings: Settings) -> impl Stream<Item = Event> {
    iced::stream::channel(16, async move |mut output: mpsc::Sender<Event>| {
        let (control, requests) = Control::channel();
        if output.send(Event::Ready(control)).await.is_err() {
            return;
        }
        let (events, mut from_worker) = mpsc::unbounded();
        std::thread::Builder::new()
            .name("tune-xcp".into())
            .spawn(move || {
                let mut worker = Worker::new(settings);
                for request in requests {
                    if events.unbounded_send(worker.handle(request)).is_err() {
                        return;
                    }
                }
            })
            .ok();
        while let Some(event) = from_worker.next().await {
            if output.send(event).await.is_err() {
                return;
            }
        }
        // The worker thread ended (it cannot start, or it failed): the page must not wait.
        let _ = output
            .send(Event::Disconnected("the XCP worker stopped".into()))
            .await;
    })
}

/// One XCP session at a time, and the requests carried out on it.
pub struct Worker {
    settings: Settings,
    master: Option<Master>,
}

impl Worker {
    pub fn new(settings: Settings) -> Self {
        Self {
            settings,
            master: None,
        }
    }

    /// Carries out `request` and says what came of it.
    pub fn handle(&mut self, request: Request) -> Event {
        if request == Request::Connect {
            self.master = None;
            let connected = Master::connect(self.settings.gateway, self.settings.timeout).and_then(
                |mut master| {
                    let page = master.read_page()?;
                    let ecu_page = master.ecu_page()?;
                    let locked = master.calibration_locked()?;
                    Ok((master, page, ecu_page, locked))
                },
            );
            return match connected {
                Ok((master, page, ecu_page, locked)) => {
                    self.master = Some(master);
                    Event::Connected {
                        page: Box::new(page),
                        ecu_page,
                        locked,
                    }
                }
                Err(error) => Event::Disconnected(format!(
                    "cannot reach the CCM through {}: {error}",
                    self.settings.gateway
                )),
            };
        }
        let Some(master) = self.master.as_mut() else {
            return Event::Disconnected("not connected".into());
        };
        let result = match request.clone() {
            Request::Connect => return Event::Disconnected("not connected".into()),
            Request::Disconnect => {
                let ended = self.master.take().map(Master::disconnect);
                return Event::Disconnected(match ended {
                    Some(Err(error)) => format!("disconnected ({error})"),
                    _ => "disconnected".into(),
                });
            }
            Request::Unlock => match master.unlock(self.settings.secret.as_ref()) {
                Err(MasterError::NoSecret) => {
                    return Event::Refused {
                        request,
                        reason: format!(
                            "no XCP secret ({}): calibration stays locked",
                            self.settings.no_secret
                        ),
                        values_now: Vec::new(),
                    };
                }
                other => other.map(|()| Event::Unlocked),
            },
            Request::Write {
                parameter,
                values,
                edited,
            } => write(master, parameter, &values, edited),
            Request::Revert => master.revert_to_reference().and_then(|()| {
                Ok(Event::Reverted {
                    page: Box::new(master.read_page()?),
                })
            }),
            Request::Save => master.save().map(|()| Event::Saved),
        };
        let result = match result {
            // A wrong key ends the slave's session (the standard's rule).
            Err(MasterError::Refused(aer_xcp::protocol::err::ACCESS_LOCKED))
                if request == Request::Unlock =>
            {
                self.master = None;
                return Event::Disconnected(
                    "the CCM refused the key and ended the session (is secret_file the secret \
                     the firmware was built with?)"
                        .into(),
                );
            }
            Err(MasterError::Refused(code)) => refused(master, request, code),
            other => other,
        };
        match result {
            Ok(event) => event,
            // Anything else (no answer in time, the connection gone) ends the session: a late
            // answer would otherwise pass for the answer to the next command.
            Err(error) => {
                self.master = None;
                Event::Disconnected(format!("the session with the CCM ended: {error}"))
            }
        }
    }
}

/// Writes a parameter whole and reads it back.
fn write(
    master: &mut Master,
    parameter: usize,
    values: &[f32],
    edited: Vec<usize>,
) -> Result<Event, MasterError> {
    let address =
        element_address(parameter, 0).ok_or(MasterError::Protocol("no such parameter"))?;
    // Every element type the schema has, so a new one is a compile error here.
    let bytes: Vec<u8> = match PARAMETERS.get(parameter).map(|p| p.element) {
        Some(ElementType::F32) | None => values.iter().flat_map(|v| v.to_le_bytes()).collect(),
    };
    master.write(address, &bytes)?;
    Ok(Event::Written {
        parameter,
        edited,
        values: read_parameter(master, parameter)?,
    })
}

/// The refusal of `request` with XCP error `code`, in a tuner's words, with the values as
/// they stand now.
fn refused(master: &mut Master, request: Request, code: u8) -> Result<Event, MasterError> {
    let (reason, values_now) = match &request {
        Request::Write {
            parameter,
            values,
            edited,
        } => {
            let p = PARAMETERS.get(*parameter);
            // The value the reason is about: an edited one outside the limits, else the first
            // edited one.
            let typed = edited
                .iter()
                .filter_map(|&e| values.get(e))
                .map(|v| f64::from(*v));
            let outside = typed
                .clone()
                .find(|v| p.is_some_and(|p| !(p.min..=p.max).contains(v)));
            (
                refusal_text(code, p, outside.or(typed.clone().next())),
                read_parameter(master, *parameter)?,
            )
        }
        Request::Save if code == aer_xcp::protocol::err::WRITE_PROTECTED => (
            "saving to flash only at standstill with the tractive system off".into(),
            Vec::new(),
        ),
        _ => (refusal_text(code, None, None), Vec::new()),
    };
    Ok(Event::Refused {
        request,
        reason,
        values_now,
    })
}

/// The XCP address of an element.
pub fn element_address(parameter: usize, element: usize) -> Option<u32> {
    let p = PARAMETERS.get(parameter)?;
    if element >= p.count {
        return None;
    }
    let offset = p.offset + element * p.element.size();
    CALIBRATION_ADDRESS.checked_add(u32::try_from(offset).ok()?)
}

/// Every element of a parameter as the CCM has it now.
fn read_parameter(master: &mut Master, parameter: usize) -> Result<Vec<Option<f64>>, MasterError> {
    let p = PARAMETERS
        .get(parameter)
        .ok_or(MasterError::Protocol("no such parameter"))?;
    let address =
        element_address(parameter, 0).ok_or(MasterError::Protocol("no such parameter"))?;
    let bytes = master.read(address, p.len())?;
    Ok((0..p.count)
        .map(|element| {
            let at = element * p.element.size();
            match p.element {
                ElementType::F32 => {
                    let raw: [u8; 4] = bytes.get(at..at + 4)?.try_into().ok()?;
                    Some(f64::from(f32::from_le_bytes(raw)))
                }
            }
        })
        .collect())
}
