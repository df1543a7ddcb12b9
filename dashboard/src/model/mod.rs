//! What the screens show, as plain data: the latest packet and its age, derived driver values
//! (speed, power, the hottest temperature), alarms, plots, laps and link health. No UI types
//! here, and time is passed in, so tests drive it exactly.

pub mod alarms;
pub mod can;
pub mod fields;
pub mod health;
pub mod history;
pub mod record;
pub mod tune;

use crate::config::Config;
use aer::can::AnyMessage;
use aer::can::VehicleState;
use aer::mqtt::{Sample, TelemetryRecord};
use aer::telemetry::{Level, Telemetry, TelemetryHeader};
use aer_host::reports::status::{Metrics, Status};
use aer_host::run::laps::LapTimer;
use alarms::Alarms;
use can::CanMessages;
use fields::{Field, FieldValue, Schema};
use health::{Connection, Health};
use history::History;
use record::{Row, SessionRecord};
use std::time::{Duration, Instant};

/// The car's own constants (ccm/src/constants.rs): one place for them, shared with the firmware.
use aer_params::POWER_LIMIT_W;

/// Something the dashboard learns from the broker.
#[derive(Debug, Clone, PartialEq)]
pub enum Update {
    /// Connected (again) and subscribed.
    Connected,
    /// The client id this dashboard connects with, to find itself among the clients the Pi's
    /// status lists (how far behind the Pi's gate sees it).
    Identity(String),
    /// The connection failed or was lost; the link retries by itself.
    Disconnected(String),
    Telemetry(Box<Sample<TelemetryRecord>>),
    /// A frame of a CAN message the pit view shows, from its CAN topic.
    Can(Box<Sample<AnyMessage>>),
    /// The Pi service's retained status.
    Status(Box<Status>),
    /// The Pi service's counters, every second.
    Metrics(Box<Metrics>),
    /// Batches of the compact stream missing between received ones (a dropout, or a radio
    /// that lost them): their frames and packets did not arrive (yet: the link asks the Pi
    /// for them).
    StreamGap(u32),
    /// A telemetry packet the live stream missed, fetched from the Pi's history.
    PastTelemetry(Box<Sample<TelemetryRecord>>),
    /// How far the history has caught up.
    Backfill(BackfillProgress),
    /// A payload that is not its topic's type.
    Undecodable {
        topic: String,
        error: String,
    },
}

/// How complete the pit's copy of the session is, while history fills its gaps.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BackfillProgress {
    /// Seconds of the session still missing.
    pub behind_s: f64,
    /// The share of the session held (0-1).
    pub complete: f64,
    /// A gap is being filled, or waits to be.
    pub catching_up: bool,
    /// Batches recovered from the Pi's history so far.
    pub recovered: u64,
    /// Batches missed that the Pi no longer holds.
    pub not_held: u64,
    /// History batches that were not what was asked (left out).
    pub unexpected: u64,
}

/// The newest telemetry packet.
#[derive(Debug, Clone, PartialEq)]
pub struct Latest {
    /// When the Pi received it (s since the epoch).
    pub ts: f64,
    /// When it reached this dashboard.
    pub received: Instant,
    pub header: TelemetryHeader,
    pub telemetry: Telemetry,
}

/// How current the data on screen is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Freshness {
    /// No packet since start-up.
    NoData,
    Fresh,
    /// The newest packet is this old: more than the stale limit.
    Stale(Duration),
}

/// A value with its label, unit and level, as the driver view shows it.
#[derive(Debug, Clone, PartialEq)]
pub struct Reading {
    pub label: &'static str,
    pub value: f64,
    pub unit: &'static str,
    pub level: Level,
}

