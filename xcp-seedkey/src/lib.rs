//! The team's XCP seed-and-key library, as calibration tools load it: CANape and INCA on
//! Windows (`aer_xcp_seedkey.dll`, named in the A2L's `SEED_AND_KEY_EXTERNAL_FUNCTION`), pyxcp
//! on Linux (`libaer_xcp_seedkey.so`, its option `seed_n_key_dll`). It exports, unmangled and
//! cdecl, the two C functions of the tools' seed-and-key interface:
//!
//! - `uint32_t XCP_GetAvailablePrivileges(uint8_t *privileges)`: the resources it can unlock,
//!   [`PRIVILEGES`] (CAL/PAG, 0x01): the only resource the CCM's slave protects. Reads and DAQ
//!   are never locked (its GET_SEED answers a seed of length 0 for DAQ).
//! - `uint32_t XCP_ComputeKeyFromSeed(uint8_t privilege, uint8_t seed_len, const uint8_t *seed,
//!   uint8_t *key_len, uint8_t *key)`: `*key_len` holds the key buffer's size on entry and the
//!   key's length ([`KEY_LEN`], 16) on return.
//!
//! Both return a [`Status`]: 0 ack, 1 privilege not available, 2 invalid seed length, 3 key
//! buffer too small. The key is [`aer_xcp::seed_key::key_for`], the function the CCM checks
//! with: the first 16 bytes of HMAC-SHA256 over the seed (any length from 1 to 255 bytes; the
//! CCM's is 6), keyed with the team's 32-byte secret.
//!
//! The secret is never compiled in. Every key computation reads it (64 hex digits, the format
//! of `ccm/xcp-secret.key`) from the file the environment variable [`SECRET_FILE_VAR`]
//! (`AER_XCP_SECRET_FILE`) names, else from [`SECRET_FILE`] (`aer-xcp-secret.key`) in the
//! directory the library was loaded from. Read at every call, a replaced file counts at the
//! next unlock without restarting the tool. Without a readable secret the library can unlock
//! nothing: XCP_ComputeKeyFromSeed answers 1 (privilege not available), so the tool reports
//! that it cannot unlock instead of sending a wrong key, which would end the session.
//!
//! The arguments are checked before the secret is read, in this order: the privilege (1 unless
//! it is exactly CAL/PAG), the seed (2 if its length is 0 or the pointer null), the key buffer
//! (3 if `key_len` or `key` is null or `*key_len` is below 16; `*key_len` is then set to 16
//! when it can be written). XCP_GetAvailablePrivileges answers 1 to a null pointer.
//!
//! Nothing here panics (no unwrap, no indexing: the lints below deny them). A panic would
//! still not cross the C boundary: XCP_ComputeKeyFromSeed catches it and answers 1 (the other
//! export only writes one byte).
//!
//! Data flow: tool -> export -> [`compute_key`] (the safe API, tested on the host) ->
//! `aer_xcp::seed_key::key_for`; the secret from [`load_secret`].

#![deny(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

use aer_xcp::protocol::resource;
use aer_xcp::seed_key::{key_for, parse_secret};
use std::io::Read;
use std::path::{Path, PathBuf};

pub use aer_xcp::seed_key::{KEY_LEN, SECRET_LEN};

/// The resources this library can unlock (XCP resource bits): calibration and paging, which
/// the CCM's slave locks at every CONNECT.
pub const PRIVILEGES: u8 = resource::CAL_PAG;

/// The secret file's name, in the library's directory.
pub const SECRET_FILE: &str = "aer-xcp-secret.key";

/// The environment variable naming another secret file (the firmware's build reads the same).
pub const SECRET_FILE_VAR: &str = "AER_XCP_SECRET_FILE";

/// The longest seed the C interface can pass (its length is one byte).
pub const SEED_MAX: usize = u8::MAX as usize;

/// Bytes of a secret file read at most: the 64 digits with whitespace fit many times over.
const SECRET_FILE_MAX: u64 = 4096;

