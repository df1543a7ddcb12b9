#!/usr/bin/env python3
"""Exit 0 when two Intel HEX files load the same bytes at the same addresses (the record
layout may differ): checks `cargo xtask firmware` against llvm-objcopy."""
import sys


def load(path):
    memory, upper = {}, 0
    for number, line in enumerate(open(path), 1):
        line = line.strip()
        if not line:
            continue
        raw = bytes.fromhex(line[1:])
        if not line.startswith(":") or sum(raw) & 0xFF:
            sys.exit(f"{path}:{number}: bad record")
        length, address, kind, data = raw[0], int.from_bytes(raw[1:3], "big"), raw[3], raw[4:-1]
        if len(data) != length:
            sys.exit(f"{path}:{number}: bad length")
        if kind == 0:
            for offset, byte in enumerate(data):
                memory[upper + address + offset] = byte
        elif kind == 1:
            break
        elif kind == 4:
            upper = int.from_bytes(data, "big") << 16
    return memory


ours, reference = load(sys.argv[1]), load(sys.argv[2])
if ours != reference:
    differing = sorted(set(ours.items()) ^ set(reference.items()))[:5]
    sys.exit(f"{sys.argv[1]} and {sys.argv[2]} differ, e.g. at {[hex(a) for a, _ in differing]}")
print(f"{sys.argv[1]}: {len(ours)} bytes, same as {sys.argv[2]}")
