//! Headless UI tests (iced_test): the real views, laid out and queried without a display.
//! Time is passed in, so staleness is tested exactly, without sleeping.

use aer::can::VehicleState;
use aer::mqtt::{Sample, TelemetryRecord};
use aer::runtime::SignalMeta;
use aer::telemetry::{FieldDisplay, Telemetry, TelemetryHeader};
use aer_dashboard::config::{Config, View};
use aer_dashboard::model::fields::{FieldValue, Schema};
use aer_dashboard::model::{Dashboard, Update};
use aer_dashboard::screenshot::{DRIVER_SIZE, PIT_SIZE};
use aer_dashboard::tune_worker as tune;
use aer_dashboard::ui::tune as tune_ui;
use aer_dashboard::ui::{App, Message};
use iced::{Element, Settings};
use iced_test::Simulator;
use iced_test::selector::Candidate;
use std::time::{Duration, Instant};

fn packet(sequence: u16, telemetry: Telemetry) -> Update {
    Update::Telemetry(Box::new(Sample {
        ts: 1_795_348_800.0 + f64::from(sequence) * 0.01,
        value: TelemetryRecord {
            header: TelemetryHeader {
                sequence,
                timestamp_us: u32::from(sequence) * 10_000,
            },
            telemetry,
        },
    }))
}

/// A car driving: 1000 rpm at the motor (37.7 km/h with the 3.5 gear and 0.35 m wheel),
/// 400 V x 150 A = 60 kW, SOC 72 %, motor 90 degC (of 120), inverter 80 degC (of 85).
fn driving() -> Telemetry {
    Telemetry {
        motor_speed: 1_000.0,
        pack_voltage: 400.0,
        pack_current: 150.0,
        soc: 72.0,
        motor_temp: 90,
        inverter_temp: 80,
        vehicle_state: VehicleState::Driving,
        ready_to_drive: true,
        ..Telemetry::zeroed()
    }
}

/// An app in `view` that has been connected since `t0` and got `telemetry` at `t0`.
fn app_with(view: View, telemetry: Telemetry, t0: Instant) -> App {
    let mut config = Config::default();
    config.display.view = view;
    let mut app = App::new(&config, t0);
    app.update(Message::Link(t0, Update::Connected));
    app.update(Message::Link(t0, packet(1, telemetry)));
    app
}

fn simulate(app: &App) -> Simulator<'_, Message> {
    let size = match app.current_view() {
        View::Driver => DRIVER_SIZE,
        View::Pit | View::Tune => PIT_SIZE,
    };
    Simulator::with_size(Settings::default(), size, app.view())
}

fn shows(app: &App, text: &str) -> bool {
    simulate(app).find(text).is_ok()
}

/// True when some text on screen contains `part`.
fn shows_part(app: &App, part: &str) -> bool {
    let part = part.to_owned();
    simulate(app)
        .find(move |candidate: Candidate<'_>| match candidate {
            Candidate::Text { content, .. } if content.contains(part.as_str()) => Some(()),
            _ => None,
        })
        .is_ok()
}

#[test]
fn driver_values_arrive_as_text() {
    let t0 = Instant::now();
    let app = app_with(View::Driver, driving(), t0);
    for expected in [
        "38",
        "72 %",
        "60 / 80 kW",
        "INVERTER",
        "80 °C",
        "DRIVING",
        "READY TO DRIVE",
        "NO FAULTS",
    ] {
        assert!(shows(&app, expected), "driver view lacks {expected:?}");
    }
    assert!(!shows_part(&app, "STALE"));

    let mut parked = driving();
    parked.vehicle_state = VehicleState::Standby;
    parked.ready_to_drive = false;
    let app = app_with(View::Driver, parked, t0);
    assert!(shows(&app, "STANDBY") && shows(&app, "NOT READY"));
    assert!(!shows(&app, "READY TO DRIVE"));
}