/// The key's length as `*key_len` reports it.
const KEY_LEN_U8: u8 = KEY_LEN as u8;
const _: () = assert!(KEY_LEN <= u8::MAX as usize);

/// What the seed-and-key functions answer (their `uint32_t` return value).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Status {
    /// The key was computed.
    Ack = 0,
    /// The library cannot unlock this resource (or has no secret to unlock with).
    PrivilegeNotAvailable = 1,
    /// No seed (length 0, or a null pointer).
    InvalidSeedLength = 2,
    /// The key does not fit the buffer (or there is no buffer).
    KeyBufferTooSmall = 3,
}

impl Status {
    /// The C interface's number.
    pub const fn code(self) -> u32 {
        self as u32
    }
}

/// Whether a key for `privilege`, from a seed of `seed_len` bytes, into a buffer of
/// `key_capacity` bytes can be computed: the checks of [`compute_key`], in its order.
pub fn check(privilege: u8, seed_len: usize, key_capacity: usize) -> Result<(), Status> {
    if privilege != PRIVILEGES {
        return Err(Status::PrivilegeNotAvailable);
    }
    if seed_len == 0 || seed_len > SEED_MAX {
        return Err(Status::InvalidSeedLength);
    }
    if key_capacity < KEY_LEN {
        return Err(Status::KeyBufferTooSmall);
    }
    Ok(())
}

/// The key for `seed` under `secret` into the start of `key`; returns its length
/// ([`KEY_LEN`]). Refuses as XCP_ComputeKeyFromSeed does ([`check`]).
pub fn compute_key(
    secret: &[u8; SECRET_LEN],
    privilege: u8,
    seed: &[u8],
    key: &mut [u8],
) -> Result<usize, Status> {
    check(privilege, seed.len(), key.len())?;
    let computed = key_for(secret, seed);
    for (out, byte) in key.iter_mut().zip(computed.iter()) {
        *out = *byte;
    }
    Ok(KEY_LEN)
}

/// Where the secret is read from: the file [`SECRET_FILE_VAR`] names when it is set and not
/// empty (and then only that file), else [`SECRET_FILE`] beside the library.
pub fn secret_path() -> Option<PathBuf> {
    match std::env::var_os(SECRET_FILE_VAR) {
        Some(path) if !path.is_empty() => Some(PathBuf::from(path)),
        _ => library_path().and_then(|library| Some(library.parent()?.join(SECRET_FILE))),
    }
}

/// The secret in the file at `path`, if it is 64 hex digits (whitespace around them ignored).
pub fn read_secret(path: &Path) -> Option<[u8; SECRET_LEN]> {
    let mut text = String::new();
    std::fs::File::open(path)
        .ok()?
        .take(SECRET_FILE_MAX)
        .read_to_string(&mut text)
        .ok()?;
    parse_secret(&text)
}

/// The secret the exports unlock with ([`secret_path`], [`read_secret`]).
pub fn load_secret() -> Option<[u8; SECRET_LEN]> {
    read_secret(&secret_path()?)
}

/// The file this code was loaded from: the DLL or shared object (the executable when the rlib
/// is linked into one).
pub fn library_path() -> Option<PathBuf> {
    own_file::path()
}

/// XCP_GetAvailablePrivileges: writes [`PRIVILEGES`] to `*privileges` and answers 0 (1 to a
/// null pointer).
///
/// # Safety
/// `privileges` is null or points to one writable byte.
#[allow(non_snake_case)]
#[unsafe(no_mangle)]
pub unsafe extern "C" fn XCP_GetAvailablePrivileges(privileges: *mut u8) -> u32 {
    if privileges.is_null() {
        return Status::PrivilegeNotAvailable.code();
    }
    // SAFETY: not null, and the caller's one writable byte.
    unsafe { privileges.write(PRIVILEGES) };
    Status::Ack.code()
}