/// Everything the two views show.
#[derive(Debug, Clone)]
pub struct Dashboard {
    schema: Schema,
    stale_after: Duration,
    latest: Option<Latest>,
    values: Vec<FieldValue>,
    alarms: Alarms,
    history: History,
    laps: LapTimer,
    health: Health,
    plots: Vec<usize>,
    can: CanMessages,
    /// The PCC's latched causes, from its newest status.
    pcc_alarms: Vec<(&'static str, Level)>,
    /// The session so far, for merging history (with the compact stream only: the JSON
    /// topics have no history to fetch).
    record: Option<SessionRecord>,
    lap_length_m: Option<f64>,
    last_merge: Option<Instant>,
    /// How long the last replay took.
    replay_took: Duration,
}

/// History is merged at most this often while it flows (each merge replays the session).
const MERGE_EVERY: Duration = Duration::from_secs(1);
/// ... and a long session's replay takes at most this share of the time while it flows, so
/// the screen stays responsive (an hour at 100 Hz replays in about a second).
const MERGE_SHARE: u32 = 10;

impl Dashboard {
    /// An empty dashboard for the car's telemetry, set up from `config`.
    pub fn new(config: &Config) -> Self {
        Self::with_schema(Schema::TELEMETRY, config)
    }

    /// An empty dashboard for the fields of `schema` (the car's, or a test's).
    pub fn with_schema(schema: Schema, config: &Config) -> Self {
        let plots = config
            .display
            .plots
            .iter()
            .filter_map(|name| schema.field(name).map(|f| f.index))
            .collect();
        Self {
            schema,
            stale_after: config.stale_after(),
            latest: None,
            values: Vec::with_capacity(schema.fields.len()),
            alarms: Alarms::new(schema),
            history: History::new(config.display.plot_window_s, schema.fields.len()),
            laps: LapTimer::new(config.display.lap_length_m),
            health: Health::default(),
            plots,
            can: CanMessages::new(&config.display.can_messages),
            pcc_alarms: Vec::new(),
            record: (config.link.stream == crate::config::StreamFormat::Compact)
                .then(SessionRecord::default),
            lap_length_m: config.display.lap_length_m,
            last_merge: None,
            replay_took: Duration::ZERO,
        }
    }

    /// Takes one update received at `now`.
    pub fn apply(&mut self, update: Update, now: Instant) {
        match update {
            Update::Connected => self.health.connection = Connection::Connected,
            Update::Identity(client_id) => self.health.client_id = Some(client_id),
            Update::Disconnected(reason) => {
                // Keep the time of the first failure while it stays down.
                if !matches!(self.health.connection, Connection::Lost { .. }) {
                    self.health.connection = Connection::Lost { since: now, reason };
                } else if let Connection::Lost { reason: old, .. } = &mut self.health.connection {
                    *old = reason;
                }
            }
            Update::Telemetry(sample) => self.telemetry(&sample, now),
            Update::Can(sample) => {
                if let AnyMessage::PccStatus(status) = &sample.value {
                    self.pcc_alarms = pcc_alarms(status);
                }
                self.can.take(&sample, now);
            }
            Update::Status(status) => self.health.status(*status),
            Update::Metrics(metrics) => self.health.metrics = Some(*metrics),
            Update::Undecodable { topic, error } => self.health.undecodable(&topic, &error),
            Update::StreamGap(missed) => self.health.stream_gaps += u64::from(missed),
            Update::PastTelemetry(sample) => {
                if let Some(record) = &mut self.record {
                    record.history(row(&sample));
                }
            }
            Update::Backfill(progress) => self.health.backfill = Some(progress),
        }
    }

    /// Merges the history that arrived into the plots, the fault history and the lap times
    /// (at most every second while it flows, less often for a long session; at once when it
    /// has caught up). Call it after taking updates.
    pub fn settle(&mut self, now: Instant) {
        let Some(record) = &mut self.record else {
            return;
        };
        let catching_up = self.health.backfill.is_some_and(|b| b.catching_up);
        let every = MERGE_EVERY.max(self.replay_took * MERGE_SHARE);
        let due = self
            .last_merge
            .is_none_or(|last| now.saturating_duration_since(last) >= every);
        if !record.has_pending() || (catching_up && !due) {
            return;
        }
        self.last_merge = Some(now);
        let added = record.merge();
        self.health.backfilled += added as u64;
        if added > 0 {
            let started = Instant::now();
            self.replay();
            self.replay_took = started.elapsed();
        }
    }