#[test]
fn telemetry_is_marked_stale_after_exactly_the_schemas_limit_in_both_views() {
    let t0 = Instant::now();
    // 200 ms: `timeout_ms` in schema/telemetry.yaml.
    let limit = Duration::from_millis(u64::from(Telemetry::TIMEOUT_MS));
    assert_eq!(limit, Duration::from_millis(200));
    for view in [View::Driver, View::Pit] {
        let mut app = app_with(view, driving(), t0);
        app.update(Message::Tick(t0 + limit));
        assert!(!shows_part(&app, "STALE"), "{view:?} stale at the limit");
        app.update(Message::Tick(t0 + limit + Duration::from_millis(1)));
        assert!(
            shows(&app, "STALE: no telemetry for 0.2 s"),
            "{view:?} not stale at 201 ms"
        );
        // A new packet makes it current again.
        app.update(Message::Link(
            t0 + Duration::from_millis(250),
            packet(2, driving()),
        ));
        assert!(
            !shows_part(&app, "STALE"),
            "{view:?} still stale after a packet"
        );
    }
}

#[test]
fn a_lost_broker_connection_is_obvious() {
    let t0 = Instant::now();
    for view in [View::Driver, View::Pit] {
        let mut app = app_with(view, driving(), t0);
        app.update(Message::Link(
            t0 + Duration::from_millis(10),
            Update::Disconnected("connection refused".into()),
        ));
        app.update(Message::Tick(t0 + Duration::from_secs(3)));
        assert!(
            shows(&app, "NO LINK to the broker for 3 s: connection refused"),
            "{view:?}"
        );
    }
    let mut config = Config::default();
    config.display.view = View::Driver;
    let app = App::new(&config, t0);
    assert!(shows(&app, "CONNECTING to the broker"));
}

fn pi_status(telemetry_fingerprint: u32, firmware_ok: Option<bool>) -> Update {
    Update::Status(Box::new(aer_host::reports::status::Status {
        service: "aer-raspi".into(),
        car_id: "car1".into(),
        schema_fingerprint: format!("{:#010x}", aer::can::SCHEMA_FINGERPRINT),
        telemetry_fingerprint: format!("{telemetry_fingerprint:#010x}"),
        firmware_fingerprint_seen: firmware_ok.map(|_| "0x12345678".into()),
        fingerprint_match: firmware_ok,
        last_packet_ts: None,
        undecodable_packets: 0,
        undecodable_fingerprint: None,
        problems: Default::default(),
        message_health: Default::default(),
        bus_traffic: Default::default(),
        message_rates: Default::default(),
        mqtt_clients: Default::default(),
        xcp_gateway: None,
    }))
}

#[test]
fn the_link_panel_shows_how_far_behind_the_pi_serves_this_pit_and_the_pis_problems() {
    let t0 = Instant::now();
    let mut config = Config::default();
    config.display.view = View::Pit;
    let mut app = App::new(&config, t0);
    app.update(Message::Link(
        t0,
        Update::Identity("aer-dashboard-7".into()),
    ));
    app.update(Message::Link(t0, Update::Connected));
    let client = |id: &str, lag_ms: u64, dropped: u64| aer_host::reports::status::MqttClient {
        client_id: id.into(),
        listener: "v4-pit".into(),
        protocol: "3.1.1".into(),
        lag_ms,
        queued_bytes: 48_000,
        dropped,
    };
    let clients = vec![
        (client("aer-dashboard-7", 2_100, 312), 40),
        (client("grafana", 0, 0), 0),
    ];
    let Update::Status(mut status) = pi_status(aer::telemetry::TELEMETRY_FINGERPRINT, Some(true))
    else {
        unreachable!("pi_status makes a status");
    };
    status.problems.mqtt_clients = aer_host::reports::status::clients_behind(&clients);
    status.mqtt_clients = clients.into_iter().map(|(client, _)| client).collect();
    app.update(Message::Link(t0, Update::Status(status)));
    assert!(shows_part(
        &app,
        "Pi to here: 2.1 s behind   312 live messages dropped   48 kB waiting   MQTT 3.1.1 on `v4-pit`   1 other clients"
    ));
    assert!(shows_part(
        &app,
        "Pi problem, MQTT clients: MQTT clients not keeping up"
    ));
    assert!(shows_part(
        &app,
        "`aer-dashboard-7` (v4-pit) 2.1 s behind, 40 messages dropped"
    ));
    assert!(
        !shows_part(&app, "`grafana`"),
        "a client keeping up is no problem"
    );
}