/// XCP_ComputeKeyFromSeed: the key for the seed under the secret ([`load_secret`]) into `key`,
/// its length into `*key_len` (see the crate's documentation for the refusals).
///
/// # Safety
/// Each pointer is null or valid: `seed` for `seed_len` bytes read, `key_len` for one byte
/// read and written, `key` for `*key_len` bytes written.
#[allow(non_snake_case)]
#[unsafe(no_mangle)]
pub unsafe extern "C" fn XCP_ComputeKeyFromSeed(
    privilege: u8,
    seed_len: u8,
    seed: *const u8,
    key_len: *mut u8,
    key: *mut u8,
) -> u32 {
    let answer = std::panic::catch_unwind(|| {
        // SAFETY: the caller's pointers, as this function's contract states them.
        unsafe { key_from_seed(load_secret, privilege, seed_len, seed, key_len, key) }
    });
    match answer {
        Ok(Ok(())) => Status::Ack.code(),
        Ok(Err(status)) => status.code(),
        Err(_) => Status::PrivilegeNotAvailable.code(),
    }
}

/// XCP_ComputeKeyFromSeed with the secret from `secret` (read only once the arguments passed
/// [`check`]). Caller memory is only copied, never borrowed: the seed and the key may even
/// share a buffer.
///
/// # Safety
/// As [`XCP_ComputeKeyFromSeed`].
unsafe fn key_from_seed(
    secret: impl FnOnce() -> Option<[u8; SECRET_LEN]>,
    privilege: u8,
    seed_len: u8,
    seed: *const u8,
    key_len: *mut u8,
    key: *mut u8,
) -> Result<(), Status> {
    let seed_len = if seed.is_null() {
        0
    } else {
        usize::from(seed_len)
    };
    let capacity = if key_len.is_null() || key.is_null() {
        0
    } else {
        // SAFETY: not null, and the caller's readable byte.
        usize::from(unsafe { key_len.read() })
    };
    if let Err(status) = check(privilege, seed_len, capacity) {
        if status == Status::KeyBufferTooSmall && !key_len.is_null() {
            // SAFETY: not null, and the caller's writable byte.
            unsafe { key_len.write(KEY_LEN_U8) };
        }
        return Err(status);
    }
    let secret = secret().ok_or(Status::PrivilegeNotAvailable)?;
    let mut seed_copy = [0u8; SEED_MAX];
    // SAFETY: `seed` is not null and the caller's `seed_len` (at most 255) readable bytes; the
    // copy is local.
    unsafe { core::ptr::copy_nonoverlapping(seed, seed_copy.as_mut_ptr(), seed_len) };
    let mut computed = [0u8; KEY_LEN];
    let len = compute_key(
        &secret,
        privilege,
        seed_copy.get(..seed_len).unwrap_or_default(),
        &mut computed,
    )?;
    // SAFETY: `key` is not null and the caller's `capacity` (at least KEY_LEN = len) writable
    // bytes; `key_len` is not null and writable.
    unsafe {
        core::ptr::copy_nonoverlapping(computed.as_ptr(), key, len);
        key_len.write(KEY_LEN_U8);
    }
    Ok(())
}

/// Finding this library's own file.
#[cfg(windows)]
mod own_file {
    use std::ffi::OsString;
    use std::os::windows::ffi::OsStringExt;
    use std::path::PathBuf;
    use windows_sys::Win32::Foundation::HMODULE;
    use windows_sys::Win32::System::LibraryLoader::{
        GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS, GET_MODULE_HANDLE_EX_FLAG_UNCHANGED_REFCOUNT,
        GetModuleFileNameW, GetModuleHandleExW,
    };

    /// The longest path Windows gives out, in UTF-16 units.
    const PATH_UNITS_MAX: usize = 32_768;