    /// Rebuilds what the packets' order matters to from the session record, as if every
    /// packet had arrived live and in order.
    fn replay(&mut self) {
        let Some(record) = &self.record else {
            return;
        };
        let mut alarms = Alarms::new(self.schema);
        let mut laps = LapTimer::new(self.lap_length_m);
        let mut history = History::new(self.history.window_s(), self.schema.fields.len());
        let newest = record.rows().last().map_or(0.0, |row| row.ts);
        let mut marks = record.marks().to_vec();
        marks.sort_by(f64::total_cmp);
        let mut marks = marks.into_iter().peekable();
        let mut values = Vec::with_capacity(self.schema.fields.len());
        for row in record.rows() {
            while let Some(mark) = marks.next_if(|&mark| mark <= row.ts) {
                laps.mark(mark);
            }
            let telemetry = row.telemetry;
            laps.update(
                row.ts,
                speed_m_s(&telemetry),
                telemetry.vehicle_state == VehicleState::Driving,
            );
            fields::read(&telemetry, &mut values);
            alarms.update(row.ts, &values);
            if row.ts >= newest - history.window_s() {
                history.push(row.ts, &values);
            }
        }
        marks.for_each(|mark| laps.mark(mark));
        self.alarms = alarms;
        self.laps = laps;
        self.history = history;
    }

    /// Takes one telemetry packet received at `now`.
    pub fn telemetry(&mut self, sample: &Sample<TelemetryRecord>, now: Instant) {
        if let Some(record) = &mut self.record {
            record.live(row(sample));
        }
        let telemetry = sample.value.telemetry;
        self.laps.update(
            sample.ts,
            speed_m_s(&telemetry),
            telemetry.vehicle_state == VehicleState::Driving,
        );
        self.health.packet(sample.value.header.sequence, now);
        self.latest = Some(Latest {
            ts: sample.ts,
            received: now,
            header: sample.value.header,
            telemetry,
        });
        let mut values = std::mem::take(&mut self.values);
        fields::read(&telemetry, &mut values);
        self.record(sample.ts, values);
    }

    /// Takes one packet's field values for this dashboard's schema: what [`Self::telemetry`]
    /// does with a packet of the car's, for any field table.
    pub fn take_values(&mut self, ts: f64, values: &[FieldValue]) {
        let mut own = std::mem::take(&mut self.values);
        own.clear();
        own.extend_from_slice(values);
        self.record(ts, own);
    }

    fn record(&mut self, ts: f64, values: Vec<FieldValue>) {
        self.alarms.update(ts, &values);
        self.history.push(ts, &values);
        self.values = values;
    }

    /// The field table shown.
    pub fn schema(&self) -> Schema {
        self.schema
    }

    /// The newest packet's value of every field, in schema order (empty before the first).
    pub fn field_values(&self) -> &[FieldValue] {
        &self.values
    }

    /// The newest packet.
    pub fn latest(&self) -> Option<&Latest> {
        self.latest.as_ref()
    }

    /// How current the data is at `now`.
    pub fn freshness(&self, now: Instant) -> Freshness {
        match &self.latest {
            None => Freshness::NoData,
            Some(latest) => {
                let age = now.saturating_duration_since(latest.received);
                if age > self.stale_after {
                    Freshness::Stale(age)
                } else {
                    Freshness::Fresh
                }
            }
        }
    }

