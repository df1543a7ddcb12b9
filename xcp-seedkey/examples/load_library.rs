//! Loads the built seed-and-key library as a calibration tool does (LoadLibraryW and
//! GetProcAddress on Windows, dlopen and dlsym elsewhere), calls both exports and compares
//! their answers with `aer_xcp::seed_key::key_for` under the same secret, computed here.
//! `tools/seedkey_check.sh` runs the Windows build of this program under Wine.
//!
//! Usage: `load_library [LIBRARY]`; without an argument, the library beside this program
//! (`aer_xcp_seedkey.dll`, `libaer_xcp_seedkey.so`). The secret is read as the library reads
//! it: the file `AER_XCP_SECRET_FILE` names, else `aer-xcp-secret.key` beside the library.
//! Prints one line per check; exits 0 only if every check passed.

use aer_xcp::seed_key::{KEY_LEN, SECRET_LEN, key_for, parse_secret};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// `uint32_t XCP_GetAvailablePrivileges(uint8_t *privileges)`.
type GetAvailablePrivileges = unsafe extern "C" fn(*mut u8) -> u32;
/// `uint32_t XCP_ComputeKeyFromSeed(uint8_t, uint8_t, const uint8_t *, uint8_t *, uint8_t *)`.
type ComputeKeyFromSeed = unsafe extern "C" fn(u8, u8, *const u8, *mut u8, *mut u8) -> u32;

const SECRET_FILE: &str = "aer-xcp-secret.key";
const SECRET_FILE_VAR: &str = "AER_XCP_SECRET_FILE";
const CAL_PAG: u8 = 0x01;
const DAQ: u8 = 0x04;
const PGM: u8 = 0x10;

struct Library {
    privileges: GetAvailablePrivileges,
    compute: ComputeKeyFromSeed,
}

impl Library {
    /// `XCP_ComputeKeyFromSeed` into a buffer of `capacity` bytes: status, `*key_len`, key.
    fn key(&self, privilege: u8, seed: &[u8], capacity: u8) -> (u32, u8, Vec<u8>) {
        let mut key = vec![0u8; usize::from(capacity)];
        let mut key_len = capacity;
        let seed_len = u8::try_from(seed.len()).unwrap_or(u8::MAX);
        // SAFETY: the seed's bytes, a one-byte length and a buffer of `capacity` bytes.
        let status = unsafe {
            (self.compute)(
                privilege,
                seed_len,
                seed.as_ptr(),
                &mut key_len,
                key.as_mut_ptr(),
            )
        };
        key.truncate(usize::from(key_len));
        (status, key_len, key)
    }
}

#[cfg(windows)]
fn load(path: &Path) -> Result<Library, String> {
    use std::os::windows::ffi::OsStrExt;
    use windows_sys::Win32::Foundation::GetLastError;
    use windows_sys::Win32::System::LibraryLoader::{GetProcAddress, LoadLibraryW};

    let wide: Vec<u16> = path.as_os_str().encode_wide().chain([0]).collect();
    // SAFETY: a NUL-terminated UTF-16 path. The library stays loaded until the program ends.
    let module = unsafe { LoadLibraryW(wide.as_ptr()) };
    if module.is_null() {
        // SAFETY: no other call in between.
        let error = unsafe { GetLastError() };
        return Err(format!("LoadLibraryW({}): error {error}", path.display()));
    }
    let symbol = |name: &core::ffi::CStr| {
        // SAFETY: a loaded module and a NUL-terminated name.
        unsafe { GetProcAddress(module, name.as_ptr().cast()) }
            .ok_or_else(|| format!("GetProcAddress({name:?}) found nothing"))
    };
    let privileges = symbol(c"XCP_GetAvailablePrivileges")?;
    let compute = symbol(c"XCP_ComputeKeyFromSeed")?;
    // SAFETY: the exports have these C signatures (the interface's).
    unsafe {
        Ok(Library {
            privileges: core::mem::transmute::<
                unsafe extern "system" fn() -> isize,
                GetAvailablePrivileges,
            >(privileges),
            compute: core::mem::transmute::<unsafe extern "system" fn() -> isize, ComputeKeyFromSeed>(
                compute,
            ),
        })
    }
}

