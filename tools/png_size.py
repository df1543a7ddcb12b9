#!/usr/bin/env python3
"""Checks that a file is a PNG image of the given width and height whose image data is not
uniform (a blank render would pass a size check alone). The data is read as stored, after PNG
row filtering: a uniform image filters to a handful of distinct values, a real one to many."""

import struct
import sys
import zlib


def main() -> int:
    path, width, height = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        print(f"{path}: not a PNG file", file=sys.stderr)
        return 1
    w, h = struct.unpack(">II", data[16:24])
    if (w, h) != (width, height):
        print(f"{path}: {w}x{h}, expected {width}x{height}", file=sys.stderr)
        return 1
    chunks, pos = [], 8
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        if kind == b"IDAT":
            chunks.append(data[pos + 8 : pos + 8 + length])
        pos += 12 + length
    pixels = zlib.decompress(b"".join(chunks))
    stride = 1 + 4 * w
    rows = {pixels[r * stride + 1 : (r + 1) * stride] for r in range(h)}
    distinct = {row[i : i + 4] for row in rows for i in range(0, len(row), 4)}
    if len(distinct) < 16:
        print(f"{path}: only {len(distinct)} distinct values: a blank render?", file=sys.stderr)
        return 1
    print(f"{path}: {w}x{h} PNG, {len(distinct)} distinct pixel values")
    return 0


if __name__ == "__main__":
    sys.exit(main())