    /// The car's time at `now`: the newest packet's time plus its age (s).
    pub fn car_time(&self, now: Instant) -> Option<f64> {
        self.latest
            .as_ref()
            .map(|latest| latest.ts + now.saturating_duration_since(latest.received).as_secs_f64())
    }

    /// Road speed from the motor speed (km/h).
    pub fn speed_kmh(&self) -> Option<f64> {
        self.latest
            .as_ref()
            .map(|latest| speed_m_s(&latest.telemetry) * 3.6)
    }

    /// Battery power (kW, positive while discharging): amber above 90 % of the rules' limit
    /// ([`Self::power_limit_kw`]), red above it.
    pub fn power(&self) -> Option<Reading> {
        let latest = self.latest.as_ref()?;
        let kw = aer_host::run::derived::battery_power_w(&latest.telemetry) / 1_000.0;
        let limit = Self::power_limit_kw();
        let level = if kw > limit {
            Level::Critical
        } else if kw > 0.9 * limit {
            Level::Warn
        } else {
            Level::Normal
        };
        Some(Reading {
            label: "Power",
            value: kw,
            unit: "kW",
            level,
        })
    }

    /// The accumulator power limit (EV.3.3.1), as the CCM enforces it (kW).
    pub fn power_limit_kw() -> f64 {
        f64::from(POWER_LIMIT_W) / 1_000.0
    }

    /// The schema field called `name` as a reading of the newest packet.
    pub fn reading(&self, name: &str) -> Option<Reading> {
        let field = self.schema.field(name)?;
        self.reading_of(field)
    }

    fn reading_of(&self, field: Field) -> Option<Reading> {
        let value = self.values.get(field.index)?.value;
        Some(Reading {
            label: field.display.label,
            value,
            unit: field.unit(),
            level: field.level(value),
        })
    }

    /// Of the temperatures the schema gives a critical limit (pack, motor, inverter), the one
    /// closest to its limit: a pack at 55 °C of 60 matters more than a motor at 90 of 120.
    pub fn hottest(&self) -> Option<Reading> {
        self.schema
            .fields()
            .filter(|f| f.meta.unit == "degC")
            .filter_map(|f| {
                let limit = f.display.critical.filter(|c| *c > 0.0)?;
                let reading = self.reading_of(f)?;
                Some((reading.value / limit, reading))
            })
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, reading)| reading)
    }

    /// The CCM's vehicle state.
    pub fn vehicle_state(&self) -> Option<VehicleState> {
        self.latest.as_ref().map(|l| l.telemetry.vehicle_state)
    }

    /// The CCM says drive is enabled (ready-to-drive sound done).
    pub fn ready_to_drive(&self) -> bool {
        self.latest
            .as_ref()
            .is_some_and(|l| l.telemetry.ready_to_drive)
    }

    /// Alarms active now, critical first: the telemetry's, and the PCC's latched causes from
    /// its own status (PCC_Status), which the Pi forwards as it arrives.
    pub fn active_alarms(&self) -> Vec<(&'static str, Level)> {
        let mut active = self.alarms.active();
        active.extend(self.pcc_alarms.iter().copied());
        active.sort_by_key(|(_, level)| std::cmp::Reverse(*level));
        active
    }

    /// The alarm history.
    pub fn alarms(&self) -> &Alarms {
        &self.alarms
    }

    /// The plot history.
    pub fn history(&self) -> &History {
        &self.history
    }

    /// The session so far, history merged (with the compact stream).
    pub fn session_record(&self) -> Option<&SessionRecord> {
        self.record.as_ref()
    }

    /// The lap timer.
    pub fn laps(&self) -> &LapTimer {
        &self.laps
    }

    /// Ends the lap in progress at `now` (key `L`).
    /// Returns the instant marked (on the data's time base), if the car has been seen.
    pub fn mark_lap(&mut self, now: Instant) -> Option<f64> {
        let ts = self.car_time(now)?;
        self.laps.mark(ts);
        if let Some(record) = &mut self.record {
            record.mark(ts);
        }
        Some(ts)
    }

    /// Link health.
    pub fn health(&self) -> &Health {
        &self.health
    }

    /// Fields plotted in the pit view, in the order they were picked.
    pub fn plots(&self) -> &[usize] {
        &self.plots
    }

    /// The CAN messages shown and their newest frames.
    pub fn can(&self) -> &CanMessages {
        &self.can
    }

    /// Shows CAN message `index` (of [`CanMessages::topics`]), or hides it.
    pub fn toggle_can(&mut self, index: usize) {
        self.can.toggle(index);
    }

    /// Adds field `index` to the plots, or removes it.
    pub fn toggle_plot(&mut self, index: usize) {
        if let Some(at) = self.plots.iter().position(|&p| p == index) {
            self.plots.remove(at);
        } else if index < self.schema.fields.len() {
            self.plots.push(index);
        }
    }
}

