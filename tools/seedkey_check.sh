#!/usr/bin/env bash
# The seed-and-key library (xcp-seedkey/) as the calibration tools load it:
# - builds the 64-bit Windows DLL (CANape, INCA) and checks its export table names exactly
#   XCP_GetAvailablePrivileges and XCP_ComputeKeyFromSeed, undecorated, and that it needs no
#   MinGW runtime DLL a tuner's PC lacks;
# - loads it under Wine from a Windows program (examples/load_library.rs: LoadLibraryW,
#   GetProcAddress) that compares its keys with aer_xcp::seed_key::key_for under the same
#   secret file, and checks the refusals;
# - builds the 32-bit DLL (older CANape and INCA) and checks its exports the same way, without
#   running it: Debian's wine64 runs 64-bit programs only (AER_SEEDKEY_I686=0 skips it);
# - the Linux shared object (pyxcp) through the same program and through Python's ctypes,
#   against Python's own HMAC.
# Installs what it needs (Debian 12, as root): the Rust targets, the MinGW-w64 cross
# compilers (the win32-threads variants only) and wine64, each only when missing.
set -euo pipefail
cd "$(dirname "$0")/.."

started=$SECONDS
step() { printf '\n(%d s) === %s\n' $((SECONDS - started)) "$*"; }
fail() { echo "seedkey_check: $*" >&2; exit 1; }

i686=${AER_SEEDKEY_I686:-1}
target_dir=${CARGO_TARGET_DIR:-target}
work=$(realpath -m "$target_dir")/seedkey-check
new_secret() { python3 -c 'import secrets; print(secrets.token_hex(32))'; }

step "toolchain: the Windows targets, MinGW-w64, wine64"
targets=(x86_64-pc-windows-gnu)
if [ "$i686" = 1 ]; then
  targets+=(i686-pc-windows-gnu)
fi
rustup target add "${targets[@]}"
missing=()
command -v x86_64-w64-mingw32-gcc >/dev/null || missing+=(gcc-mingw-w64-x86-64-win32)
if [ "$i686" = 1 ]; then
  command -v i686-w64-mingw32-gcc >/dev/null || missing+=(gcc-mingw-w64-i686-win32)
fi
[ -x /usr/lib/wine/wine64 ] || missing+=(wine64)
if [ ${#missing[@]} -gt 0 ]; then
  apt-get update
  DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}"
fi

step "build: the DLLs with the Windows test program, the Linux .so with the same program"
for target in "${targets[@]}"; do
  cargo build -p aer-xcp-seedkey --release --target "$target" --lib --example load_library
done
cargo build -p aer-xcp-seedkey --release --lib --example load_library

# The names a DLL exports, one a line (awk reads to the end: objdump must not see a closed pipe).
exports() {
  "$1" -p "$2" | awk '/\[Ordinal\/Name Pointer\] Table/{table=1; next} NF==0{table=0} table{print $NF}'
}
# The DLLs a DLL imports, one a line, lower case.
imports() {
  "$1" -p "$2" | awk '/DLL Name:/{print tolower($3)}' | sort -u
}

for target in "${targets[@]}"; do
  case $target in
    x86_64-*) objdump=x86_64-w64-mingw32-objdump ;;
    i686-*) objdump=i686-w64-mingw32-objdump ;;
  esac
  dll=$target_dir/$target/release/aer_xcp_seedkey.dll
  step "$target: $dll ($(stat -c %s "$dll") bytes)"
  names=$(exports "$objdump" "$dll" | sort | tr '\n' ' ')
  echo "exports: $names"
  [ "$names" = "XCP_ComputeKeyFromSeed XCP_GetAvailablePrivileges " ] ||
    fail "$dll exports '$names', not exactly the two functions, undecorated"
  needed=$(imports "$objdump" "$dll" | tr '\n' ' ')
  echo "imports: $needed"
  for lib in $needed; do
    case $lib in
      kernel32.dll | ntdll.dll | msvcrt.dll | advapi32.dll | userenv.dll | ws2_32.dll | \
        bcryptprimitives.dll | api-ms-win-*) ;;
      *) fail "$dll needs $lib, which a calibration PC need not have" ;;
    esac
  done
done

step "x86_64-pc-windows-gnu: the DLL loaded by a Windows program under Wine"
dir=$work/x86_64-pc-windows-gnu
rm -rf "$dir" && mkdir -p "$dir"
cp "$target_dir/x86_64-pc-windows-gnu/release/aer_xcp_seedkey.dll" \
  "$target_dir/x86_64-pc-windows-gnu/release/examples/load_library.exe" "$dir/"
