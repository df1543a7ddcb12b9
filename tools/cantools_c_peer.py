"""cantools' generated C for a DBC, plus a harness in the same translation unit, so the codec
benchmark can run the reference's C beside ours on the same frames.

usage: cantools_c_peer.py DBC NAME OUT_DIR

Writes OUT_DIR/NAME.h, OUT_DIR/NAME.c (cantools generate_c_source, default options: encoding
truncates) and OUT_DIR/NAME_harness.c, which includes NAME.c (one translation unit, so gcc can
inline the per-signal functions) and defines, for a frame (id, extended, data):
  int NAME_c_decode(...)  unpack, then decode every signal and add it to *sink;
  int NAME_c_values(...)  the same values into an array, in signal order (to prepare encodes);
  int NAME_c_encode(...)  encode every value of such an array, then pack.
Each returns -1 for an unknown frame or a failed unpack/pack.
"""
import subprocess
import sys
from pathlib import Path

import cantools
from cantools.database.can.c_source import camel_to_snake_case


# One dispatch on (id, extended), as a jump table or a search: what a C user would write.
SWITCH = "    switch ((id << 1) | (extended ? 1u : 0u)) {\n"
END = "    default:\n        return -1;\n    }\n}\n\n"


def main() -> None:
    dbc, name, out = sys.argv[1], sys.argv[2], Path(sys.argv[3])
    out.mkdir(parents=True, exist_ok=True)
    subprocess.run(
        [sys.executable, "-m", "cantools", "generate_c_source", "--database-name", name,
         "-o", str(out), dbc],
        check=True, stdout=subprocess.DEVNULL)
    db = cantools.database.load_file(dbc, strict=True)
    decode, values, encode = [], [], []
    for m in db.messages:
        msg = f"{name}_{camel_to_snake_case(m.name)}"
        ext = 1 if m.is_extended_frame else 0
        head = f"    case {(m.frame_id << 1) | ext}u: {{\n        struct {msg}_t m;\n"
        sigs = [(camel_to_snake_case(s.name), s) for s in m.signals]
        body = "".join(f"        sum += {msg}_{s}_decode(m.{s});\n" for s, _ in sigs)
        decode.append(head + f"        if ({msg}_unpack(&m, data, len) < 0) return -1;\n"
                      "        double sum = 0.0;\n" + body + "        *sink += sum;\n"
                      "        return 0;\n    }\n")
        vals = "".join(f"        values[{i}] = {msg}_{s}_decode(m.{s});\n"
                       for i, (s, _) in enumerate(sigs))
        values.append(head + f"        if ({msg}_unpack(&m, data, len) < 0) return -1;\n"
                      f"        if (cap < {len(sigs)}) return -1;\n" + vals
                      + f"        return {len(sigs)};\n    }}\n")
        encs = "".join(f"        m.{s} = {msg}_{s}_encode(values[{i}]);\n"
                       for i, (s, _) in enumerate(sigs))
        encode.append(head + encs + f"        return {msg}_pack(out, &m, size);\n    }}\n")
    args = "uint32_t id, int extended, const uint8_t *data, size_t len"
    harness = (
        f'#include "{name}.c"\n\n'
        f"int {name}_c_decode({args}, double *sink)\n{{\n" + SWITCH + "".join(decode) + END
        + f"int {name}_c_values({args}, double *values, size_t cap)\n{{\n" + SWITCH
        + "".join(values) + END
        + f"int {name}_c_encode(uint32_t id, int extended, const double *values, uint8_t *out, "
        "size_t size)\n{\n" + SWITCH + "".join(encode) + END)
    (out / f"{name}_harness.c").write_text(harness)


if __name__ == "__main__":
    main()