/// The PCC's latched causes as the driver's display names them: what stops the car is
/// critical; a shutdown (the car switched off with the shutdown circuit) is a warning.
fn pcc_alarms(status: &aer::can::PccStatus) -> Vec<(&'static str, Level)> {
    [
        (
            status.pcc_error_tractive_silent,
            "PCC: TS sensing lost, treat TS as live",
            Level::Critical,
        ),
        (
            status.pcc_error_no_discharge,
            "PCC: TS not discharged, treat as live",
            Level::Critical,
        ),
        (
            status.pcc_error_bypassed,
            "PCC: AIR+ welded or precharge bypassed",
            Level::Critical,
        ),
        (
            status.pcc_error_accumulator_silent,
            "PCC: pack sensing lost",
            Level::Critical,
        ),
        (
            status.pcc_error_resistor_hot,
            "PCC: precharge resistor hot",
            Level::Critical,
        ),
        (
            status.pcc_error_air_plus_open,
            "PCC: AIR+ did not close",
            Level::Critical,
        ),
        (
            status.pcc_error_converters_disagree,
            "PCC: voltage sensing disagrees",
            Level::Critical,
        ),
        (
            status.pcc_error_too_fast && !status.pcc_error_bypassed,
            "PCC: precharge too fast",
            Level::Critical,
        ),
        (
            status.pcc_error_too_slow,
            "PCC: precharge too slow",
            Level::Critical,
        ),
        (
            status.pcc_error_bms_timeout,
            "PCC: BMS timeout",
            Level::Critical,
        ),
        (
            status.pcc_error_undefined_state,
            "PCC: watchdog restart",
            Level::Critical,
        ),
        (
            status.pcc_error_shutdown,
            "PCC: shutdown circuit opened",
            Level::Warn,
        ),
    ]
    .into_iter()
    .filter(|(set, _, _)| *set)
    .map(|(_, label, level)| (label, level))
    .collect()
}

fn row(sample: &Sample<TelemetryRecord>) -> Row {
    Row {
        ts: sample.ts,
        sequence: sample.value.header.sequence,
        telemetry: sample.value.telemetry,
    }
}

