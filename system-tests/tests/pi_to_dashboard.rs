//! End to end with the real components: the Pi service replays the bundled session through its
//! pipeline and publishes on the embedded rumqttd broker; the dashboard's own MQTT link reads
//! the typed topics; its model and views must show exactly what the car sent, and of the CAN
//! topics only those of the messages the pit view shows.

use aer::can::{AnyMessage, DtiTemperatures, PccStatus};
use aer_dashboard::config::{Config, View};
use aer_dashboard::link::{self, CanTopics, Settings};
use aer_dashboard::model::health::SchemaMatch;
use aer_dashboard::model::{Dashboard, Update};
use aer_dashboard::screenshot::PIT_SIZE;
use aer_dashboard::session;
use aer_dashboard::session::BUNDLED_SESSION;
use aer_dashboard::ui::App;
use aer_host::counters::Counters;
use aer_host::status::{Problems, STATUS, status};
use aer_raspi::broker;
use aer_raspi::config::BrokerOptions;
use aer_raspi::ingest::Stage;
use aer_raspi::sink::Sink;
use aer_raspi::sink::mqtt as publish;
use aer_raspi::source::Replies;
use iced::futures::StreamExt;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio_util::sync::CancellationToken;

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

/// Waits for the next update; a stuck link fails the test instead of hanging it.
async fn next(
    stream: &mut (impl iced::futures::Stream<Item = (Instant, Update)> + Unpin),
) -> (Instant, Update) {
    tokio::time::timeout(Duration::from_secs(30), stream.next())
        .await
        .expect("an update within 30 s")
        .expect("the link never ends")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_replayed_session_reaches_the_dashboard_intact() {
    let expected = session::load(BUNDLED_SESSION, "car1");
    assert_eq!(expected.samples.len(), 4_500);

    // The Pi's broker, with segments that hold a replay run flat out.
    let port = free_port();
    let text = broker::DEFAULT_CONFIG
        .replace("127.0.0.1:1883", &format!("127.0.0.1:{port}"))
        .replace("max_segment_size = 262144", "max_segment_size = 67108864");
    let mut broker_config = broker::parse(&text).expect("broker config");
    // The dashboard is read only after the replay: not a client that stopped reading.
    broker_config.stall_limit = Duration::from_secs(120);
    let counters = Arc::new(Counters::default());
    let broker = broker::start(broker_config, counters.clone(), CancellationToken::new())
        .await
        .expect("broker");

    // The dashboard's link, showing one CAN message: connected means subscribed.
    let shown = aer::mqtt::can::DTI_TEMPERATURES.suffix();
    let settings = Settings {
        host: "127.0.0.1".into(),
        port,
        credentials: None,
        prefix: "aer/car1".into(),
        can: CanTopics::new([shown]),
    };
    let mut updates = Box::pin(link::stream(settings.clone()));
    let mut config = Config::default();
    config.display.can_messages = vec![DtiTemperatures::META.name.into()];
    let mut model = Dashboard::new(&config);
    loop {
        let (at, update) = next(&mut updates).await;
        let connected = update == Update::Connected;
        model.apply(update, at);
        if connected {
            break;
        }
    }

    // The Pi service: replay -> ingest -> typed topics (in process, as it publishes into its
    // embedded broker), then its retained status.
    let queue = BrokerOptions::default().queue;
    let (publisher, driver) = publish::embedded(
        broker.link,
        broker.spares,
        queue,
        "aer/car1".into(),
        counters.clone(),
        Arc::default(),
    );
    let (up_tx, mut up) = tokio::sync::watch::channel(false);
    tokio::spawn(publish::drive(driver, up_tx));
    tokio::time::timeout(Duration::from_secs(10), up.wait_for(|u| *u))
        .await
        .expect("the Pi connects")
        .expect("watch");
    let sinks: Vec<Box<dyn Sink>> = vec![Box::new(publisher.clone())];
    let stage = Stage::new(counters.clone(), sinks, Replies::default());
    let (stage, _) = stage
        .replay_all(BUNDLED_SESSION.as_bytes(), &counters)
        .await;
    drop(stage);
    publisher.publish_on(
        &STATUS,
        &status("car1", &counters, Problems::default()),
        true,
    );
    assert_eq!(counters.snapshot().publish_dropped, 0);

    // The session's DTI_Temperatures frames: the only CAN frames the dashboard may get.
    let dti_temperatures = BUNDLED_SESSION
        .lines()
        .filter_map(|line| aer_host::candump::parse_line(line, |_| 0).ok())
        .filter(|frame| aer::runtime::raw_id(frame.id) == (DtiTemperatures::META.id, true))
        .count();
    assert!(dti_temperatures > 100, "{dti_temperatures}");

    let mut received = Vec::new();
    let mut can_frames = 0;
    while received.len() < expected.samples.len()
        || can_frames < dti_temperatures
        || model.health().status.is_none()
    {
        let (at, update) = next(&mut updates).await;
        match &update {
            Update::Telemetry(sample) => received.push((**sample).clone()),
            Update::Can(sample) => {
                assert!(
                    matches!(sample.value, AnyMessage::DtiTemperatures(_)),
                    "a message the pit view does not show: {:?}",
                    sample.value.meta().name
                );
                can_frames += 1;
            }
            _ => {}
        }
        model.apply(update, at);
    }
    assert_eq!(can_frames, dti_temperatures);

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
    settings.can.set(
        &settings.prefix,
        [shown, aer::mqtt::can::PCC_STATUS.suffix()],
    );
    loop {
        // The broker's acknowledgement of the new subscription.
        if next(&mut updates).await.1 == Update::Connected {
            break;
        }
    }
    let pcc = AnyMessage::decode(PccStatus::META.id, false, &[0; 8]).expect("frame");
    publisher.publish(
        &aer_host::ingest::Record::Can {
            ts_us: 1_795_348_800_000_000,
            bus: 0,
            message: pcc,
            check: Default::default(),
        },
        &["can0".into()],
    );
    publisher.flush();
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
}

/// A pit laptop on a broker listener with credentials (as the Pi's network listener must have):
/// without them or with a wrong password the link reports why it is down, with the right
/// ones it connects.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_listener_with_credentials_admits_only_the_right_ones() {
    let port = free_port();
    let text = broker::DEFAULT_CONFIG
        .replace("127.0.0.1:1883", &format!("127.0.0.1:{port}"))
        .replacen(
            "    dynamic_filters = true",
            "    dynamic_filters = true\n    auth = { pit = \"Xq7-fast-laps\" }",
            1,
        );
    let broker_config = broker::parse(&text).expect("broker config");
    let _broker = broker::start(
        broker_config,
        Arc::new(Counters::default()),
        CancellationToken::new(),
    )
    .await
    .expect("broker");

    let settings = |credentials: Option<(&str, &str)>| Settings {
        host: "127.0.0.1".into(),
        port,
        credentials: credentials.map(|(u, p)| (u.into(), p.into())),
        prefix: "aer/car1".into(),
        can: CanTopics::default(),
    };
    for refused in [
        None,
        Some(("pit", "guess")),
        Some(("driver", "Xq7-fast-laps")),
    ] {
        let mut updates = Box::pin(link::stream(settings(refused)));
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
    let (_, update) = next(&mut updates).await;
    assert_eq!(update, Update::Connected);
}