#[cfg(unix)]
fn load(path: &Path) -> Result<Library, String> {
    use std::ffi::{CStr, CString};
    use std::os::unix::ffi::OsStrExt;

    let dl_error = || {
        // SAFETY: dlerror's message, if any, stays valid until the next dl call.
        let message = unsafe { libc::dlerror() };
        if message.is_null() {
            String::from("no message")
        } else {
            // SAFETY: a C string from dlerror.
            unsafe { CStr::from_ptr(message) }
                .to_string_lossy()
                .into_owned()
        }
    };
    let name = CString::new(path.as_os_str().as_bytes()).map_err(|e| e.to_string())?;
    // SAFETY: a NUL-terminated path. The library stays loaded until the program ends.
    let handle = unsafe { libc::dlopen(name.as_ptr(), libc::RTLD_NOW | libc::RTLD_LOCAL) };
    if handle.is_null() {
        return Err(format!("dlopen({}): {}", path.display(), dl_error()));
    }
    let symbol = |name: &CStr| {
        // SAFETY: a loaded library and a NUL-terminated name.
        let address = unsafe { libc::dlsym(handle, name.as_ptr()) };
        if address.is_null() {
            Err(format!("dlsym({name:?}): {}", dl_error()))
        } else {
            Ok(address)
        }
    };
    let privileges = symbol(c"XCP_GetAvailablePrivileges")?;
    let compute = symbol(c"XCP_ComputeKeyFromSeed")?;
    // SAFETY: the exports have these C signatures (the interface's).
    unsafe {
        Ok(Library {
            privileges: core::mem::transmute::<*mut libc::c_void, GetAvailablePrivileges>(
                privileges,
            ),
            compute: core::mem::transmute::<*mut libc::c_void, ComputeKeyFromSeed>(compute),
        })
    }
}

/// The checks, one line each; counts the failures.
struct Report {
    failed: usize,
}

impl Report {
    fn check(&mut self, what: &str, passed: bool, detail: impl std::fmt::Display) {
        if passed {
            println!("ok    {what}");
        } else {
            println!("FAIL  {what}: {detail}");
            self.failed += 1;
        }
    }
}

/// A secret file's 32 bytes, as the library parses them.
fn read_secret(path: &Path) -> Result<[u8; SECRET_LEN], String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    parse_secret(&text).ok_or_else(|| format!("{}: not 64 hex digits", path.display()))
}

fn set_secret_file(path: Option<&Path>) {
    // SAFETY: this program has one thread; the library reads the variable at each call.
    unsafe {
        match path {
            Some(path) => std::env::set_var(SECRET_FILE_VAR, path),
            None => std::env::remove_var(SECRET_FILE_VAR),
        }
    }
}