/// Road speed (m/s) from the motor speed, as every tier derives it.
fn speed_m_s(telemetry: &Telemetry) -> f64 {
    aer_host::run::derived::speed_m_s(telemetry)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn packet(sequence: u16, ts: f64, telemetry: Telemetry) -> Sample<TelemetryRecord> {
        Sample {
            ts,
            value: TelemetryRecord {
                header: TelemetryHeader {
                    sequence,
                    timestamp_us: 0,
                },
                telemetry,
            },
        }
    }

    #[test]
    fn the_pccs_latched_causes_are_named_on_the_drivers_display() {
        let mut dashboard = Dashboard::new(&Config::default());
        let t0 = Instant::now();
        let mut data = [0u8; 8];
        // ERROR (5) with the tractive system's converter silent (0x20 of byte 1).
        data[0] = 5;
        data[1] = 0x20;
        let status = aer::can::PccStatus::decode(&data).expect("decodes");
        let sample = Sample {
            ts: 1.0,
            value: AnyMessage::PccStatus(status),
        };
        dashboard.apply(Update::Can(Box::new(sample)), t0);
        assert_eq!(
            dashboard.active_alarms(),
            vec![("PCC: TS sensing lost, treat TS as live", Level::Critical)]
        );
        // A status without causes clears them.
        let clear = aer::can::PccStatus::decode(&[0u8; 8]).expect("decodes");
        let sample = Sample {
            ts: 2.0,
            value: AnyMessage::PccStatus(clear),
        };
        dashboard.apply(Update::Can(Box::new(sample)), t0);
        assert!(dashboard.active_alarms().is_empty());
    }

    #[test]
    fn data_is_stale_after_the_schemas_limit() {
        let mut dashboard = Dashboard::new(&Config::default());
        let t0 = Instant::now();
        assert_eq!(dashboard.freshness(t0), Freshness::NoData);
        dashboard.telemetry(&packet(1, 10.0, Telemetry::zeroed()), t0);
        let limit = Duration::from_millis(u64::from(Telemetry::TIMEOUT_MS));
        assert_eq!(dashboard.freshness(t0 + limit), Freshness::Fresh);
        let late = limit + Duration::from_millis(1);
        assert_eq!(dashboard.freshness(t0 + late), Freshness::Stale(late));
    }

    #[test]
    fn driver_values_follow_the_car_constants() {
        let mut dashboard = Dashboard::new(&Config::default());
        // 1000 rpm at the motor = 1000 / 3.5 at the wheel: 2 pi 0.35 m x 285.7/min = 37.7 km/h.
        let telemetry = Telemetry {
            motor_speed: 1_000.0,
            pack_voltage: 400.0,
            pack_current: 150.0,
            motor_temp: 90,
            inverter_temp: 80,
            ..Telemetry::zeroed()
        };
        dashboard.telemetry(&packet(1, 10.0, telemetry), Instant::now());
        let speed = dashboard.speed_kmh().unwrap();
        assert!((speed - 37.699).abs() < 0.01, "{speed}");
        let power = dashboard.power().unwrap();
        assert_eq!((power.value, power.level), (60.0, Level::Normal));
        assert_eq!(Dashboard::power_limit_kw(), 80.0);
        // Inverter 80 of 85 is closer to its limit than motor 90 of 120.
        let hottest = dashboard.hottest().unwrap();
        assert_eq!((hottest.label, hottest.value), ("Inverter", 80.0));
        assert_eq!(hottest.level, Level::Warn);
    }

    #[test]
    fn a_lost_connection_keeps_the_time_it_was_first_lost() {
        let mut dashboard = Dashboard::new(&Config::default());
        let t0 = Instant::now();
        dashboard.apply(Update::Disconnected("refused".into()), t0);
        dashboard.apply(
            Update::Disconnected("timed out".into()),
            t0 + Duration::from_secs(3),
        );
        assert_eq!(
            dashboard.health().connection,
            Connection::Lost {
                since: t0,
                reason: "timed out".into()
            }
        );
        dashboard.apply(Update::Connected, t0 + Duration::from_secs(4));
        assert_eq!(dashboard.health().connection, Connection::Connected);
    }

    #[test]
    fn plots_can_be_picked_and_dropped() {
        let mut dashboard = Dashboard::new(&Config::default());
        let soc = Schema::TELEMETRY.field("soc").unwrap().index;
        let before = dashboard.plots().len();
        dashboard.toggle_plot(soc);
        assert_eq!(dashboard.plots().last(), Some(&soc));
        dashboard.toggle_plot(soc);
        assert_eq!(dashboard.plots().len(), before);
        dashboard.toggle_plot(10_000);
        assert_eq!(dashboard.plots().len(), before);
    }
}
