//! Publishing a CAN message on the telemetry topic does not compile: each topic is bound to its
//! payload type.

use aer::can::Mcu1;
use aer::mqtt::{Sample, TELEMETRY};

fn main() {
    let frame = Mcu1::decode(&[0; 8]).expect("decodes");
    let _payload = TELEMETRY.encode(&Sample { ts: 0.0, value: frame });
}