#[test]
fn a_schema_mismatch_says_which_side_to_rebuild() {
    let t0 = Instant::now();
    let ours = aer::telemetry::TELEMETRY_FINGERPRINT;
    let mut config = Config::default();
    config.display.view = View::Driver;

    // The Pi runs another schema: its payloads do not decode here.
    let mut app = App::new(&config, t0);
    app.update(Message::Link(t0, Update::Connected));
    app.update(Message::Link(t0, pi_status(ours ^ 1, Some(true))));
    app.update(Message::Link(
        t0,
        Update::Undecodable {
            topic: "aer/car1/telemetry".into(),
            error: "missing field `pack_temp`".into(),
        },
    ));
    assert!(shows(
        &app,
        "TELEMETRY UNREADABLE: the Pi runs another schema"
    ));
    app.update(Message::ToggleView);
    assert!(
        shows_part(&app, "missing field `pack_temp`"),
        "the pit view names the error"
    );

    // The CCM runs another schema: the Pi rejects its packets, so nothing arrives.
    let mut app = App::new(&config, t0);
    app.update(Message::Link(t0, Update::Connected));
    app.update(Message::Link(t0, pi_status(ours, Some(false))));
    assert!(shows(
        &app,
        "FIRMWARE ON ANOTHER SCHEMA: the Pi rejects its packets, flash the CCM"
    ));

    // All agree: no banner once data flows.
    let mut app = app_with(View::Driver, driving(), t0);
    app.update(Message::Link(t0, pi_status(ours, Some(true))));
    assert!(!shows_part(&app, "SCHEMA") && !shows_part(&app, "UNREADABLE"));
}

#[test]
fn a_fault_flag_shows_its_name() {
    let t0 = Instant::now();
    let mut faulty = driving();
    faulty.fault_bse = true;
    faulty.motor_stall_fault = true;
    let driver = app_with(View::Driver, faulty, t0);
    let bse = Schema::TELEMETRY.field("fault_bse").unwrap().display.label;
    let stall = Schema::TELEMETRY
        .field("motor_stall_fault")
        .unwrap()
        .display
        .label;
    assert_ne!(
        bse, "fault_bse",
        "the schema gives the fault a readable name"
    );
    assert!(shows(&driver, bse), "driver view lacks {bse:?}");
    assert!(shows(&driver, stall), "driver view lacks {stall:?}");
    assert!(!shows(&driver, "NO FAULTS"));

    // The pit view's history has it, with the time it was raised.
    let mut pit = app_with(View::Pit, driving(), t0);
    pit.update(Message::Link(
        t0 + Duration::from_millis(10),
        packet(2, faulty),
    ));
    assert!(shows(&pit, "FAULT"));
    assert!(shows(&pit, "12:00:00.020"), "the packet's time of day");
}

#[test]
fn the_dtis_fault_code_and_limits_read_in_words() {
    use aer::can::{DtiDriveEnable, DtiFaultCode};
    let t0 = Instant::now();
    let mut limited = driving();
    limited.dti_drive_enabled = DtiDriveEnable::Enabled;
    limited.dti_limit_motor_temp = true;
    // A limit is a warning the driver view names.
    let driver = app_with(View::Driver, limited, t0);
    assert!(shows(&driver, "DTI limit: motor temperature"));

    let mut faulted = limited;
    faulted.dti_fault_code = DtiFaultCode::ControllerOvertemp;
    faulted.dti_drive_enabled = DtiDriveEnable::Disabled;
    let pit = app_with(View::Pit, faulted, t0);
    assert!(
        shows_part(&pit, "CONTROLLER_OVERTEMP"),
        "the fault code in words"
    );
    assert!(shows_part(&pit, "DISABLED"), "drive enable in words");
}

