//! The intermediate representation: what the wire looks like, independent of DBC/YAML syntax and of
//! any output language. Every emitter reads only this.

/// A validated CAN database.
#[derive(Debug, Clone, PartialEq)]
pub struct Database {
    /// Human name of the database (the file stem), used in generated docs.
    pub name: String,
    pub nodes: Vec<Node>,
    pub enums: Vec<EnumType>,
    pub messages: Vec<Message>,
    /// The buses' bit rate (the `Baudrate` database attribute), if the schema gives it.
    pub bit_rate: Option<u32>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    pub name: String,
    pub comment: Option<String>,
}

/// A named set of raw values (from `VAL_TABLE_` or a signal's `VAL_`).
#[derive(Debug, Clone, PartialEq)]
pub struct EnumType {
    /// Rust type name.
    pub type_name: String,
    pub variants: Vec<Variant>,
    /// The integer type that holds every raw value of every signal using this enum.
    pub repr: IntType,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Variant {
    pub ident: String,
    pub value: i128,
    /// The label as written in the schema.
    pub label: String,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    pub name: String,
    pub type_name: String,
    /// Its snake-case name, unique in the database: SQL table, MQTT topic, metadata static.
    pub item_name: String,
    pub id: u32,
    pub extended: bool,
    /// Payload length in bytes (up to 64 for CAN FD).
    pub len: usize,
    pub fd: bool,
    pub cycle_time_ms: Option<u32>,
    /// How old its last frame may be before receivers count it lost: the `AerTimeoutMs`
    /// attribute, else [`DEFAULT_MISSED_FRAMES`] cycle times; `None` without a cycle time.
    pub timeout_ms: Option<u32>,
    /// The rolling counter it carries, if the schema declares one.
    pub counter: Option<Counter>,
    /// The checksum it carries, if the schema declares one.
    pub checksum: Option<Checksum>,
    /// The buses it is sent on (the `AerBus` message attribute, comma-separated); empty when
    /// the schema does not say (the file is one bus).
    pub buses: Vec<String>,
    pub transmitter: Option<String>,
    pub comment: Option<String>,
    /// In schema order; `mux` conditions only refer to earlier-decoded signals via `eval_order`.
    pub signals: Vec<Signal>,
    /// Indices into `signals` such that every multiplexor comes before the signals it selects.
    pub eval_order: Vec<usize>,
}

/// A periodic message without an `AerTimeoutMs` counts as lost after this many cycle times.
pub const DEFAULT_MISSED_FRAMES: u32 = 5;

/// A message's rolling counter: one of its signals, advanced by `step` on every frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Counter {
    /// Index into the message's signals.
    pub signal: usize,
    pub step: u8,
}

/// A message's checksum: one whole byte, over the payload's other bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Checksum {
    /// Index into the message's signals.
    pub signal: usize,
    /// The payload byte it occupies.
    pub byte: u8,
    pub algorithm: ChecksumAlgorithm,
}

/// The checksum algorithms the runtime computes, by their schema names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChecksumAlgorithm {
    /// `SumXorFF`: the bytes' sum, XOR 0xFF.
    SumXorFf,
    /// `Crc8SaeJ1850`: CRC-8, polynomial 0x1D, initial value and final XOR 0xFF.
    Crc8SaeJ1850,
}

impl ChecksumAlgorithm {
    /// Every algorithm with the name the schema uses for it.
    pub const NAMES: [(&'static str, Self); 2] = [
        ("SumXorFF", Self::SumXorFf),
        ("Crc8SaeJ1850", Self::Crc8SaeJ1850),
    ];

    /// The runtime's variant name.
    pub fn variant(self) -> &'static str {
        match self {
            Self::SumXorFf => "SumXorFf",
            Self::Crc8SaeJ1850 => "Crc8SaeJ1850",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ByteOrder {
    /// Intel: the start bit is the least significant bit.
    LittleEndian,
    /// Motorola: the start bit is the most significant bit, in Vector's sawtooth numbering.
    BigEndian,
}

/// How the raw bits are interpreted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    Unsigned,
    Signed,
    Float32,
    Float64,
}

/// Rust integer types a value can be held in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum IntType {
    U8,
    U16,
    U32,
    U64,
    U128,
    I8,
    I16,
    I32,
    I64,
    I128,
}

impl IntType {
    pub fn rust(self) -> &'static str {
        match self {
            IntType::U8 => "u8",
            IntType::U16 => "u16",
            IntType::U32 => "u32",
            IntType::U64 => "u64",
            IntType::U128 => "u128",
            IntType::I8 => "i8",
            IntType::I16 => "i16",
            IntType::I32 => "i32",
            IntType::I64 => "i64",
            IntType::I128 => "i128",
        }
    }

