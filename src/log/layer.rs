//! A tracing layer that copies events to `/log` (foxglove.Log).

use super::{LogEvent, LogHandle, writer::ON_WRITER_THREAD};
use foxglove::messages::log::Level;
use std::fmt::Write as _;
use tracing::field::{Field, Visit};
use tracing::{Event, Subscriber};
use tracing_subscriber::layer::{Context, Layer};

/// Sends every event it sees to the flight log's queue (never blocks; the
/// subscriber's filter decides which events it sees).
pub struct LogLayer {
    handle: LogHandle,
}

impl LogLayer {
    pub(crate) fn new(handle: LogHandle) -> Self {
        Self { handle }
    }
}

/// Collects `message` and the other fields as `key=value`.
#[derive(Default)]
struct Text {
    message: String,
    fields: String,
}

impl Visit for Text {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            let _ = write!(self.message, "{value:?}");
        } else {
            let _ = write!(self.fields, " {}={value:?}", field.name());
        }
    }
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.message.push_str(value);
        } else {
            let _ = write!(self.fields, " {}={value}", field.name());
        }
    }
}

fn level(l: &tracing::Level) -> Level {
    match *l {
        tracing::Level::ERROR => Level::Error,
        tracing::Level::WARN => Level::Warning,
        tracing::Level::INFO => Level::Info,
        _ => Level::Debug,
    }
}

impl<S: Subscriber> Layer<S> for LogLayer {
    fn on_event(&self, event: &Event<'_>, _ctx: Context<'_, S>) {
        // The writer writes its own reports; looping them through the queue
        // could feed back on a failing disk.
        if ON_WRITER_THREAD.with(std::cell::Cell::get) {
            return;
        }
        let meta = event.metadata();
        let mut text = Text::default();
        event.record(&mut text);
        text.message.push_str(&text.fields);
        self.handle.log_event(LogEvent {
            time_ns: self.handle.now_ns(),
            level: level(meta.level()),
            message: text.message,
            name: meta.target().to_string(),
            file: meta.file().unwrap_or("").to_string(),
            line: meta.line().unwrap_or(0),
        });
    }
}