#[test]
fn every_schema_field_is_in_the_pit_view() {
    let app = app_with(View::Pit, driving(), Instant::now());
    let mut ui = simulate(&app);
    for field in Schema::TELEMETRY.fields() {
        let label = field.display.label;
        let plotted = ui.find(format!("● {label}")).is_ok();
        assert!(
            plotted || ui.find(label).is_ok(),
            "pit view lacks {label:?}"
        );
    }
}

/// A schema with one field this code has never heard of, as if it were added to telemetry.yaml.
fn schema_with_shocktravel5() -> Schema {
    let mut fields = Telemetry::FIELDS.to_vec();
    let mut display = Telemetry::DISPLAY.to_vec();
    let template = Schema::TELEMETRY.field("shocktravel4").unwrap();
    fields.push(SignalMeta {
        name: "shocktravel5",
        comment: "Fifth shock travel sensor.",
        ..*template.meta
    });
    display.push(FieldDisplay {
        label: "shocktravel5",
        ..*template.display
    });
    Schema {
        fields: Vec::leak(fields),
        display: Vec::leak(display),
    }
}

#[test]
fn a_new_schema_field_appears_in_the_pit_view() {
    let schema = schema_with_shocktravel5();
    let config = Config::default();
    let mut model = Dashboard::with_schema(schema, &config);
    let t0 = Instant::now();
    model.apply(Update::Connected, t0);
    let mut values: Vec<FieldValue> = (0..schema.fields.len())
        .map(|_| FieldValue {
            value: 0.0,
            label: None,
        })
        .collect();
    if let Some(last) = values.last_mut() {
        last.value = 31.42;
    }
    model.take_values(1.0, &values);
    let app = App::with_model(&config, model, View::Pit, t0);
    assert!(shows(&app, "shocktravel5"));
    assert!(shows(&app, "31.42"));
}

#[test]
fn clicking_a_field_plots_it() {
    let t0 = Instant::now();
    let mut app = app_with(View::Pit, driving(), t0);
    let soc = Schema::TELEMETRY.field("soc").unwrap();
    assert!(!shows(&app, &format!("● {}", soc.display.label)));
    let messages: Vec<Message> = {
        let mut ui = simulate(&app);
        ui.click(soc.display.label).expect("the SOC row");
        ui.into_messages().collect()
    };
    assert!(matches!(messages.as_slice(), [Message::TogglePlot(i)] if *i == soc.index));
    for message in messages {
        app.update(message);
    }
    assert!(shows(&app, &format!("● {}", soc.display.label)));
    assert!(shows(&app, "72.0 %"), "the plot's title shows the value");
}

#[test]
fn keys_switch_the_view_and_mark_laps() {
    let t0 = Instant::now();
    let mut app = app_with(View::Driver, driving(), t0);
    let (control, mut link_told) = aer_dashboard::link::Control::channel();
    app.update(Message::LinkReady(control));
    assert!(matches!(
        link_told.try_recv(),
        Ok(aer_dashboard::link::Request::ShowCan(_))
    ));
    assert!(shows(&app, "LAP 1"));
    app.update(Message::Link(
        t0 + Duration::from_secs(62),
        packet(6_200, driving()),
    ));
    app.update(Message::MarkLap);
    assert!(shows(&app, "LAP 2"));
    // The mark goes to the Pi too, for the session's record and the run report.
    let Ok(aer_dashboard::link::Request::Mark(mark)) = link_told.try_recv() else {
        panic!("no mark sent to the Pi");
    };
    assert_eq!(mark.by, "driver");
    assert!(shows(&app, "last 1:02.0   best 1:02.0"));
    app.update(Message::ToggleView);
    assert_eq!(app.current_view(), View::Pit);
    let _: Element<'_, Message> = app.view();
}