    pub fn range(self) -> (i128, i128) {
        match self {
            IntType::U8 => (0, u8::MAX.into()),
            IntType::U16 => (0, u16::MAX.into()),
            IntType::U32 => (0, u32::MAX.into()),
            IntType::U64 => (0, u64::MAX.into()),
            IntType::U128 => (0, i128::MAX),
            IntType::I8 => (i8::MIN.into(), i8::MAX.into()),
            IntType::I16 => (i16::MIN.into(), i16::MAX.into()),
            IntType::I32 => (i32::MIN.into(), i32::MAX.into()),
            IntType::I64 => (i64::MIN.into(), i64::MAX.into()),
            IntType::I128 => (i128::MIN, i128::MAX),
        }
    }

    /// The smallest type that holds every value in `lo..=hi`.
    pub fn smallest_for(lo: i128, hi: i128) -> IntType {
        const ORDER: [IntType; 10] = [
            IntType::U8,
            IntType::I8,
            IntType::U16,
            IntType::I16,
            IntType::U32,
            IntType::I32,
            IntType::U64,
            IntType::I64,
            IntType::U128,
            IntType::I128,
        ];
        ORDER
            .into_iter()
            .find(|t| {
                let (tlo, thi) = t.range();
                tlo <= lo && hi <= thi
            })
            .unwrap_or(IntType::I128)
    }
}

/// The Rust type of a signal's physical value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PhysType {
    /// A 1-bit unsigned flag with identity scaling.
    Bool,
    /// Integral factor and offset: the physical value is an exact integer.
    Int(IntType),
    F32,
    F64,
    /// Index into `Database::enums`; the field holds the raw value's meaning.
    Enum(usize),
}

/// When a multiplexed signal is present: its multiplexor's raw value lies in one of `ranges`.
#[derive(Debug, Clone, PartialEq)]
pub struct MuxCondition {
    /// Index of the multiplexor signal in the message.
    pub selector: usize,
    /// Inclusive raw-value ranges.
    pub ranges: Vec<(u64, u64)>,
}