fn run(library_path: &Path) -> Result<usize, String> {
    let library = load(library_path)?;
    println!("loaded {}", library_path.display());
    let secret_path = match std::env::var_os(SECRET_FILE_VAR) {
        Some(path) if !path.is_empty() => PathBuf::from(path),
        _ => library_path
            .parent()
            .ok_or("the library's path has no directory")?
            .join(SECRET_FILE),
    };
    let secret = read_secret(&secret_path)?;
    let mut report = Report { failed: 0 };

    let mut privileges = 0xEE;
    // SAFETY: one writable byte.
    let status = unsafe { (library.privileges)(&mut privileges) };
    report.check(
        "XCP_GetAvailablePrivileges: 0, CAL/PAG only",
        status == 0 && privileges == CAL_PAG,
        format!("status {status}, privileges {privileges:#04x}"),
    );
    // SAFETY: null is part of what the library must survive.
    let status = unsafe { (library.privileges)(core::ptr::null_mut()) };
    report.check(
        "XCP_GetAvailablePrivileges(NULL): 1",
        status == 1,
        format!("status {status}"),
    );

    let long: Vec<u8> = (0..=254u8).collect();
    for seed in [&[0x5e, 0xed, 0x00, 0x01, 0xfe, 0x42][..], &[0x00], &long] {
        let expected = key_for(&secret, seed);
        let (status, key_len, key) = library.key(CAL_PAG, seed, 255);
        report.check(
            &format!("a {}-byte seed: the CCM's key", seed.len()),
            status == 0 && usize::from(key_len) == KEY_LEN && key == expected,
            format!("status {status}, key_len {key_len}, key {key:02x?}, expected {expected:02x?}"),
        );
    }
    let seed = [1, 2, 3, 4, 5, 6];
    let (status, key_len, key) = library.key(CAL_PAG, &seed, 16);
    report.check(
        "a buffer of exactly 16 bytes",
        status == 0 && key_len == 16 && key == key_for(&secret, &seed),
        format!("status {status}, key_len {key_len}"),
    );
    let (status, key_len, _) = library.key(CAL_PAG, &seed, 15);
    report.check(
        "a 15-byte buffer: 3, key_len set to 16",
        status == 3 && key_len == 16,
        format!("status {status}, key_len {key_len}"),
    );
    for privilege in [DAQ, PGM, 0x00] {
        let (status, _, _) = library.key(privilege, &seed, 255);
        report.check(
            &format!("privilege {privilege:#04x}: 1"),
            status == 1,
            format!("status {status}"),
        );
    }
    let (status, _, _) = library.key(CAL_PAG, &[], 255);
    report.check("an empty seed: 2", status == 2, format!("status {status}"));
    let mut key = [0u8; 32];
    let mut key_len = 32u8;
    // SAFETY: null pointers are part of what the library must survive; the others are valid.
    let nulls = unsafe {
        [
            (library.compute)(
                CAL_PAG,
                6,
                core::ptr::null(),
                &mut key_len,
                key.as_mut_ptr(),
            ),
            (library.compute)(
                CAL_PAG,
                6,
                seed.as_ptr(),
                &mut key_len,
                core::ptr::null_mut(),
            ),
            (library.compute)(
                CAL_PAG,
                6,
                seed.as_ptr(),
                core::ptr::null_mut(),
                key.as_mut_ptr(),
            ),
        ]
    };
    report.check(
        "null seed, key, key_len: 2, 3, 3",
        nulls == [2, 3, 3],
        format!("{nulls:?}"),
    );

    // AER_XCP_SECRET_FILE names another secret: the library's key follows it.
    let other_path = std::env::temp_dir().join(format!("aer-seedkey-{}.key", std::process::id()));
    let other: [u8; SECRET_LEN] = core::array::from_fn(|i| (i as u8).wrapping_mul(37));
    let hex: String = other.iter().map(|b| format!("{b:02x}")).collect();
    std::fs::write(&other_path, hex).map_err(|e| format!("{}: {e}", other_path.display()))?;
    let previous = std::env::var_os(SECRET_FILE_VAR);
    set_secret_file(Some(&other_path));
    let (status, _, key) = library.key(CAL_PAG, &seed, 255);
    report.check(
        "AER_XCP_SECRET_FILE names the secret",
        status == 0 && key == key_for(&other, &seed),
        format!("status {status}"),
    );
    let _ = std::fs::remove_file(&other_path);
    let (status, _, _) = library.key(CAL_PAG, &seed, 255);
    report.check(
        "no readable secret: 1",
        status == 1,
        format!("status {status}"),
    );
    set_secret_file(previous.as_deref().map(Path::new));
    Ok(report.failed)
}

fn main() -> ExitCode {
    let library = match std::env::args_os().nth(1) {
        Some(path) => PathBuf::from(path),
        None => {
            let name = format!(
                "{}aer_xcp_seedkey{}",
                std::env::consts::DLL_PREFIX,
                std::env::consts::DLL_SUFFIX
            );
            match std::env::current_exe() {
                Ok(exe) => exe.with_file_name(name),
                Err(error) => {
                    eprintln!("load_library: where is this program? {error}");
                    return ExitCode::FAILURE;
                }
            }
        }
    };
    match run(&library) {
        Ok(0) => {
            println!("every check passed");
            ExitCode::SUCCESS
        }
        Ok(failed) => {
            println!("{failed} checks failed");
            ExitCode::FAILURE
        }
        Err(error) => {
            eprintln!("load_library: {error}");
            ExitCode::FAILURE
        }
    }
}
