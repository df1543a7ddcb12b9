//! Every codec for each benchmarked DBC file, generated at build time (see build.rs; nothing
//! generated here is committed), and the operations the benchmarks time and count, each in a
//! function of its own (`#[inline(never)]`) so that callgrind can count exactly its
//! instructions (`src/bin/instructions.rs`).
#![allow(clippy::all, dead_code, unused_imports, non_camel_case_types)]

include!(concat!(env!("OUT_DIR"), "/codecs.rs"));

use embedded_can::{ExtendedId, Id, StandardId};

/// A boxed encoder: the peer's constructors differ per message.
pub type Encoder = Box<dyn Fn(&mut [u8]) -> usize>;

/// A frame every codec accepts: in range, so each re-encodes it.
pub struct Frame {
    pub id: u32,
    pub extended: bool,
    pub data: Vec<u8>,
}

impl Frame {
    pub fn can_id(&self) -> Id {
        if self.extended {
            Id::Extended(ExtendedId::new(self.id).expect("valid id"))
        } else {
            Id::Standard(StandardId::new(self.id as u16).expect("valid id"))
        }
    }
}

/// Deterministic pseudo-random bytes (xorshift64*).
struct Rng(u64);

impl Rng {
    fn byte(&mut self) -> u8 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 56) as u8
    }
}

/// The frames and what each codec needs prepared before the clock starts.
pub struct Suite<M> {
    pub frames: Vec<Frame>,
    pub ids: Vec<Id>,
    /// Ours, decoded (what our encode takes).
    pub messages: Vec<M>,
    /// The peer's, constructed per frame.
    pub peer_encoders: Vec<Encoder>,
    /// cantools C's physical values per frame, in signal order.
    pub c_values: Vec<Vec<f64>>,
}

/// Adds up every physical value a message holds, so decoding is not optimised away and each
/// value is read as a user would.
pub struct Sum(pub f64);

macro_rules! suite {
    ($suite:ident, $codecs:ident) => {
        /// The operations on one DBC file's codecs.
        pub mod $suite {
            use crate::$codecs::ours::can::{AnyMessage, MESSAGES};
            use crate::$codecs::ours::runtime::{SignalMeta, SignalVisitor, Value};
            use crate::$codecs::{c, peer_harness};
            use crate::{Encoder, Frame, Rng, Suite, Sum};
            use core::hint::black_box;

            impl SignalVisitor for Sum {
                fn signal(
                    &mut self,
                    _: &'static SignalMeta,
                    value: Value,
                    _: Option<&'static str>,
                ) {
                    self.0 += value.to_f64();
                }
            }

            /// Four frames per message that every codec decodes and re-encodes.
            pub fn prepare() -> Suite<AnyMessage> {
                let mut rng = Rng(0x5EED_0000_0000_0001);
                let mut suite = Suite {
                    frames: Vec::new(),
                    ids: Vec::new(),
                    messages: Vec::new(),
                    peer_encoders: Vec::new(),
                    c_values: Vec::new(),
                };
                for meta in MESSAGES.iter() {
                    let mut found = 0;
                    for _ in 0..200 {
                        let data: Vec<u8> = (0..meta.len).map(|_| rng.byte()).collect();
                        let Ok(msg) = AnyMessage::decode(meta.id, meta.extended, &data) else {
                            continue;
                        };
                        let mut out = [0u8; 64];
                        let Ok(n) = msg.encode(&mut out) else {
                            continue;
                        };
                        let frame = Frame {
                            id: meta.id,
                            extended: meta.extended,
                            data: out[..n].to_vec(),
                        };
                        let Some(peer) = peer_harness::prepare(frame.can_id(), &frame.data) else {
                            continue;
                        };
                        if peer(&mut [0u8; 64]) == 0 {
                            continue;
                        }
                        let mut values = vec![0.0; 256];
                        let count = unsafe {
                            c::values(
                                frame.id,
                                frame.extended as i32,
                                frame.data.as_ptr(),
                                frame.data.len(),
                                values.as_mut_ptr(),
                                values.len(),
                            )
                        };
                        let Ok(count) = usize::try_from(count) else {
                            continue;
                        };
                        if unsafe {
                            c::encode(
                                frame.id,
                                frame.extended as i32,
                                values.as_ptr(),
                                out.as_mut_ptr(),
                                out.len(),
                            )
                        } < 0
                        {
                            continue;
                        }
                        values.truncate(count);
                        suite.ids.push(frame.can_id());
                        suite.messages.push(msg);
                        suite.peer_encoders.push(peer);
                        suite.c_values.push(values);
                        suite.frames.push(frame);
                        found += 1;
                        if found == 4 {
                            break;
                        }
                    }
                }
                suite
            }

            /// Ours: one dispatch on the id, every value read (`decode_visit`).
            #[inline(never)]
            pub fn ours_decode(s: &Suite<AnyMessage>) -> f64 {
                let mut sum = Sum(0.0);
                for f in &s.frames {
                    let _ = AnyMessage::decode_visit(
                        black_box(f.id),
                        f.extended,
                        black_box(&f.data),
                        &mut sum,
                    );
                }
                sum.0
            }

            /// dbc-codegen: parse, then every getter.
            #[inline(never)]
            pub fn peer_decode(s: &Suite<AnyMessage>) {
                for (f, id) in s.frames.iter().zip(&s.ids) {
                    peer_harness::decode(black_box(*id), black_box(&f.data));
                }
            }

            /// cantools C: unpack, then every signal's decode, added up.
            #[inline(never)]
            pub fn c_decode(s: &Suite<AnyMessage>) -> f64 {
                let mut sum = 0.0;
                for f in &s.frames {
                    let data = black_box(&f.data);
                    unsafe {
                        c::decode(
                            black_box(f.id),
                            f.extended as i32,
                            data.as_ptr(),
                            data.len(),
                            &mut sum,
                        )
                    };
                }
                sum
            }

            /// Ours: range checks, round to nearest, pack.
            #[inline(never)]
            pub fn ours_encode(s: &Suite<AnyMessage>, out: &mut [u8; 64]) -> usize {
                let mut n = 0;
                for msg in &s.messages {
                    n += black_box(msg).encode(black_box(&mut out[..])).unwrap_or(0);
                }
                n
            }

            /// dbc-codegen: `new` with range checks, through a boxed closure per message.
            #[inline(never)]
            pub fn peer_encode(s: &Suite<AnyMessage>, out: &mut [u8; 64]) -> usize {
                s.peer_encoders
                    .iter()
                    .map(|enc| enc(black_box(&mut out[..])))
                    .sum()
            }

            /// cantools C: every signal's encode (truncating, no range check), then pack.
            #[inline(never)]
            pub fn c_encode(s: &Suite<AnyMessage>, out: &mut [u8; 64]) -> usize {
                let mut n = 0;
                for (f, values) in s.frames.iter().zip(&s.c_values) {
                    let values = black_box(values);
                    let len = unsafe {
                        c::encode(
                            f.id,
                            f.extended as i32,
                            values.as_ptr(),
                            out.as_mut_ptr(),
                            out.len(),
                        )
                    };
                    n += usize::try_from(len).unwrap_or(0);
                }
                n
            }
        }
    };
}

suite!(aer_suite, aer);
suite!(vehicle_suite, vehicle);