impl MuxCondition {
    /// The ranges as text: a single value alone, a range as `lo{to}hi`, joined by
    /// `separator` (`1 | 4..=7` in a pattern, `1, 4..7` in the documentation).
    pub fn describe(ranges: &[(u64, u64)], to: &str, separator: &str) -> String {
        ranges
            .iter()
            .map(|&(lo, hi)| {
                if lo == hi {
                    lo.to_string()
                } else {
                    format!("{lo}{to}{hi}")
                }
            })
            .collect::<Vec<_>>()
            .join(separator)
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Signal {
    pub name: String,
    pub field: String,
    /// As written in the DBC: LSB for Intel, MSB (sawtooth numbering) for Motorola.
    pub start_bit: u32,
    pub len: u32,
    pub byte_order: ByteOrder,
    pub encoding: Encoding,
    pub factor: f64,
    pub offset: f64,
    /// `None` when the schema gives no range (`[0|0]`, Vector's convention).
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub unit: String,
    pub comment: Option<String>,
    pub receivers: Vec<String>,
    pub phys: PhysType,
    /// Named raw values of a scaled signal (`VAL_` on a signal whose factor or offset is not
    /// the identity): its value stays a number, as cantools decodes it, and these are only
    /// recognised. A signal with identity scaling gets an enum type instead.
    pub value_labels: Vec<(i128, String)>,
    pub mux: Option<MuxCondition>,
    pub is_multiplexor: bool,
}

impl Signal {
    /// Raw integer type holding the extracted bits (sign-extended for signed signals).
    pub fn raw_int(&self) -> IntType {
        let signed = self.encoding == Encoding::Signed;
        match (self.len, signed) {
            (0..=8, false) => IntType::U8,
            (9..=16, false) => IntType::U16,
            (17..=32, false) => IntType::U32,
            (_, false) => IntType::U64,
            (0..=8, true) => IntType::I8,
            (9..=16, true) => IntType::I16,
            (17..=32, true) => IntType::I32,
            (_, true) => IntType::I64,
        }
    }

    /// Smallest and largest raw integer the bits can hold.
    pub fn raw_range(&self) -> (i128, i128) {
        let len = self.len.min(64);
        match self.encoding {
            Encoding::Signed => (-(1i128 << (len - 1)), (1i128 << (len - 1)) - 1),
            _ => (0, (1i128 << len) - 1),
        }
    }

    pub fn is_float_raw(&self) -> bool {
        matches!(self.encoding, Encoding::Float32 | Encoding::Float64)
    }

    /// Bit positions the signal occupies, numbered `byte * 8 + bit_in_byte` (LSB = 0).
    pub fn bits(&self) -> Vec<u32> {
        match self.byte_order {
            ByteOrder::LittleEndian => (self.start_bit..self.start_bit + self.len).collect(),
            ByteOrder::BigEndian => {
                let msb = be_linear(self.start_bit);
                (msb..msb + self.len)
                    .map(|p| (p / 8) * 8 + (7 - p % 8))
                    .collect()
            }
        }
    }
}

/// Position of a Motorola start bit in big-endian linear numbering (bit 0 = MSB of byte 0).
pub fn be_linear(start_bit: u32) -> u32 {
    (start_bit / 8) * 8 + (7 - start_bit % 8)
}

/// The ISO-TP telemetry packet, laid out byte by byte.
#[derive(Debug, Clone, PartialEq)]
pub struct Telemetry {
    pub type_name: String,
    pub description: String,
    pub tx_id: u16,
    pub flow_control_id: u16,
    pub period_ms: u32,
    /// How old the newest packet may be before receivers count the data stale (ms).
    pub timeout_ms: u32,
    /// The bus it is sent on (one of the DBC's `AerBus` names), if the schema says.
    pub bus: Option<String>,
    /// The node that sends it (a DBC node), if the schema says.
    pub sender: Option<String>,
    /// Bytes the packet is planned to grow by; its bus must keep room for them.
    pub headroom_bytes: usize,
    /// Every field, in schema order; `layout` says where each one sits.
    pub fields: Vec<TelemetryField>,
    /// Total packet length in bytes, header included.
    pub len: usize,
}

/// Bytes of the fixed header: fingerprint u32, sequence u16, timestamp_us u32.
pub const TELEMETRY_HEADER_LEN: usize = 10;

/// Largest payload an ISO-TP (ISO 15765-2, classic CAN) message carries.
pub const ISOTP_MAX_LEN: usize = 4095;

/// How a telemetry field is stored on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WireType {
    U8,
    U16,
    U32,
    I8,
    I16,
    I32,
    F32,
    Flag,
}

impl WireType {
    pub fn bytes(self) -> usize {
        match self {
            WireType::U8 | WireType::I8 => 1,
            WireType::U16 | WireType::I16 => 2,
            WireType::U32 | WireType::I32 | WireType::F32 => 4,
            WireType::Flag => 0,
        }
    }

    pub fn bits(self) -> u32 {
        match self {
            WireType::Flag => 1,
            other => other.bytes() as u32 * 8,
        }
    }

    pub fn rust(self) -> &'static str {
        match self {
            WireType::U8 => "u8",
            WireType::U16 => "u16",
            WireType::U32 => "u32",
            WireType::I8 => "i8",
            WireType::I16 => "i16",
            WireType::I32 => "i32",
            WireType::F32 => "f32",
            WireType::Flag => "bool",
        }
    }

    /// Smallest and largest raw value.
    pub fn range(self) -> (i128, i128) {
        match self {
            WireType::U8 => IntType::U8.range(),
            WireType::U16 => IntType::U16.range(),
            WireType::U32 => IntType::U32.range(),
            WireType::I8 => IntType::I8.range(),
            WireType::I16 => IntType::I16.range(),
            WireType::I32 => IntType::I32.range(),
            WireType::Flag => (0, 1),
            WireType::F32 => (i128::MIN, i128::MAX),
        }
    }
}

/// Where a field sits in the packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Placement {
    /// Byte offset of a byte-aligned little-endian value.
    Bytes(usize),
    /// Byte offset and bit (0 = LSB) of a flag.
    Bit(usize, u8),
}

