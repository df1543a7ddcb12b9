/// Bits on the wire for one classic CAN data frame with `len` payload bytes, worst-case bit
/// stuffing included (one stuff bit per four bits from the start of frame to the CRC), and
/// the 3-bit interframe space. (This item is Rust source the generator compiles for the
/// build-time bus load and also copies verbatim into the car's generated `runtime.rs`, which
/// the Pi measures the buses with: the two figures use one formula.)
pub fn frame_bits(len: usize, extended: bool) -> u32 {
    let data = 8 * u32::try_from(len.min(64)).unwrap_or(512);
    // Start of frame to the CRC, which stuffing applies to; then CRC delimiter, ACK, end of
    // frame and the interframe space.
    let (stuffed, fixed) = if extended {
        (54 + data, 13)
    } else {
        (34 + data, 13)
    };
    stuffed + (stuffed - 1) / 4 + fixed
}
