//! Code using a signal the schema no longer has (the old hand-written layout's torque percentage)
//! does not compile.

fn main() {
    let mcu1 = aer::can::Mcu1::decode(&[0; 8]).expect("decodes");
    let _percent = mcu1.mcu_actual_torque_percent;
    let telemetry_field = aer::telemetry::Telemetry::motor_torque_percent_from_raw(0);
    let _ = telemetry_field;
}
