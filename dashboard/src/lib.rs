//! The driver and pit dashboard as a library: the binary (`aer-dashboard`), the headless UI
//! tests, the end-to-end test and the benchmark use the same code.
//!
//! Data flow: [`link`] (MQTT: the Pi's compact stream, read by [`pit_stream`], with what it
//! missed fetched by [`backfill`], or the generated typed JSON topics, on the Pi's broker) ->
//! [`model`] (the
//! latest packet, alarms, plots, laps, link health; no UI types) -> [`ui`] (iced: the driver
//! and pit views, and the pit's Tune page, whose XCP master is [`tune_worker`]). [`session`]
//! and [`screenshot`] render the views from a recorded session without a display;
//! [`link_check`] runs the link and the model without a window.

pub mod backfill;
pub mod config;
pub mod link;
pub mod link_check;
pub mod model;
pub mod pit_stream;
pub mod screenshot;
pub mod session;
pub mod tune_worker;
pub mod ui;
