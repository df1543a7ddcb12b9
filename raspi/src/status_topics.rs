//! The service's own topics, every second: the retained status (which schema it decodes,
//! which the firmware sends, when data last came) and the metrics (every counter, packet
//! rate, store lag), with the clients the gate serves and how far behind each is; in the demo
//! also a console line.

use crate::broker::gate::Clients;
use crate::health::Health;
use crate::sink::mqtt::Publisher;
use crate::status_events::StatusWatch;
use crate::store::NoteSender;
use crate::xcp_gateway;
use aer_host::reports::counters::Counters;
use aer_host::reports::status::{METRICS, STATUS, clients_behind, metrics, status};
use std::sync::Arc;
use std::time::Duration;
use tokio_util::sync::CancellationToken;

/// What the service serves besides ingest, whose state the status reports.
#[derive(Default)]
pub struct Served {
    /// The gate's MQTT clients (embedded broker only).
    pub clients: Option<Arc<Clients>>,
    /// The pit's XCP gateway, when it runs.
    pub xcp_gateway: Option<Arc<xcp_gateway::State>>,
    /// Where the status's changes go as session events (the store's writer).
    pub events: Option<NoteSender>,
}

/// Publishes status and metrics every second until `cancel`; `console` also prints a line.
pub async fn run(
    publisher: Publisher,
    car_id: String,
    counters: Arc<Counters>,
    health: Arc<Health>,
    served: Served,
    cancel: CancellationToken,
    console: bool,
) {
    let mut previous = counters.snapshot();
    let mut watch = StatusWatch::new(&previous);
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            () = cancel.cancelled() => return,
        }
        let now = counters.snapshot();
        let metrics = metrics(now, previous);
        let mut status = status(&car_id, &counters, health.problems());
        if let Some(clients) = &served.clients {
            let served = clients.snapshot();
            status.problems.mqtt_clients = clients_behind(&served);
            status.mqtt_clients = served.into_iter().map(|(client, _)| client).collect();
        }
        status.xcp_gateway = served.xcp_gateway.as_ref().map(|state| state.snapshot());
        if let Some(events) = &served.events {
            let at_us = i64::try_from(aer_host::clock::now_us()).unwrap_or(i64::MAX);
            let loop_at_us = counters
                .last_replay_pass_us
                .load(std::sync::atomic::Ordering::Relaxed);
            let loop_at_us = i64::try_from(loop_at_us).unwrap_or(0);
            for event in watch.update(&status.problems, &now, at_us, loop_at_us) {
                events.send(event);
            }
        }
        // The next status measures the next second's traffic.
        if let Ok(mut traffic) = counters.traffic.lock() {
            traffic.restart();
        }
        publisher.publish_on(&STATUS, &status, true);
        publisher.publish_on(&METRICS, &metrics, false);
        if console {
            println!(
                "packets {:>7} ({:>4}/s)  rejected {} (another schema {})  frames {:>8}  raw {:>8}  stored {:>8}  published {:>8}  dropped mqtt {} store {} raw {}  errors isotp {} decode {} unknown {} bad-lines {}",
                now.packets,
                metrics.packets_per_s,
                now.fingerprint_mismatches + now.packet_errors,
                now.fingerprint_mismatches,
                now.frames,
                now.raw_frames,
                now.stored,
                now.published,
                now.publish_dropped,
                now.store_dropped,
                now.raw_dropped,
                now.isotp_errors,
                now.decode_errors,
                now.unknown_ids,
                now.bad_lines
            );
        }
        previous = now;
    }
}
