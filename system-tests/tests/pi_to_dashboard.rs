//! End to end with the real components: the Pi service (its own pipeline, as `serve` runs
//! it) replays the bundled session and publishes on its embedded rumqttd broker; the
//! dashboard's own MQTT link reads the typed topics; its model and views must show exactly what the car sent, and of the CAN
//! topics only those of the messages the pit view shows.

use aer::can::{AnyMessage, DtiTemperatures, PccStatus};
use aer_dashboard::config::{Config, StreamFormat, View};
use aer_dashboard::link::{self, Control, Event, Settings};
use aer_dashboard::model::health::SchemaMatch;
use aer_dashboard::model::{Dashboard, Update};
use aer_dashboard::screenshot::PIT_SIZE;
use aer_dashboard::session;
use aer_dashboard::session::BUNDLED_SESSION;
use aer_dashboard::ui::App;
use aer_host::reports::counters::Counters;
use aer_raspi::broker;
use aer_raspi::config::Config as ServiceConfig;
use aer_raspi::service::{Job, Pipeline};
use aer_raspi::source::replay::{ReplayOptions, replay};
use iced::futures::StreamExt;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use tokio_util::sync::CancellationToken;

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

/// Waits for the link's next event; a stuck link fails the test instead of hanging it.
async fn next_event(stream: &mut (impl iced::futures::Stream<Item = Event> + Unpin)) -> Event {
    tokio::time::timeout(Duration::from_secs(30), stream.next())
        .await
        .expect("an event within 30 s")
        .expect("the link never ends")
}

/// Draws the pit view of `model` at both screen sizes into the tests' target directory
/// (`pit-<name>-1280x800.png`, ...), for the docs and a reviewer's eye; returns the files.
fn pit_screenshots(model: &Dashboard, now: Instant, name: &str) -> Vec<std::path::PathBuf> {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("pit-link");
    let mut offscreen = aer_dashboard::screenshot::Offscreen::new().expect("software renderer");
    let app = App::with_model(&Config::default(), model.clone(), View::Pit, now);
    aer_dashboard::screenshot::every_size(&mut offscreen, &app, &dir, &format!("pit-{name}"))
        .expect("screenshots written")
}

/// Waits for the next update.
async fn next(
    stream: &mut (impl iced::futures::Stream<Item = Event> + Unpin),
) -> (Instant, Update) {
    match next_event(stream).await {
        Event::Update(at, update) => (at, update),
        Event::Ready(_) => panic!("the link started twice"),
    }
}

/// A link's control, the first thing it hands over.
async fn started(
    stream: &mut (impl iced::futures::Stream<Item = Event> + Unpin),
) -> (Control, Update) {
    let control = match next_event(stream).await {
        Event::Ready(control) => control,
        Event::Update(_, update) => panic!("an update before the link's control: {update:?}"),
    };
    match next_event(stream).await {
        Event::Update(_, Update::Identity(id)) if id.starts_with("aer-dashboard-") => {
            (control, Update::Identity(id))
        }
        Event::Update(_, other) => panic!("the link's client id first, got {other:?}"),
        Event::Ready(_) => panic!("the link started twice"),
    }
}

/// The Pi service's configuration in `dir`: the repository's broker config on `port`, with
/// segments and a publish queue that hold a replay run flat out (the Pi's are sized for the
/// car's 100 packets/s); the store and the raw log in `dir`.
fn service_config(dir: &Path, port: u16) -> ServiceConfig {
    let broker_config = dir.join("rumqttd.toml");
    let text = broker::DEFAULT_CONFIG
        .replace("127.0.0.1:1883", &format!("127.0.0.1:{port}"))
        .replace("max_segment_size = 262144", "max_segment_size = 67108864");
    std::fs::write(&broker_config, text).expect("broker config");
    let mut config = ServiceConfig::default();
    config.broker.config = Some(broker_config);
    config.broker.queue = 100_000;
    config.store.path = dir.join("store.sqlite");
    config.raw_log.dir = dir.join("raw");
    config
}

