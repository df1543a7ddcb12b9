//! The clients off the Pi: TLS for MQTT with the team's certificates, the pit's history
//! requests and the Pi's answers, the dashboards' lap marks, and the XCP master that talks to the CCM through the Pi's
//! gateway.

pub mod marks;
pub mod pit_history;
pub mod tls;
pub mod xcp_master;