/// The demo replays the bundled session in a loop, its times carrying on: each loop is one
/// run (start, drive, back to OFF), and the driver's lap timer closes a lap at each loop.
#[test]
fn the_demo_course_closes_a_lap_each_loop() {
    use aer_dashboard::session::{BUNDLED_SESSION, load};
    let session = load(BUNDLED_SESSION, "car1");
    let mut model = Dashboard::new(&Config::default());
    let t0 = Instant::now();
    let first = session.samples.first().map(|s| s.ts).expect("packets");
    let length = session.samples.last().map(|s| s.ts).expect("packets") - first + 0.01;
    for pass in 0..3 {
        for sample in &session.samples {
            let mut sample = sample.clone();
            sample.ts += f64::from(pass) * length;
            let now = t0 + Duration::from_secs_f64(sample.ts - first);
            model.telemetry(&sample, now);
        }
    }
    let laps = model.laps();
    assert_eq!(
        laps.completed(),
        2,
        "a lap closed at each of the two loop restarts"
    );
    let last = laps.last().expect("a lap");
    assert!(
        (25.0..45.0).contains(&last),
        "one run of the demo: {last} s"
    );
    assert_eq!(laps.best(), Some(last), "every loop is the same run");
}

/// The pit view on the car's 800x480 display and on a 1280x800 laptop: the same fields, fault
/// names in full, the Pi's counters with their units, a status code in hex.
#[test]
fn the_pit_view_fits_both_screens() {
    let t0 = Instant::now();
    let mut car = driving();
    car.fault_apps_brake_plausibility = true;
    let app = app_with(View::Pit, car, t0);
    for size in [DRIVER_SIZE, PIT_SIZE] {
        let simulate = || Simulator::with_size(Settings::default(), size, app.view());
        assert!(
            simulate().find("APPS/brake plausibility").is_ok(),
            "{size:?}: the fault's whole name"
        );
        assert!(
            simulate().find("0x00").is_ok(),
            "{size:?}: the IMD code in hex"
        );
        assert!(
            simulate().find("Throttle").is_ok() && simulate().find("Fault history").is_ok(),
            "{size:?}: fields and fault history"
        );
        let units = simulate().find(|candidate: Candidate<'_>| match candidate {
            Candidate::Text { content, .. } if content.contains("lost 0 packets") => Some(()),
            _ => None,
        });
        assert!(units.is_ok(), "{size:?}: counts with their units");
    }
}

/// Batches of the compact stream that never came (a radio dropout) are counted in the link
/// panel, beside the lost packets.
#[test]
fn the_link_panel_counts_missed_stream_batches() {
    let t0 = Instant::now();
    let mut app = app_with(View::Pit, driving(), t0);
    app.update(Message::Link(t0, Update::StreamGap(149)));
    app.update(Message::Link(t0, Update::StreamGap(1)));
    let shown = simulate(&app).find(|candidate: Candidate<'_>| match candidate {
        Candidate::Text { content, .. } if content.contains("missed 150 stream batches") => {
            Some(())
        }
        _ => None,
    });
    assert!(shown.is_ok(), "the missed batches in the link panel");
}

/// A frame of all-zero bytes of `meta`'s message, as the Pi publishes it on its CAN topic,
/// read back with the topic's own type.
fn can_frame(meta: &aer::runtime::MessageMeta, bytes: &[u8]) -> Update {
    let message = aer::can::AnyMessage::decode(meta.id, meta.extended, bytes).unwrap();
    let (suffix, payload) = aer::mqtt::encode_message(&message, 1_795_348_800.0, "can1");
    let prefix = "aer/car1";
    aer_dashboard::link::decode(prefix, &format!("{prefix}/{suffix}"), &payload)
}

#[test]
fn every_can_message_of_the_schema_is_on_the_pit_view() {
    // The panel lists `aer::can::MESSAGES`, which `cargo build` regenerates from aer.dbc: a
    // message added there is listed with no dashboard change.
    let app = app_with(View::Pit, driving(), Instant::now());
    let mut ui = simulate(&app);
    for meta in aer::can::MESSAGES {
        assert!(ui.find(meta.name).is_ok(), "pit view lacks {}", meta.name);
    }
}

