/// Copies `bytes` into `out` at `at`; bytes past the end of `out` are not written.
#[inline(always)]
pub fn put(out: &mut [u8], at: usize, bytes: &[u8]) {
    for (i, b) in bytes.iter().enumerate() {
        if let Some(slot) = out.get_mut(at + i) {
            *slot = *b;
        }
    }
}

/// `N` bytes of `data` from `at`; bytes past the end read as zero.
#[inline(always)]
pub fn take<const N: usize>(data: &[u8], at: usize) -> [u8; N] {
    let mut bytes = [0u8; N];
    for (i, b) in bytes.iter_mut().enumerate() {
        *b = data.get(at + i).copied().unwrap_or(0);
    }
    bytes
}
