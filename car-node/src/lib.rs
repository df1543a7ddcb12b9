//! The closed-loop car as a node a real XCP master talks to.
//!
//! The car model (`aer_car_model`) runs the CCM's library with its XCP slave
//! ([`aer_car_model::XcpCar`]); this crate puts that slave on a real transport ([`link`]):
//! XCP on TCP (the A2L's desk endpoint, 127.0.0.1:5555) or XCP on CAN on a SocketCAN
//! interface (a vcan in the virtual Pi, with the DBC's XCP_Cmd/XCP_Res ids). Two uses:
//! - [`serve`]: the car on the desk in real time, for CANape, INCA or pyxcp, over
//!   [`masters`] (any number of clients, one master at a time);
//! - [`scenarios`]: the calibration engineer's scenarios played by pyxcp, judged by
//!   [`checks`] against what the CCM computed.
//!
//! Data flow: link -> slave (in the car) -> link; the script's requests -> car; results ->
//! checks.

pub mod checks;
pub mod expected;
pub mod link;
pub mod masters;
pub mod scenarios;
pub mod serve;