#[test]
fn a_clicked_can_message_is_subscribed_and_shows_its_signals_in_words() {
    use aer::can::DtiTemperatures;
    let t0 = Instant::now();
    let mut app = app_with(View::Pit, driving(), t0);
    // The link starts and hands the application its control; what the application tells it
    // is what it subscribes to.
    let (control, mut link_told) = aer_dashboard::link::Control::channel();
    app.update(Message::LinkReady(control));
    let mut shown = || match link_told.try_recv() {
        Ok(aer_dashboard::link::Request::ShowCan(shown)) => Some(shown),
        _ => None,
    };
    assert_eq!(shown(), Some(vec![]), "nothing shown, nothing subscribed");
    let messages: Vec<Message> = {
        // Tall enough that the panel, below the telemetry fields, needs no scrolling.
        let tall = iced::Size::new(PIT_SIZE.width, 2_400.0);
        let mut ui = Simulator::with_size(Settings::default(), tall, app.view());
        ui.click("DTI_Temperatures").expect("the message's name");
        ui.into_messages().collect()
    };
    let [Message::ToggleCan(index)] = messages.as_slice() else {
        panic!("{messages:?}");
    };
    app.update(Message::ToggleCan(*index));
    assert_eq!(shown(), Some(vec!["can/dti_temperatures"]));
    assert!(shows(&app, "no frame yet"));

    // Controller 45.6 degC, motor -12.3 degC (big-endian, 0.1 degC), fault code 0x04.
    let update = can_frame(
        DtiTemperatures::META,
        &[0x01, 0xC8, 0xFF, 0x85, 0x04, 0, 0, 0],
    );
    app.update(Message::Link(t0, update));
    for expected in ["DTI_ControllerTemp", "45.6", "-12.3", "°C", "DTI_FaultCode"] {
        assert!(shows(&app, expected), "pit view lacks {expected:?}");
    }
    assert!(shows(&app, "every 100 ms, stale after 500 ms"));

    // Hidden again: unsubscribed, and its signals gone.
    app.update(Message::ToggleCan(*index));
    assert_eq!(shown(), Some(vec![]));
    assert!(!shows(&app, "DTI_ControllerTemp"));
}

#[test]
fn a_can_message_that_stops_is_stale_after_exactly_its_generated_limit() {
    use aer::can::{DtiTemperatures, PccStatus};
    let t0 = Instant::now();
    let mut config = Config::default();
    config.display.view = View::Pit;
    config.display.can_messages = vec!["PCC_Status".into(), "DTI_Temperatures".into()];
    let mut app = App::new(&config, t0);
    app.update(Message::Link(t0, Update::Connected));
    app.update(Message::Link(t0, packet(1, driving())));
    app.update(Message::Link(t0, can_frame(PccStatus::META, &[0; 8])));
    app.update(Message::Link(t0, can_frame(DtiTemperatures::META, &[0; 8])));
    // Each message by its own limit: PCC_Status 100 ms (AerTimeoutMs), DTI_Temperatures
    // 500 ms (five 100 ms cycles). Telemetry keeps coming, so only the messages go stale.
    let pcc = Duration::from_millis(u64::from(PccStatus::TIMEOUT_MS));
    let dti = Duration::from_millis(u64::from(DtiTemperatures::TIMEOUT_MS));
    assert_eq!((pcc.as_millis(), dti.as_millis()), (100, 500));
    let one_ms = Duration::from_millis(1);
    let at = |app: &mut App, when: Duration, sequence: u16| {
        app.update(Message::Link(t0 + when, packet(sequence, driving())));
    };
    at(&mut app, pcc, 2);
    assert!(!shows_part(&app, "STALE"), "stale at PCC_Status's limit");
    at(&mut app, pcc + one_ms, 3);
    assert!(shows(&app, "STALE: no frame for 0.1 s"));
    assert_eq!(count_part(&app, "STALE"), 1, "only PCC_Status is stale");
    at(&mut app, dti, 4);
    assert_eq!(count_part(&app, "STALE"), 1, "DTI_Temperatures is not yet");
    at(&mut app, dti + one_ms, 5);
    assert!(shows(&app, "STALE: no frame for 0.5 s"));
    assert_eq!(count_part(&app, "STALE"), 2);
    // A new frame makes it current again.
    app.update(Message::Link(
        t0 + dti + one_ms,
        can_frame(DtiTemperatures::META, &[0; 8]),
    ));
    assert_eq!(count_part(&app, "STALE"), 1);
}

