//! ISO-TP sender and receiver against each other, every length class up to 4095 bytes.

use crate::Digest;
use aer_car_model::rng::Rng;
use aer_isotp::{Config, Received, Receiver, Sender, StMin};
use core::fmt::Write;

const BIG: usize = aer_isotp::MAX_PAYLOAD;

/// Sends messages of many lengths and block sizes; digests what arrives.
pub fn transfers(out: &mut impl Write) -> core::fmt::Result {
    let mut rng = Rng::new(0x0001_507B);
    let mut digest = Digest::default();
    let mut delivered = 0u32;
    let mut frames = 0u32;
    let mut payload = [0u8; BIG];
    for (round, len) in [1usize, 7, 8, 62, 63, 300, 1_000, 4_095]
        .iter()
        .cycle()
        .take(24)
        .enumerate()
    {
        let block_size = [0u8, 1, 4, 8][round % 4];
        let config = Config {
            block_size,
            st_min: StMin::from_raw([0u8, 0xF3, 1, 0][round % 4]),
            ..Config::CAR
        };
        let message = payload.get_mut(..*len).unwrap_or_default();
        rng.fill(message);
        let mut sender: Sender<BIG> = Sender::new(config);
        let mut receiver: Receiver<BIG> = Receiver::new(config);
        if sender.start(message).is_err() {
            writeln!(out, "isotp round {round}: start refused")?;
            continue;
        }
        let mut now = 0u32;
        let mut done = false;
        for _ in 0..200_000 {
            now = now.wrapping_add(100);
            match sender.poll(now) {
                Ok(Some(frame)) => {
                    sender.sent(now);
                    frames += 1;
                    match receiver.on_frame(frame.as_slice(), now) {
                        Ok(Received::FlowControl(reply)) => {
                            if sender.on_flow_control(reply.as_slice(), now).is_err() {
                                break;
                            }
                        }
                        Ok(Received::Message(bytes)) => {
                            digest.bytes(bytes);
                            done = bytes == &*message;
                            break;
                        }
                        Ok(Received::Nothing) => {}
                        Err(error) => {
                            write!(digest, "{error:?}")?;
                            break;
                        }
                    }
                }
                Ok(None) if sender.is_idle() => break,
                Ok(None) => {}
                Err(error) => {
                    write!(digest, "{error:?}")?;
                    break;
                }
            }
        }
        delivered += u32::from(done);
    }
    writeln!(
        out,
        "isotp messages=24 delivered-intact={delivered} frames={frames} digest={:08x}",
        digest.value()
    )
}