new_secret > "$dir/aer-xcp-secret.key"
# Rust's standard library takes its random numbers from bcryptprimitives.dll's ProcessPrng
# (every Windows since 10 has it); Debian 12's Wine 8 lacks the DLL, so the program and the
# library would not load. A stand-in beside the program, for the test only (never shipped).
cat > "$work/bcryptprimitives.c" <<'EOF_C'
#include <windows.h>
#include <bcrypt.h>
/* ProcessPrng: fills data with random bytes, through BCryptGenRandom (which Wine has). */
BOOL WINAPI ProcessPrng(PBYTE data, SIZE_T len)
{
    while (len > 0) {
        ULONG chunk = len > 0x10000000 ? 0x10000000 : (ULONG)len;
        if (BCryptGenRandom(NULL, data, chunk, BCRYPT_USE_SYSTEM_PREFERRED_RNG) != 0)
            return FALSE;
        data += chunk;
        len -= chunk;
    }
    return TRUE;
}
EOF_C
x86_64-w64-mingw32-gcc -shared -O2 -o "$dir/bcryptprimitives.dll" "$work/bcryptprimitives.c" -lbcrypt
# A throwaway prefix, no display, no Mono or Gecko installers; the first start builds the
# prefix (most of this step's time; it says it failed to open syswow64\rundll32.exe, which
# is 32-bit Wine's and harmless). Wine's loader errors stay on: a DLL that does not load is
# named.
export WINEPREFIX=$work/wineprefix WINEDEBUG=-all,err+module WINEDLLOVERRIDES="mscoree,mshtml="
unset DISPLAY WAYLAND_DISPLAY
wine_started=$SECONDS
# The secret beside the DLL, as the tools will have it: no AER_XCP_SECRET_FILE.
status=0
env -u AER_XCP_SECRET_FILE /usr/lib/wine/wine64 "$dir/load_library.exe" || status=$?
# The prefix's wineserver would linger a few seconds after its last program: stop it now.
# The prefix takes about 700 MB: gone too (a new one costs about 5 s).
/usr/lib/wine/wineserver -k 2>/dev/null || true
rm -rf "$WINEPREFIX"
echo "(wine: $((SECONDS - wine_started)) s)"
[ "$status" = 0 ] || fail "the Windows program failed under Wine (exit $status)"

step "the Linux .so: the same program, then Python's ctypes against Python's HMAC"
dir=$work/linux
rm -rf "$dir" && mkdir -p "$dir"
cp "$target_dir/release/libaer_xcp_seedkey.so" "$target_dir/release/examples/load_library" "$dir/"
new_secret > "$dir/aer-xcp-secret.key"
env -u AER_XCP_SECRET_FILE "$dir/load_library"
env -u AER_XCP_SECRET_FILE python3 - "$dir/libaer_xcp_seedkey.so" "$dir/aer-xcp-secret.key" <<'EOF'
import ctypes, hashlib, hmac, sys

library, secret_file = sys.argv[1:]
secret = bytes.fromhex(open(secret_file).read().strip())
lib = ctypes.CDLL(library)
lib.XCP_GetAvailablePrivileges.argtypes = [ctypes.POINTER(ctypes.c_uint8)]
lib.XCP_GetAvailablePrivileges.restype = ctypes.c_uint32
lib.XCP_ComputeKeyFromSeed.argtypes = [ctypes.c_uint8, ctypes.c_uint8, ctypes.c_char_p,
                                       ctypes.POINTER(ctypes.c_uint8), ctypes.c_char_p]
lib.XCP_ComputeKeyFromSeed.restype = ctypes.c_uint32


def key(privilege, seed, capacity):
    buffer = ctypes.create_string_buffer(capacity)
    length = ctypes.c_uint8(capacity)
    status = lib.XCP_ComputeKeyFromSeed(privilege, len(seed), seed, ctypes.byref(length), buffer)
    return status, length.value, buffer.raw[: length.value]


failed = 0


def check(what, passed, detail):
    global failed
    print(("ok    " if passed else "FAIL  ") + what + ("" if passed else f": {detail}"))
    failed += not passed


privileges = ctypes.c_uint8(0xEE)
status = lib.XCP_GetAvailablePrivileges(ctypes.byref(privileges))
check("ctypes: privileges CAL/PAG", (status, privileges.value) == (0, 0x01), (status, privileges.value))
for seed in (bytes([0x5E, 0xED, 0x00, 0x01, 0xFE, 0x42]), b"\x00", bytes(range(255))):
    expected = hmac.new(secret, seed, hashlib.sha256).digest()[:16]
    got = key(0x01, seed, 128)
    check(f"ctypes: a {len(seed)}-byte seed, Python's HMAC", got == (0, 16, expected), (got, expected.hex()))
got = key(0x01, b"123456", 15)
check("ctypes: a 15-byte buffer: 3", got[:2] == (3, 16), got)
got = key(0x04, b"123456", 128)
check("ctypes: privilege DAQ: 1", got[0] == 1, got)
sys.exit(1 if failed else 0)
EOF

if [ "$i686" = 1 ]; then
  echo
  echo "note: the 32-bit DLL was built and its exports checked, not run (Debian's wine64 runs"
  echo "64-bit programs only; wine32 needs the i386 architecture)."
fi
step "every seed-and-key check passed"