/// Applies updates to `model` until the link says it is connected (and so subscribed).
async fn until_connected(
    updates: &mut (impl iced::futures::Stream<Item = Event> + Unpin),
    model: &mut Dashboard,
) {
    loop {
        let (at, update) = next(updates).await;
        let connected = update == Update::Connected;
        model.apply(update, at);
        if connected {
            return;
        }
    }
}

/// The pipeline's task: its counters as it ended, or why it failed.
type Running = tokio::task::JoinHandle<
    Result<aer_host::reports::counters::ServiceCounters, Box<dyn std::error::Error + Send + Sync>>,
>;

/// Runs `pipeline` until the returned sender is dropped, and replays the bundled session into
/// it flat out meanwhile (its input stays open).
fn run_and_replay(
    pipeline: Pipeline,
    input: &aer_raspi::source::Sender,
    counters: &Arc<Counters>,
) -> (
    tokio::sync::oneshot::Sender<()>,
    Running,
    tokio::task::JoinHandle<()>,
) {
    let (stop, running) = run_until_stopped(pipeline);
    let replaying = {
        let (input, counters) = (input.clone(), counters.clone());
        tokio::spawn(async move { feed(BUNDLED_SESSION, &input, &counters).await })
    };
    (stop, running, replaying)
}

/// Runs `pipeline` until the returned sender is dropped.
fn run_until_stopped(pipeline: Pipeline) -> (tokio::sync::oneshot::Sender<()>, Running) {
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let running = tokio::spawn(async move {
        pipeline
            .run(async {
                let _ = stopped.await;
            })
            .await
            .map_err(Into::into)
    });
    (stop, running)
}

/// The loopback listener's connection settings with the pit's username and password.
const PIT_AUTH: &str = "    dynamic_filters = true\n    auth = { pit = \"Xq7-fast-laps\" }";

/// The embedded broker and its gate, configured by `text`.
async fn start_broker(text: &str) -> broker::Broker {
    let broker_config = broker::parse(text).expect("broker config");
    broker::start(
        broker_config,
        Arc::new(Counters::default()),
        CancellationToken::new(),
    )
    .await
    .expect("broker")
}