/// How many texts on screen contain `part`.
fn count_part(app: &App, part: &str) -> usize {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicUsize, Ordering};
    let part = part.to_owned();
    let count = Arc::new(AtomicUsize::new(0));
    let seen = count.clone();
    // Never matches, so every text on screen is looked at once.
    let _ = simulate(app).find(move |candidate: Candidate<'_>| -> Option<()> {
        if let Candidate::Text { content, .. } = candidate {
            if content.contains(part.as_str()) {
                seen.fetch_add(1, Ordering::Relaxed);
            }
        }
        None
    });
    count.load(Ordering::Relaxed)
}

#[test]
fn the_pit_view_shows_the_pis_bus_loads_and_slow_messages() {
    use aer_host::reports::traffic::{BusTraffic, MessageRate};
    let t0 = Instant::now();
    let mut app = app_with(View::Pit, driving(), t0);
    let Update::Status(mut status) = pi_status(aer::telemetry::TELEMETRY_FINGERPRINT, Some(true))
    else {
        unreachable!()
    };
    status.bus_traffic.insert(
        "can0".into(),
        BusTraffic {
            frames: 1_440,
            frames_per_s: 1_440.0,
            bits_per_s: 194_650.0,
            load: 0.3893,
        },
    );
    let rate = |measured: f64, declared: f64| MessageRate {
        frames: 50,
        measured_hz: Some(measured),
        declared_hz: Some(declared),
    };
    let can1 = status.message_rates.entry("can1".into()).or_default();
    can1.insert("DTI_Speed".into(), rate(50.0, 100.0));
    can1.insert("DTI_Flags".into(), rate(99.9, 100.0));
    app.update(Message::Link(t0, Update::Status(status)));
    assert!(shows_part(&app, "Pi buses: can0 38.9 % (1440 frames/s)"));
    assert!(shows_part(&app, "SLOW: DTI_Speed on can1 50 of 100 Hz"));
    assert!(!shows_part(&app, "DTI_Flags on can1"));
}

/// On the comp car (DTI) the bench inverter's mirrored fields are not live, and the reverse:
/// which fields those are comes from what the schema says each field mirrors, and which
/// messages the car carries from the Pi's status.
#[test]
fn the_pit_view_marks_the_other_inverters_fields_not_fitted() {
    use aer::can::MESSAGES;
    use aer_host::reports::traffic::MessageRate;
    let cars = [
        ("the comp car (DTI)", "MCU"),
        ("the bench (IFL100)", "DTI_"),
    ];
    for (car, other) in cars {
        let t0 = Instant::now();
        let mut app = app_with(View::Pit, driving(), t0);
        let carried: Vec<&str> = MESSAGES
            .iter()
            .map(|meta| meta.name)
            .filter(|name| !name.starts_with(other))
            .collect();
        // Before the Pi reports any traffic, nothing is judged.
        assert!(!shows_part(&app, "not fitted"), "{car}: before any status");
        let Update::Status(mut status) =
            pi_status(aer::telemetry::TELEMETRY_FINGERPRINT, Some(true))
        else {
            unreachable!()
        };
        let rates = status.message_rates.entry("can1".into()).or_default();
        for name in &carried {
            rates.insert(
                (*name).into(),
                MessageRate {
                    frames: 10,
                    measured_hz: Some(10.0),
                    declared_hz: Some(10.0),
                },
            );
        }
        app.update(Message::Link(t0, Update::Status(status)));
        let absent = Telemetry::DISPLAY
            .iter()
            .filter(|d| d.mirrors.is_some_and(|m| m.starts_with(other)))
            .count();
        assert!(absent > 0, "{car}: the schema mirrors the other inverter");
        assert_eq!(count_part(&app, "not fitted"), absent, "{car}");
    }
    // The fields the issue named: the IFL100's states on the comp car.
    let motor_state = Telemetry::DISPLAY
        .iter()
        .find(|d| d.label == "Motor state")
        .and_then(|d| d.mirrors);
    assert_eq!(motor_state, Some("MCU1"));
}

