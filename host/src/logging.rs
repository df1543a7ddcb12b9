//! Log output for the host binaries: readable in a terminal and in the journal alike.
//!
//! Under systemd the output is a pipe to journald, which keeps its own timestamps and levels;
//! ANSI colour codes there only make `journalctl` show escape sequences, so colour is used
//! only when the output is a terminal (and `NO_COLOR` is unset). Libraries that report
//! routine events as errors (rumqttd logs every client that leaves as one) are quietened by
//! message, so their real errors still show.

use std::fmt::Debug;
use std::io::IsTerminal;
use tracing::field::{Field, Visit};
use tracing::{Event, Metadata};
use tracing_subscriber::EnvFilter;
use tracing_subscriber::layer::{Context, Filter, Layer, SubscriberExt};
use tracing_subscriber::util::SubscriberInitExt;

/// Events of `target` (a module path prefix) whose message starts with one of `messages` are
/// routine, whatever level the library gives them, and are not logged.
#[derive(Debug, Clone, Copy)]
pub struct Routine {
    pub target: &'static str,
    pub messages: &'static [&'static str],
}

/// Installs the global subscriber: `RUST_LOG`, or `default` when it is unset, minus the
/// `routine` events.
pub fn init(default: &str, routine: &'static [Routine]) {
    let filter = std::env::var("RUST_LOG")
        .ok()
        .filter(|s| !s.trim().is_empty())
        .and_then(|requested| {
            EnvFilter::try_new(&requested)
                .inspect_err(|error| eprintln!("RUST_LOG ignored ({error}); using {default}"))
                .ok()
        })
        .unwrap_or_else(|| EnvFilter::new(default));
    let colour = std::io::stdout().is_terminal() && std::env::var_os("NO_COLOR").is_none();
    let output = tracing_subscriber::fmt::layer()
        .with_ansi(colour)
        .with_filter(RoutineFilter(routine));
    // A second initialisation (tests that start several services in one process) keeps the
    // first subscriber; that is the one wanted.
    let _ = tracing_subscriber::registry()
        .with(filter)
        .with(output)
        .try_init();
}

struct RoutineFilter(&'static [Routine]);

impl<S> Filter<S> for RoutineFilter {
    fn enabled(&self, _: &Metadata<'_>, _: &Context<'_, S>) -> bool {
        true
    }

    fn event_enabled(&self, event: &Event<'_>, _: &Context<'_, S>) -> bool {
        !is_routine(self.0, event)
    }
}

fn is_routine(rules: &[Routine], event: &Event<'_>) -> bool {
    let target = event.metadata().target();
    let Some(rule) = rules.iter().find(|r| target.starts_with(r.target)) else {
        return false;
    };
    let mut message = Message::default();
    event.record(&mut message);
    rule.messages.iter().any(|m| message.0.starts_with(m))
}

#[derive(Default)]
struct Message(String);

impl Visit for Message {
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            value.clone_into(&mut self.0);
        }
    }

    fn record_debug(&mut self, field: &Field, value: &dyn Debug) {
        if field.name() == "message" {
            self.0 = format!("{value:?}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{Routine, RoutineFilter};
    use std::sync::{Arc, Mutex};
    use tracing_subscriber::layer::{Layer, SubscriberExt};

    const RULES: &[Routine] = &[Routine {
        target: "noisy::router",
        messages: &["client gone", "no-connection"],
    }];

    /// Collects the messages that pass the filter.
    #[derive(Clone, Default)]
    struct Seen(Arc<Mutex<Vec<String>>>);

    impl<S: tracing::Subscriber> Layer<S> for Seen {
        fn on_event(
            &self,
            event: &tracing::Event<'_>,
            _: tracing_subscriber::layer::Context<'_, S>,
        ) {
            let mut message = super::Message::default();
            event.record(&mut message);
            if let Ok(mut seen) = self.0.lock() {
                seen.push(message.0);
            }
        }
    }

    #[test]
    fn routine_messages_of_the_named_target_are_dropped_and_everything_else_kept() {
        let seen = Seen::default();
        let subscriber =
            tracing_subscriber::registry().with(seen.clone().with_filter(RoutineFilter(RULES)));
        tracing::subscriber::with_default(subscriber, || {
            tracing::error!(target: "noisy::router", "no-connection id {} is already gone", 3);
            tracing::error!(target: "noisy::router::link", "client gone");
            tracing::error!(target: "noisy::router", "no space for new connection");
            tracing::error!(target: "other", "client gone");
        });
        let seen = seen.0.lock().map(|s| s.clone()).unwrap_or_default();
        assert_eq!(seen, ["no space for new connection", "client gone"]);
    }
}