/// Dashboard hints for a field: a label and thresholds above (`warn`, `critical`) or below
/// (`warn_below`, `critical_below`) which the value needs attention.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Display {
    pub label: Option<String>,
    pub warn: Option<f64>,
    pub critical: Option<f64>,
    pub warn_below: Option<f64>,
    pub critical_below: Option<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct TelemetryField {
    pub name: String,
    pub group: String,
    pub description: String,
    pub unit: String,
    pub wire: WireType,
    pub scale: f64,
    pub offset: f64,
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub phys: PhysType,
    pub placement: Placement,
    pub display: Display,
    /// `MESSAGE.SIGNAL` this field mirrors, when it references the DBC.
    pub source: Option<String>,
}

/// The CCM's calibration: the tuned numbers, laid out in one little-endian page (the working
/// page a calibration tool reads and writes).
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// The schema's name for it (`ccm`).
    pub name: String,
    pub description: String,
    pub parameters: Vec<Parameter>,
    /// Bytes of the page.
    pub page_len: usize,
    /// The controllers' internal values a tuner samples, in their block's order.
    pub internals: Vec<Internal>,
    /// How a calibration tool reaches the slave.
    pub xcp: Xcp,
}

/// A controller's internal value (an `f32`) a tuner samples with XCP; the values lie one after
/// the other, 4 bytes each, little-endian, in declared order.
#[derive(Debug, Clone, PartialEq)]
pub struct Internal {
    /// The field name (snake_case).
    pub name: String,
    pub unit: String,
    /// The range it is expected in (for the calibration tool's display; not enforced).
    pub min: f64,
    pub max: f64,
    pub description: String,
}

/// Bytes of one internal value (an `f32`).
pub const INTERNAL_SIZE: usize = 4;

impl Calibration {
    /// Bytes of the internals' block: every value an `f32`, in declared order.
    pub fn internals_len(&self) -> usize {
        self.internals.len() * INTERNAL_SIZE
    }
}

/// The XCP slave's settings that the firmware and the calibration tool's description share.
#[derive(Debug, Clone, PartialEq)]
pub struct Xcp {
    /// The bus its messages are on (an `AerBus` name), if the schema says.
    pub bus: Option<String>,
    /// The DBC message the master sends commands in.
    pub command_message: String,
    /// The DBC message the slave answers (and sends DAQ packets) in.
    pub response_message: String,
    /// The command message's standard id.
    pub can_id_master: u32,
    /// The response message's standard id.
    pub can_id_slave: u32,
    /// The bus's bit rate (the DBC's `Baudrate`).
    pub bit_rate: u32,
    /// The response message's cycle time: the slave's frame budget, one frame per this many
    /// milliseconds on average.
    pub response_cycle_ms: u32,
    /// The TCP port of the host (test) endpoint.
    pub tcp_port: u16,
    /// DAQ lists the master may allocate.
    pub max_daq: u16,
    /// ODT entries the master may allocate over all DAQ lists.
    pub odt_entries: u16,
    /// Bytes one ODT entry may sample.
    pub max_odt_entry_size: u8,
    /// No command for this long ends a session (with DAQ running: takes back its unlock), ms.
    pub idle_timeout_ms: u32,
    /// GET_SEED is refused this long after a wrong key, doubling with each one in a row, ms.
    pub unlock_delay_ms: u32,
    /// The longest such delay, ms.
    pub unlock_delay_max_ms: u32,
    /// The event channels, numbered from 0 in this order.
    pub events: Vec<XcpEvent>,
}

/// An XCP event channel.
#[derive(Debug, Clone, PartialEq)]
pub struct XcpEvent {
    /// Its name (snake_case).
    pub name: String,
    /// How often it fires, in microseconds.
    pub period_us: u32,
    pub description: String,
}

impl XcpEvent {
    /// The period as an A2L event states it: a cycle of at most 255 units and the unit's
    /// code (3 = 1 us, 4 = 10 us, ..., 9 = 1 s), the finest unit that holds it exactly (10 ms
    /// is 100 x 100 us, as the slave's GET_DAQ_EVENT_INFO says it); `None` when none does.
    pub fn time_cycle(&self) -> Option<(u8, u8)> {
        time_cycle(self.period_us)
    }
}

/// See [`XcpEvent::time_cycle`].
pub fn time_cycle(period_us: u32) -> Option<(u8, u8)> {
    let units: [(u32, u8); 7] = [
        (1, 3),
        (10, 4),
        (100, 5),
        (1_000, 6),
        (10_000, 7),
        (100_000, 8),
        (1_000_000, 9),
    ];
    units.into_iter().find_map(|(unit_us, code)| {
        let cycle = u8::try_from(period_us / unit_us).ok()?;
        (period_us % unit_us == 0 && cycle > 0).then_some((cycle, code))
    })
}