/// A connected Tune page (unlocked, on the defaults) on an app that got `telemetry` at `t0`,
/// and the requests its XCP worker would carry out.
fn tune_page(telemetry: Telemetry, t0: Instant) -> (App, std::sync::mpsc::Receiver<tune::Request>) {
    let mut app = app_with(View::Tune, telemetry, t0);
    let (control, requests) = tune::Control::channel();
    app.update(Message::TuneWorker(tune::Event::Ready(control)));
    assert_eq!(
        requests.try_recv(),
        Ok(tune::Request::Connect),
        "shown: it connects"
    );
    app.update(Message::TuneWorker(tune::Event::Connected {
        page: Box::new(aer::calibration::Calibration::DEFAULT.to_page()),
        ecu_page: 0,
        locked: false,
    }));
    (app, requests)
}

/// Clicks `label` and applies what the page sends; the messages sent.
fn click(app: &mut App, label: &str) -> Vec<Message> {
    let messages: Vec<Message> = {
        let mut ui = simulate(app);
        ui.click(label).expect(label);
        ui.into_messages().collect()
    };
    for message in messages.clone() {
        app.update(message);
    }
    messages
}

#[test]
fn tab_reaches_the_tune_page_which_connects_when_first_shown() {
    let t0 = Instant::now();
    let mut app = app_with(View::Driver, driving(), t0);
    let (control, requests) = tune::Control::channel();
    app.update(Message::TuneWorker(tune::Event::Ready(control)));
    assert!(
        requests.try_recv().is_err(),
        "the driver view connects nothing"
    );
    app.update(Message::ToggleView);
    app.update(Message::ToggleView);
    assert_eq!(app.current_view(), View::Tune);
    assert_eq!(requests.try_recv(), Ok(tune::Request::Connect));
    assert!(shows(&app, "connecting"));
    app.update(Message::TuneWorker(tune::Event::Disconnected(
        "cannot reach the CCM through 127.0.0.1:5555: connection refused".into(),
    )));
    assert!(shows_part(&app, "not connected: cannot reach the CCM"));
    // Every parameter of the schema is listed, by section, with its limits.
    assert!(shows(&app, "traction_kp"));
    assert!(shows(&app, "launch_slip_target[3] @ 20 m/s"));
    assert!(shows(&app, "TRACTION"));
    app.update(Message::ToggleView);
    assert_eq!(app.current_view(), View::Driver);
}

#[test]
fn saving_is_offered_only_parked_with_the_tractive_system_off() {
    let t0 = Instant::now();
    let (mut driving_app, requests) = tune_page(driving(), t0);
    assert!(shows(&driving_app, "Save (stop, tractive off)"));
    assert!(
        click(&mut driving_app, "Save (stop, tractive off)").is_empty(),
        "not while driving"
    );
    assert!(requests.try_recv().is_err());

    let parked = Telemetry {
        vehicle_state: VehicleState::Standby,
        ..Telemetry::zeroed()
    };
    let (mut parked_app, requests) = tune_page(parked, t0);
    click(&mut parked_app, "Save to flash");
    assert_eq!(requests.try_recv(), Ok(tune::Request::Save));
    parked_app.update(Message::TuneWorker(tune::Event::Saved));
    assert!(shows_part(&parked_app, "saved to flash"));
}

#[test]
fn a_write_goes_to_the_worker_and_its_refusal_shows_at_the_parameter() {
    let t0 = Instant::now();
    let (mut app, requests) = tune_page(driving(), t0);
    let kp = aer::calibration::PARAMETERS
        .iter()
        .position(|p| p.name == "launch_kp")
        .expect("in the schema");
    app.update(Message::Tune(tune_ui::Action::Edit((kp, 0), "210".into())));
    app.update(Message::Tune(tune_ui::Action::Write((kp, 0))));
    let request = requests.try_recv().expect("a write");
    assert_eq!(
        request,
        tune::Request::Write {
            parameter: kp,
            values: vec![210.0],
            edited: vec![0],
        }
    );
    app.update(Message::TuneWorker(tune::Event::Refused {
        request,
        reason: "only at standstill".into(),
        values_now: vec![Some(200.0)],
    }));
    assert!(shows(&app, "refused: only at standstill"));
    assert!(shows(&app, "200 Nm"), "the value as the CCM has it");
}