    /// The module holding XCP_ComputeKeyFromSeed, and its file's name.
    pub fn path() -> Option<PathBuf> {
        let mut module: HMODULE = core::ptr::null_mut();
        let address = crate::XCP_ComputeKeyFromSeed as *const u16;
        // SAFETY: FROM_ADDRESS takes any address inside a module; UNCHANGED_REFCOUNT: the
        // handle needs no release (this code is that module, loaded while it runs).
        let found = unsafe {
            GetModuleHandleExW(
                GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS
                    | GET_MODULE_HANDLE_EX_FLAG_UNCHANGED_REFCOUNT,
                address,
                &mut module,
            )
        };
        if found == 0 {
            return None;
        }
        let mut units = 260;
        loop {
            let mut name = vec![0u16; units];
            // SAFETY: a buffer of `units` UTF-16 units, its size passed along.
            let written = unsafe {
                GetModuleFileNameW(module, name.as_mut_ptr(), u32::try_from(units).ok()?)
            };
            let written = usize::try_from(written).ok()?;
            if written == 0 {
                return None;
            }
            // A name that filled the buffer may have been cut: try a larger one.
            if written < units {
                name.truncate(written);
                return Some(PathBuf::from(OsString::from_wide(&name)));
            }
            if units >= PATH_UNITS_MAX {
                return None;
            }
            units = (units * 2).min(PATH_UNITS_MAX);
        }
    }
}

/// Finding this library's own file.
#[cfg(unix)]
mod own_file {
    use std::ffi::{CStr, OsStr};
    use std::os::unix::ffi::OsStrExt;
    use std::path::PathBuf;

    /// The object holding XCP_ComputeKeyFromSeed, as the dynamic loader names it.
    pub fn path() -> Option<PathBuf> {
        let mut info = core::mem::MaybeUninit::<libc::Dl_info>::zeroed();
        let address = crate::XCP_ComputeKeyFromSeed as *const libc::c_void;
        // SAFETY: any address, and a place for the answer.
        if unsafe { libc::dladdr(address, info.as_mut_ptr()) } == 0 {
            return None;
        }
        // SAFETY: all pointers, zero-initialised and filled by dladdr.
        let info = unsafe { info.assume_init() };
        if info.dli_fname.is_null() {
            return None;
        }
        // SAFETY: dladdr's file name, a C string the loader keeps while the object is loaded.
        let name = unsafe { CStr::from_ptr(info.dli_fname) };
        Some(PathBuf::from(OsStr::from_bytes(name.to_bytes())))
    }
}

/// Elsewhere the library cannot find itself: only the environment variable names a secret.
#[cfg(not(any(windows, unix)))]
mod own_file {
    use std::path::PathBuf;