/// One tuned number, or a list of them that changes as one.
#[derive(Debug, Clone, PartialEq)]
pub struct Parameter {
    /// The field name (snake_case).
    pub name: String,
    pub label: String,
    pub group: String,
    pub description: String,
    pub unit: String,
    pub element: ElementType,
    /// A single value rather than a list.
    pub scalar: bool,
    /// The default of every element (one for a scalar).
    pub defaults: Vec<f64>,
    /// The limits every element keeps.
    pub min: f64,
    pub max: f64,
    /// Each element must lie above the one before.
    pub increasing: bool,
    /// What each element of a list without an axis is.
    pub elements: Vec<String>,
    /// A curve's input.
    pub axis: Option<Axis>,
    /// The curve whose axis points this parameter is (they follow it in the page).
    pub axis_of: Option<String>,
    pub change: ChangeWhen,
    /// Where it starts in the page (aligned to its element).
    pub offset: usize,
}

impl Parameter {
    /// Bytes it takes in the page.
    pub fn len(&self) -> usize {
        self.defaults.len() * self.element.size()
    }

    /// Whether it has no elements (never, once validated).
    pub fn is_empty(&self) -> bool {
        self.defaults.is_empty()
    }
}

/// A curve's input: tunable points, strictly increasing, stored in the page as the parameter
/// `parameter` (right after the curve), and the internal value the firmware looks it up with.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    pub label: String,
    pub unit: String,
    /// The default points.
    pub points: Vec<f64>,
    /// The parameter holding the points (`<curve>_axis`).
    pub parameter: String,
    /// The internal the curve is looked up with (the A2L's input quantity).
    pub input: String,
    /// The limits the points keep.
    pub min: f64,
    pub max: f64,
}

/// The type of a parameter's elements.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ElementType {
    F32,
    U8,
    U16,
    U32,
    I16,
    I32,
}

impl ElementType {
    /// Its name in the schema and in Rust.
    pub fn rust(self) -> &'static str {
        match self {
            Self::F32 => "f32",
            Self::U8 => "u8",
            Self::U16 => "u16",
            Self::U32 => "u32",
            Self::I16 => "i16",
            Self::I32 => "i32",
        }
    }

    /// Bytes per element.
    pub fn size(self) -> usize {
        match self {
            Self::U8 => 1,
            Self::U16 | Self::I16 => 2,
            Self::F32 | Self::U32 | Self::I32 => 4,
        }
    }

    /// The values it holds: an integer type's range, or f32's finite range.
    pub fn range(self) -> (f64, f64) {
        match self {
            Self::F32 => (f64::from(f32::MIN), f64::from(f32::MAX)),
            Self::U8 => (0.0, f64::from(u8::MAX)),
            Self::U16 => (0.0, f64::from(u16::MAX)),
            Self::U32 => (0.0, f64::from(u32::MAX)),
            Self::I16 => (f64::from(i16::MIN), f64::from(i16::MAX)),
            Self::I32 => (f64::from(i32::MIN), f64::from(i32::MAX)),
        }
    }

    /// Whether it holds only whole numbers.
    pub fn is_integer(self) -> bool {
        self != Self::F32
    }
}

/// When a calibration tool may change a parameter: each condition includes the ones after it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum ChangeWhen {
    /// Any time, while driving too.
    Driving,
    /// Only with the car stopped.
    Standstill,
    /// Only stopped with the tractive system off.
    TractiveOff,
}

impl ChangeWhen {
    /// Its name in the schema.
    pub fn schema_name(self) -> &'static str {
        match self {
            Self::Driving => "driving",
            Self::Standstill => "standstill",
            Self::TractiveOff => "tractive_off",
        }
    }

    /// When it allows a change, in words.
    pub fn words(self) -> &'static str {
        match self {
            Self::Driving => "any time",
            Self::Standstill => "at standstill",
            Self::TractiveOff => "with the tractive system off",
        }
    }

    /// Its variant in the generated code.
    pub fn variant(self) -> &'static str {
        match self {
            Self::Driving => "Driving",
            Self::Standstill => "Standstill",
            Self::TractiveOff => "TractiveOff",
        }
    }
}