/// Replays candump `log` flat out into a fed pipeline's `input`.
async fn feed(log: &str, input: &aer_raspi::source::Sender, counters: &Counters) {
    let stats = replay(
        log.as_bytes(),
        input.clone(),
        counters,
        ReplayOptions::FAST,
        &CancellationToken::new(),
    )
    .await;
    assert_eq!(stats.bad_lines, 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_replayed_session_reaches_the_dashboard_intact() {
    let expected = session::load(BUNDLED_SESSION, "car1");
    assert_eq!(expected.samples.len(), 4_500);

    // The Pi service's pipeline, as `serve` runs it, its source not yet started.
    let dir = tempfile::tempdir().expect("temp dir");
    let port = free_port();
    let mut pipeline = Pipeline::start(service_config(dir.path(), port), Job::Fed)
        .await
        .expect("the Pi service starts");
    let counters = pipeline.counters();
    let input = pipeline.input().expect("a fed pipeline's input");

    // The dashboard's link, showing one CAN message: connected means subscribed.
    let shown = aer::mqtt::can::DTI_TEMPERATURES.suffix();
    let settings = Settings {
        host: "127.0.0.1".into(),
        port,
        credentials: None,
        tls_ca: None,
        prefix: "aer/car1".into(),
        can: vec![shown],
        format: StreamFormat::Json,
        join_history_s: 0,
    };
    let mut updates = Box::pin(link::stream(settings));
    let (control, _) = started(&mut updates).await;
    let mut config = Config::default();
    config.display.can_messages = vec![DtiTemperatures::META.name.into()];
    let mut model = Dashboard::new(&config);
    until_connected(&mut updates, &mut model).await;

    // The session through the service (replay -> ingest -> typed topics), while the dashboard
    // reads; the input stays open until the end of the test.
    let (stop, running, replaying) = run_and_replay(pipeline, &input, &counters);

    // The session's DTI_Temperatures frames: the only CAN frames the dashboard may get.
    let dti_temperatures = BUNDLED_SESSION
        .lines()
        .filter_map(|line| aer_host::formats::candump::parse_line(line, |_| 0).ok())
        .filter(|frame| aer::runtime::raw_id(frame.id) == (DtiTemperatures::META.id, true))
        .count();
    assert!(dti_temperatures > 100, "{dti_temperatures}");

    let mut received = Vec::new();
    let mut can_frames = 0;
    let mut pcc_frames = 0;
    while received.len() < expected.samples.len()
        || can_frames < dti_temperatures
        // A status from after the traffic: it knows which schema the car sends.
        || model.health().schema_match() == SchemaMatch::Unknown
    {
        let (at, update) = next(&mut updates).await;
        match &update {
            Update::Telemetry(sample) => received.push((**sample).clone()),
            Update::Can(sample) => match sample.value {
                AnyMessage::DtiTemperatures(_) => can_frames += 1,
                // The driver's display names the PCC's latched causes: always subscribed.
                AnyMessage::PccStatus(_) => pcc_frames += 1,
                _ => panic!(
                    "a message the pit view does not show and the driver's display does not need: {:?}",
                    sample.value.meta().name
                ),
            },
            _ => {}
        }
        model.apply(update, at);
    }
    replaying.await.expect("the replay");
    assert_eq!(can_frames, dti_temperatures);
    assert!(
        pcc_frames > 100,
        "the PCC's status reaches the driver's display: {pcc_frames}"
    );
    assert_eq!(counters.snapshot().publish_dropped, 0);

    // Every packet, in order, with the values the generated decoder reads from the log.
    assert_eq!(received, expected.samples);
    let health = model.health();
    assert_eq!(health.packets, 4_500);
    assert_eq!(health.lost, 0);
    assert_eq!(health.undecodable, 0);
    assert_eq!(health.schema_match(), SchemaMatch::Match);

    // The views show the last packet.
    let last = expected.samples.last().expect("a packet");
    let now = model.latest().expect("latest").received;
    let soc = format!("{:.1}", last.value.telemetry.soc);
    let app = App::with_model(&config, model, View::Pit, now);
    let mut ui = iced_test::Simulator::with_size(iced::Settings::default(), PIT_SIZE, app.view());
    assert!(ui.find(soc.as_str()).is_ok(), "pit view lacks SOC {soc}");
    assert!(ui.find("connected").is_ok());
    assert!(ui.find("DTI_ControllerTemp").is_ok());

    // Picking another message subscribes to it on the live connection, no reconnect.
    control.show_can([shown, aer::mqtt::can::PCC_STATUS.suffix()]);
    loop {
        // The broker's acknowledgement of the new subscription.
        if next(&mut updates).await.1 == Update::Connected {
            break;
        }
    }
    // One PCC_Status frame on the bus, after the session.
    let pcc_frame = format!(
        "(1795348800.000000) can0 {:03X}#0000000000000000",
        PccStatus::META.id
    );
    feed(&pcc_frame, &input, &counters).await;
    let pcc = AnyMessage::decode(PccStatus::META.id, false, &[0; 8]).expect("frame");
    loop {
        match next(&mut updates).await.1 {
            Update::Can(sample) => {
                assert_eq!(sample.value, pcc);
                break;
            }
            Update::Disconnected(why) => panic!("the link dropped: {why}"),
            _ => {}
        }
    }

    // The source ends: the service stops cleanly.
    drop(input);
    running
        .await
        .expect("the pipeline's task")
        .expect("the pipeline stops cleanly");
    drop(stop);
}

/// The Pi service as a fed pipeline, its broker on `port`: the pipeline, its counters and
/// its input.
async fn fed_pi(dir: &Path, port: u16) -> (Pipeline, Arc<Counters>, aer_raspi::source::Sender) {
    let mut pipeline = Pipeline::start(service_config(dir, port), Job::Fed)
        .await
        .expect("the Pi service starts");
    let counters = pipeline.counters();
    let input = pipeline.input().expect("a fed pipeline's input");
    (pipeline, counters, input)
}

/// The dashboard of `config` on the broker at `port`, connected: its link's updates and its
/// model.
async fn connected_dashboard(
    config: &Config,
    port: u16,
) -> (
    impl iced::futures::Stream<Item = Event> + Unpin + use<>,
    Dashboard,
) {
    let mut settings = Settings::from_config(config);
    settings.port = port;
    let mut updates = Box::pin(link::stream(settings));
    let (_, identity) = started(&mut updates).await;
    let mut model = Dashboard::new(config);
    model.apply(identity, Instant::now());
    until_connected(&mut updates, &mut model).await;
    (updates, model)
}

/// The dashboard's default: the compact stream. The Pi service replays the bundled session;
/// the dashboard's link, subscribed to `aer/car1/stream` only, gets every telemetry packet in
/// order with the values the generated decoder reads from the log, and every CAN message the
/// Pi decoded, and its model counts nothing lost or undecodable.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_compact_stream_carries_the_whole_session_to_the_dashboard() {
    let expected = session::load(BUNDLED_SESSION, "car1");
    let dir = tempfile::tempdir().expect("temp dir");
    let port = free_port();
    let (pipeline, counters, input) = fed_pi(dir.path(), port).await;
    let config = Config::default();
    assert_eq!(config.link.stream, StreamFormat::Compact, "the default");
    let (mut updates, mut model) = connected_dashboard(&config, port).await;

    // The session through the service while the dashboard reads, as at the track.
    let (stop, running, replaying) = run_and_replay(pipeline, &input, &counters);
    let mut received = Vec::new();
    let mut can_messages = 0u64;
    let decoded = |counters: &Counters| counters.messages.load(Ordering::Relaxed);
    while received.len() < expected.samples.len()
        || !replaying.is_finished()
        || can_messages < decoded(&counters)
    {
        let (at, update) = next(&mut updates).await;
        match &update {
            Update::Telemetry(sample) => received.push((**sample).clone()),
            Update::Can(_) => can_messages += 1,
            Update::Undecodable { topic, error } => panic!("{topic}: {error}"),
            _ => {}
        }
        model.apply(update, at);
    }
    replaying.await.expect("the replay");
    drop(input);
    running
        .await
        .expect("the pipeline's task")
        .expect("the pipeline stops cleanly");
    drop(stop);
    let pi = counters.snapshot();
    assert_eq!(pi.publish_dropped, 0);
    assert_eq!(pi.pit_dropped, 0);
    assert!(pi.pit_batches > 0);
    assert_eq!(received, expected.samples);
    assert_eq!(can_messages, pi.messages);
    let health = model.health();
    assert_eq!(health.packets, 4_500);
    assert_eq!(health.lost, 0);
    assert_eq!(health.undecodable, 0);
}

/// A radio between the dashboard and the Pi's broker that can drop out: a TCP proxy that,
/// while cut, closes every connection through it and every new one.
struct Radio {
    port: u16,
    cut: tokio::sync::watch::Sender<bool>,
}

async fn radio_to(upstream: u16) -> Radio {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("the radio's port");
    let port = listener.local_addr().expect("an address").port();
    let (cut, watch) = tokio::sync::watch::channel(false);
    tokio::spawn(async move {
        while let Ok((mut pit, _)) = listener.accept().await {
            if *watch.borrow() {
                continue;
            }
            let mut dropped = watch.clone();
            tokio::spawn(async move {
                let Ok(mut pi) = tokio::net::TcpStream::connect(("127.0.0.1", upstream)).await
                else {
                    return;
                };
                tokio::select! {
                    _ = tokio::io::copy_bidirectional(&mut pit, &mut pi) => {}
                    _ = dropped.wait_for(|cut| *cut) => {}
                }
            });
        }
    });
    Radio { port, cut }
}

/// Waits until the Pi has taken in `frames` frames (a fed replay's lines are sent before
/// they are ingested).
async fn ingested(counters: &Counters, frames: u64) {
    let deadline = Instant::now() + Duration::from_secs(30);
    while counters.frames.load(Ordering::Relaxed) < frames {
        assert!(
            Instant::now() < deadline,
            "the Pi did not take in {frames} frames"
        );
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// A dropout in the middle of the session: the dashboard's link loses the Pi for the middle
/// third of the bundled session, sees the numbering gap when it is back, asks the Pi for the
/// batches it missed and merges them, so its record of the session holds every telemetry
/// packet, in order, equal to the log, and its plots, faults and laps are rebuilt from it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn after_a_dropout_the_pit_fetches_what_it_missed() {
    let expected = session::load(BUNDLED_SESSION, "car1");
    let dir = tempfile::tempdir().expect("temp dir");
    let port = free_port();
    let (pipeline, counters, input) = fed_pi(dir.path(), port).await;
    let radio = radio_to(port).await;
    let (mut updates, mut model) = connected_dashboard(&Config::default(), radio.port).await;

    let (stop, running) = run_until_stopped(pipeline);
    let lines: Vec<&str> = BUNDLED_SESSION.lines().collect();
    // Each part ends where a telemetry packet's first frame begins: each feed is a replay of
    // its own, and a packet cut between two would be an ISO-TP error at the Pi already.
    let packet_starts_at = |from: usize| {
        (from..lines.len())
            .find(|&at| lines[at].contains(" 666#1"))
            .expect("a packet after it")
    };
    let third = packet_starts_at(lines.len() / 3);
    let two_thirds = packet_starts_at(2 * lines.len() / 3);
    let part = |range: std::ops::Range<usize>| {
        let mut text = lines[range].join("\n");
        text.push('\n');
        text
    };

    // The first third arrives live.
    feed(&part(0..third), &input, &counters).await;
    ingested(&counters, third as u64).await;
    while model.health().packets < counters.packets.load(Ordering::Relaxed) {
        let (at, update) = next(&mut updates).await;
        model.apply(update, at);
    }

    // The middle third while the radio is out.
    radio.cut.send_replace(true);
    feed(&part(third..two_thirds), &input, &counters).await;
    ingested(&counters, two_thirds as u64).await;
    radio.cut.send_replace(false);
    until_connected(&mut updates, &mut model).await;

    // The rest live again; the gap is fetched meanwhile (seen in the numbering of the next
    // live batch, or in the Pi's metrics, whichever comes first).
    feed(&part(two_thirds..lines.len()), &input, &counters).await;
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut caught_on_screen = Vec::new();
    loop {
        if Instant::now() >= deadline {
            let held: std::collections::BTreeSet<u16> = model
                .session_record()
                .into_iter()
                .flat_map(|record| record.rows().map(|row| row.sequence))
                .collect();
            let missing: Vec<(f64, u16)> = expected
                .samples
                .iter()
                .map(|s| (s.ts, s.value.header.sequence))
                .filter(|(_, sequence)| !held.contains(sequence))
                .take(10)
                .collect();
            panic!(
                "the session never became whole: {} packets, missing {missing:?}, {:?}; the \
                 Pi decoded {} packets",
                held.len(),
                model.health().backfill,
                counters.packets.load(Ordering::Relaxed)
            );
        }
        let (at, update) = next(&mut updates).await;
        if let Update::Undecodable { topic, error } = &update {
            panic!("{topic}: {error}");
        }
        model.apply(update, at);
        model.settle(at + Duration::from_secs(2));
        // The pit view while history flows, as the pit crew sees it (once some has merged).
        if caught_on_screen.is_empty()
            && model
                .health()
                .backfill
                .is_some_and(|b| b.catching_up && b.recovered > 0)
        {
            caught_on_screen = pit_screenshots(&model, at, "catching-up");
        }
        let whole = model
            .session_record()
            .is_some_and(|record| record.len() >= expected.samples.len());
        let settled = model.health().backfill.is_some_and(|b| !b.catching_up);
        if whole && settled {
            break;
        }
    }
    drop(input);
    drop(stop);
    running
        .await
        .expect("the pipeline's task")
        .expect("the pipeline stops cleanly");

    assert!(!caught_on_screen.is_empty(), "the catch-up was never drawn");
    pit_screenshots(&model, Instant::now(), "whole");
    let health = model.health();
    let progress = health.backfill.expect("the link reports the history");
    assert!(
        health.stream_gaps > 0,
        "the dropout left a gap: {progress:?}, {} merged",
        health.backfilled
    );
    assert!(progress.recovered > 0, "{progress:?}");
    assert_eq!(progress.not_held, 0);
    assert!((progress.complete - 1.0).abs() < 1e-9, "{progress:?}");
    assert!(health.backfilled > 0);
    let record: Vec<(f64, u16)> = model
        .session_record()
        .expect("the compact stream keeps a record")
        .rows()
        .map(|row| (row.ts, row.sequence))
        .collect();
    let wanted: Vec<(f64, u16)> = expected
        .samples
        .iter()
        .map(|sample| (sample.ts, sample.value.header.sequence))
        .collect();
    assert_eq!(record, wanted, "every packet once, in order");
    let telemetry_equal = model
        .session_record()
        .into_iter()
        .flat_map(|record| record.rows())
        .zip(&expected.samples)
        .all(|(row, sample)| row.telemetry == sample.value.telemetry);
    assert!(telemetry_equal, "the values are the log's");
    let counters = counters.snapshot();
    assert!(counters.history_batches > 0);
    assert_eq!(counters.history_refused, 0);
}

/// A pit laptop on a broker listener with credentials (as the Pi's network listener must have):
/// without them or with a wrong password the link reports why it is down, with the right
/// ones it connects.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_listener_with_credentials_admits_only_the_right_ones() {
    let port = free_port();
    let text = broker::DEFAULT_CONFIG
        .replace("127.0.0.1:1883", &format!("127.0.0.1:{port}"))
        .replacen("    dynamic_filters = true", PIT_AUTH, 1);
    let _broker = start_broker(&text).await;

    let settings = |credentials: Option<(&str, &str)>| Settings {
        host: "127.0.0.1".into(),
        port,
        credentials: credentials.map(|(u, p)| (u.into(), p.into())),
        tls_ca: None,
        prefix: "aer/car1".into(),
        can: Vec::new(),
        format: StreamFormat::Json,
        join_history_s: 0,
    };
    for refused in [
        None,
        Some(("pit", "guess")),
        Some(("driver", "Xq7-fast-laps")),
    ] {
        let mut updates = Box::pin(link::stream(settings(refused)));
        started(&mut updates).await;
        let (_, update) = next(&mut updates).await;
        match update {
            Update::Disconnected(reason) => {
                assert!(
                    reason.contains("username/password"),
                    "{refused:?}: {reason}"
                )
            }
            other => panic!("{refused:?}: expected a refusal, got {other:?}"),
        }
    }
    let mut updates = Box::pin(link::stream(settings(Some(("pit", "Xq7-fast-laps")))));
    started(&mut updates).await;
    let (_, update) = next(&mut updates).await;
    assert_eq!(update, Update::Connected);
}

/// Certificates as docs/dashboard.md has the team make them: a CA, and the Pi's certificate
/// (its name and address) signed by it. Returns the CA's PEM, the Pi's certificate and key.
fn team_certificates(names: &[&str]) -> (String, String, String) {
    use rcgen::{BasicConstraints, CertificateParams, IsCa, Issuer, KeyPair, KeyUsagePurpose};
    let mut ca = CertificateParams::new(Vec::new()).expect("CA params");
    ca.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    ca.key_usages = vec![
        KeyUsagePurpose::KeyCertSign,
        KeyUsagePurpose::DigitalSignature,
    ];
    let ca_key = KeyPair::generate().expect("CA key");
    let ca_cert = ca.self_signed(&ca_key).expect("CA");
    let issuer = Issuer::new(ca, ca_key);
    let names: Vec<String> = names.iter().map(|n| (*n).to_owned()).collect();
    let pi = CertificateParams::new(names).expect("Pi params");
    let pi_key = KeyPair::generate().expect("Pi key");
    let pi_cert = pi.signed_by(&pi_key, &issuer).expect("Pi certificate");
    (ca_cert.pem(), pi_cert.pem(), pi_key.serialize_pem())
}

/// The pit laptop on the service's TLS listener with credentials, as at the track: with the
/// team's CA and the right password it connects; a wrong
/// password, a certificate of another CA, and a plaintext attempt each get their own message.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_pit_connects_over_tls_and_each_mistake_is_named() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (ca, pi_cert, pi_key) = team_certificates(&["localhost", "127.0.0.1"]);
    let (other_ca, _, _) = team_certificates(&["localhost"]);
    let write = |name: &str, text: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, text).expect("write");
        path
    };
    let (ca, other_ca) = (write("team-ca.pem", &ca), write("other-ca.pem", &other_ca));
    let (cert, key) = (write("pi.cert.pem", &pi_cert), write("pi.key.pem", &pi_key));
    let port = free_port();
    let text = broker::DEFAULT_CONFIG
        .replace("127.0.0.1:1883", &format!("127.0.0.1:{port}"))
        .replacen(
            "    [v4.1.connections]",
            &format!(
                "    [v4.1.tls]\n    certpath = \"{}\"\n    keypath = \"{}\"\n    [v4.1.connections]",
                cert.display(),
                key.display()
            ),
            1,
        )
        .replacen("    dynamic_filters = true", PIT_AUTH, 1);
    let _broker = start_broker(&text).await;

    let settings = |password: &str, tls_ca: Option<&Path>| Settings {
        host: "127.0.0.1".into(),
        port,
        credentials: Some(("pit".into(), password.into())),
        tls_ca: tls_ca.map(Path::to_path_buf),
        prefix: "aer/car1".into(),
        can: Vec::new(),
        format: StreamFormat::Compact,
        join_history_s: 0,
    };
    let first_update = async |settings: Settings| {
        let mut updates = Box::pin(link::stream(settings));
        started(&mut updates).await;
        next(&mut updates).await.1
    };
    for (what, settings, expected) in [
        (
            "a wrong password",
            settings("guess", Some(&ca)),
            "username/password",
        ),
        (
            "a certificate of another CA",
            settings("Xq7-fast-laps", Some(&other_ca)),
            "not one AER_MQTT_TLS_CA trusts",
        ),
        ("no TLS", settings("Xq7-fast-laps", None), "without TLS"),
    ] {
        match first_update(settings).await {
            Update::Disconnected(reason) => {
                assert!(reason.contains(expected), "{what}: {reason}")
            }
            other => panic!("{what}: expected a refusal, got {other:?}"),
        }
    }
    // The Pi's CA-signed certificate is no anchor of its own: trusting it alone fails.
    match first_update(settings("Xq7-fast-laps", Some(&cert))).await {
        Update::Disconnected(reason) => assert!(reason.contains("not one"), "{reason}"),
        other => panic!("a leaf as anchor: expected a refusal, got {other:?}"),
    }
    let update = first_update(settings("Xq7-fast-laps", Some(&ca))).await;
    assert_eq!(update, Update::Connected);
}