    pub fn path() -> Option<PathBuf> {
        None
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use core::ptr;

    const SECRET: [u8; SECRET_LEN] = *b"the seed-and-key tests' secret!!";
    const SEED: [u8; 6] = [0x5e, 0xed, 0x00, 0x01, 0xfe, 0x42];

    /// The export's core with `secret`, on Rust buffers: status, key length, key buffer.
    fn call(
        secret: Option<[u8; SECRET_LEN]>,
        privilege: u8,
        seed: &[u8],
        capacity: u8,
    ) -> (Result<(), Status>, u8, Vec<u8>) {
        let mut key = vec![0xAA; usize::from(capacity)];
        let mut key_len = capacity;
        let seed_len = u8::try_from(seed.len()).unwrap();
        // SAFETY: Rust buffers of the sizes passed.
        let status = unsafe {
            key_from_seed(
                || secret,
                privilege,
                seed_len,
                seed.as_ptr(),
                &mut key_len,
                key.as_mut_ptr(),
            )
        };
        (status, key_len, key)
    }

    #[test]
    fn the_key_is_the_ccms_key() {
        for seed in [&SEED[..], &[0x00], &[0xff; SEED_MAX]] {
            let mut key = [0u8; 64];
            let len = compute_key(&SECRET, PRIVILEGES, seed, &mut key).unwrap();
            assert_eq!(len, KEY_LEN);
            assert_eq!(key[..len], key_for(&SECRET, seed), "seed {seed:02x?}");
            assert!(
                key[len..].iter().all(|&b| b == 0),
                "bytes after the key untouched"
            );
        }
    }

    #[test]
    fn the_export_computes_the_same_key_and_reports_its_length() {
        let (status, key_len, key) = call(Some(SECRET), PRIVILEGES, &SEED, 255);
        assert_eq!(status, Ok(()));
        assert_eq!(usize::from(key_len), KEY_LEN);
        assert_eq!(key[..KEY_LEN], key_for(&SECRET, &SEED));
        assert!(
            key[KEY_LEN..].iter().all(|&b| b == 0xAA),
            "only the key written"
        );
        // A buffer of exactly the key's size is enough.
        let (status, key_len, key) = call(Some(SECRET), PRIVILEGES, &SEED, 16);
        assert_eq!((status, key_len), (Ok(()), 16));
        assert_eq!(key[..], key_for(&SECRET, &SEED));
    }

    #[test]
    fn only_calibration_and_paging_can_be_unlocked() {
        assert_eq!(PRIVILEGES, 0x01);
        for privilege in [
            0x00,
            resource::DAQ,
            resource::STIM,
            resource::PGM,
            0x05,
            0xff,
        ] {
            let mut key = [0u8; KEY_LEN];
            assert_eq!(
                compute_key(&SECRET, privilege, &SEED, &mut key),
                Err(Status::PrivilegeNotAvailable),
                "privilege {privilege:#04x}"
            );
        }
        let mut privileges = 0xEE;
        // SAFETY: a writable byte.
        assert_eq!(unsafe { XCP_GetAvailablePrivileges(&mut privileges) }, 0);
        assert_eq!(privileges, 0x01);
        // SAFETY: null is handled.
        assert_eq!(unsafe { XCP_GetAvailablePrivileges(ptr::null_mut()) }, 1);
    }

    #[test]
    fn refusals_have_the_interfaces_codes() {
        assert_eq!(Status::Ack.code(), 0);
        assert_eq!(Status::PrivilegeNotAvailable.code(), 1);
        assert_eq!(Status::InvalidSeedLength.code(), 2);
        assert_eq!(Status::KeyBufferTooSmall.code(), 3);
        let mut key = [0u8; KEY_LEN];
        assert_eq!(
            compute_key(&SECRET, PRIVILEGES, &[], &mut key),
            Err(Status::InvalidSeedLength)
        );
        assert_eq!(
            compute_key(&SECRET, PRIVILEGES, &[0; SEED_MAX + 1], &mut key),
            Err(Status::InvalidSeedLength)
        );
        assert_eq!(
            compute_key(&SECRET, PRIVILEGES, &SEED, &mut key[..KEY_LEN - 1]),
            Err(Status::KeyBufferTooSmall)
        );
        // The privilege is judged first, then the seed, then the buffer.
        assert_eq!(
            compute_key(&SECRET, resource::DAQ, &[], &mut []),
            Err(Status::PrivilegeNotAvailable)
        );
        assert_eq!(
            compute_key(&SECRET, PRIVILEGES, &[], &mut []),
            Err(Status::InvalidSeedLength)
        );
    }

    #[test]
    fn a_short_buffer_is_told_the_keys_length_and_left_alone() {
        let (status, key_len, key) = call(Some(SECRET), PRIVILEGES, &SEED, 15);
        assert_eq!(status, Err(Status::KeyBufferTooSmall));
        assert_eq!(key_len, 16, "*key_len says what is needed");
        assert!(
            key.iter().all(|&b| b == 0xAA),
            "nothing written: {key:02x?}"
        );
    }

    #[test]
    fn without_a_secret_nothing_can_be_unlocked() {
        let (status, key_len, key) = call(None, PRIVILEGES, &SEED, 255);
        assert_eq!(status, Err(Status::PrivilegeNotAvailable));
        assert_eq!(key_len, 255, "*key_len untouched");
        assert!(key.iter().all(|&b| b == 0xAA));
    }

    #[test]
    fn the_arguments_are_judged_before_the_secret_is_read() {
        let unread = || -> Option<[u8; SECRET_LEN]> { unreachable!("secret read") };
        let mut key = [0u8; KEY_LEN];
        let mut key_len = 15;
        // SAFETY: Rust buffers of the sizes passed.
        let status = unsafe {
            key_from_seed(
                unread,
                PRIVILEGES,
                6,
                SEED.as_ptr(),
                &mut key_len,
                key.as_mut_ptr(),
            )
        };
        assert_eq!(status, Err(Status::KeyBufferTooSmall));
    }

    #[test]
    fn null_pointers_are_refusals() {
        let mut key = [0u8; KEY_LEN];
        let mut key_len = KEY_LEN_U8;
        let secret = || Some(SECRET);
        // SAFETY: each pointer is null or a Rust buffer of the size passed.
        unsafe {
            assert_eq!(
                key_from_seed(
                    secret,
                    PRIVILEGES,
                    6,
                    ptr::null(),
                    &mut key_len,
                    key.as_mut_ptr()
                ),
                Err(Status::InvalidSeedLength)
            );
            assert_eq!(
                key_from_seed(
                    secret,
                    PRIVILEGES,
                    6,
                    SEED.as_ptr(),
                    &mut key_len,
                    ptr::null_mut()
                ),
                Err(Status::KeyBufferTooSmall)
            );
            assert_eq!(
                key_from_seed(
                    secret,
                    PRIVILEGES,
                    6,
                    SEED.as_ptr(),
                    ptr::null_mut(),
                    key.as_mut_ptr()
                ),
                Err(Status::KeyBufferTooSmall)
            );
            // Through the export itself: refused before any secret is looked for.
            assert_eq!(
                XCP_ComputeKeyFromSeed(
                    PRIVILEGES,
                    6,
                    ptr::null(),
                    ptr::null_mut(),
                    ptr::null_mut()
                ),
                2
            );
            assert_eq!(
                XCP_ComputeKeyFromSeed(
                    PRIVILEGES,
                    6,
                    SEED.as_ptr(),
                    ptr::null_mut(),
                    ptr::null_mut()
                ),
                3
            );
            assert_eq!(
                XCP_ComputeKeyFromSeed(
                    resource::DAQ,
                    6,
                    SEED.as_ptr(),
                    &mut key_len,
                    key.as_mut_ptr()
                ),
                1
            );
        }
    }

    #[test]
    fn the_seed_and_the_key_may_share_a_buffer() {
        let mut buffer = [0u8; 32];
        buffer[..6].copy_from_slice(&SEED);
        let mut key_len = 32;
        let at = buffer.as_mut_ptr();
        // SAFETY: one Rust buffer of 32 bytes for both; only raw copies touch it.
        let status = unsafe { key_from_seed(|| Some(SECRET), PRIVILEGES, 6, at, &mut key_len, at) };
        assert_eq!(status, Ok(()));
        assert_eq!(buffer[..KEY_LEN], key_for(&SECRET, &SEED));
    }

    #[test]
    fn the_secret_file_is_64_hex_digits() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(SECRET_FILE);
        let hex: String = SECRET.iter().map(|b| format!("{b:02x}")).collect();
        std::fs::write(&path, format!("{hex}\n")).unwrap();
        assert_eq!(read_secret(&path), Some(SECRET));
        std::fs::write(&path, &hex[1..]).unwrap();
        assert_eq!(read_secret(&path), None, "63 digits");
        assert_eq!(read_secret(&dir.path().join("missing")), None);
    }

    #[test]
    fn the_code_finds_the_file_it_was_loaded_from() {
        // Linked into the test program: the program's file.
        let path = library_path().expect("the loader names this code's file");
        assert!(path.is_file(), "{}", path.display());
        let beside = secret_path().unwrap();
        if std::env::var_os(SECRET_FILE_VAR).is_none_or(|v| v.is_empty()) {
            assert_eq!(beside, path.parent().unwrap().join(SECRET_FILE));
        }
    }
}
