#!/usr/bin/env python3
"""Differential check of the generator against cantools over a directory of DBC files.

For every DBC that cantools loads in strict mode: generate a standalone crate with
`aer-codegen crate`, build all crates (with their `decode` and `encode` examples) in one
workspace, feed cantools' vectors through the examples and compare:

- decode: same signal set; integers equal; floats within half a raw step (and counted when
  bit-exact); IEEE float signals exact.
- encode: byte-exact where cantools' strict encoder accepts the values, an error where it
  refuses them.

Prints files generated/compiled, frames compared and mismatches; exits non-zero on any mismatch
or compile failure.

Usage: corpus_check.py --codegen PATH/aer-codegen --work DIR [--frames N] DIR_OR_FILES...
"""

import argparse
import glob
import json
import os
import random
import subprocess
import sys

import cantools

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cantools_vectors import vectors_for  # noqa: E402


def crate_name(stem):
    out = "".join(c.lower() if c.isalnum() else "_" for c in stem).strip("_")
    return f"corpus_{out}"


def candump(v):
    ident = f"{v['id']:08X}" if v["extended"] else f"{v['id']:03X}"
    sep = "##0" if len(v["data"]) > 16 else "#"
    return f"(1700000000.000001) can0 {ident}{sep}{v['data'].upper()}"


def compare_decode(db_msg, v, out):
    if "error" in out:
        return f"decode error {out['error']!r}"
    want, got = v["signals"], out.get("signals", {})
    if set(want) != set(got):
        return f"signal sets differ: missing {sorted(set(want) - set(got))}, extra {sorted(set(got) - set(want))}"
    for name, w in want.items():
        g = got[name]
        if w is None or g is None:
            if w is not g:
                return f"{name}: want {w}, got {g}"
            continue
        sig = db_msg.get_signal_by_name(name)
        if sig.is_float:
            if float(w) != float(g):
                return f"{name}: want {w!r}, got {g!r} (IEEE float)"
        elif isinstance(w, int) and isinstance(g, int):
            if w != g:
                return f"{name}: want {w}, got {g}"
        elif abs(float(w) - float(g)) > abs(sig.scale) / 2:
            return f"{name}: want {w!r}, got {g!r} (more than half a raw step)"
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--codegen", required=True)
    ap.add_argument("--work", required=True)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--seed", type=int, default=2026)
    args = ap.parse_args()

    files = []
    for i in args.inputs:
        files += sorted(glob.glob(os.path.join(i, "*.dbc"))) if os.path.isdir(i) else [i]
    os.makedirs(args.work, exist_ok=True)

    loaded, skipped = {}, []
    for f in files:
        try:
            loaded[f] = cantools.database.load_file(f, strict=True)
        except Exception as exc:
            skipped.append((f, str(exc).splitlines()[0]))

    generated, gen_failed = {}, []
    for f in loaded:
        stem = os.path.splitext(os.path.basename(f))[0]
        name = crate_name(stem)
        out = os.path.join(args.work, name)
        r = subprocess.run(
            [args.codegen, "crate", "--dbc", f, "--out", out, "--name", name, "--workspace-member"],
            capture_output=True, text=True)
        if r.returncode == 0:
            generated[f] = name
            # Example names must differ between packages: cargo puts every package's examples
            # in one folder, where two `decode`s overwrite each other.
            for kind in ("decode", "encode"):
                os.replace(os.path.join(out, "examples", f"{kind}.rs"),
                           os.path.join(out, "examples", f"{name}_{kind}.rs"))
        else:
            gen_failed.append((f, r.stderr.strip()[:2000]))

    with open(os.path.join(args.work, "Cargo.toml"), "w") as ws:
        ws.write("[workspace]\nresolver = \"3\"\nmembers = [\n")
        for name in generated.values():
            ws.write(f"    \"{name}\",\n")
        ws.write("]\n")
        # ~80 crates x 2 binaries: without debug info they take a tenth of the disk.
        ws.write("\n[profile.dev]\ndebug = false\n")
    # One parallel build of everything (an earlier run's binary must not stand in for one
    # that fails to build now).
    for name in generated.values():
        for kind in ("decode", "encode"):
            stale = os.path.join(args.work, "target", "debug", "examples", f"{name}_{kind}")
            if os.path.exists(stale):
                os.remove(stale)
    build = subprocess.run(["cargo", "build", "--examples", "--keep-going", "--quiet"],
                           cwd=args.work, capture_output=True, text=True)
    if build.returncode != 0:
        print(build.stderr[-6000:], file=sys.stderr)
    by_name = {}
    for name in generated.values():
        found = {}
        for kind in ("decode", "encode"):
            path = os.path.join(args.work, "target", "debug", "examples", f"{name}_{kind}")
            if os.path.exists(path):
                found[kind] = path
        by_name[name] = found

    frames = mismatches = exact = encodes = refused = 0
    compile_failed = []
    report_lines = []
    for f, name in generated.items():
        bins = by_name.get(name, {})
        if "decode" not in bins or "encode" not in bins:
            compile_failed.append(f)
            continue
        db = loaded[f]
        rng = random.Random(f"{args.seed}:{os.path.splitext(os.path.basename(f))[0]}")
        vectors = list(vectors_for(db, rng, args.frames))
        if not vectors:
            continue
        dec = subprocess.run([bins["decode"]], capture_output=True, text=True,
                             input="\n".join(candump(v) for v in vectors) + "\n")
        enc_in = "\n".join(json.dumps({"id": v["id"], "extended": v["extended"], "signals": v["signals"]})
                           for v in vectors) + "\n"
        enc = subprocess.run([bins["encode"]], capture_output=True, text=True, input=enc_in)
        dec_lines = dec.stdout.splitlines()
        enc_lines = enc.stdout.splitlines()
        file_bad = 0
        for i, v in enumerate(vectors):
            frames += 1
            msg = db.get_message_by_name(v["name"])
            problem = None
            if i >= len(dec_lines) or i >= len(enc_lines):
                problem = "missing output line"
            else:
                out = json.loads(dec_lines[i])
                problem = compare_decode(msg, v, out)
                if problem is None and all(
                        out["signals"].get(k) == w for k, w in v["signals"].items()):
                    exact += 1
                if problem is None:
                    line = enc_lines[i]
                    if v["encoded"] is None:
                        refused += 1
                        if not line.startswith("{"):
                            problem = f"encode accepted values cantools refuses: {line}"
                    else:
                        encodes += 1
                        want = candump(dict(v, data=v["encoded"])).split(" ", 1)[1]
                        if line.startswith("{") or line.split(" ", 1)[1] != want:
                            problem = f"encode: want {want}, got {line}"
            if problem:
                mismatches += 1
                file_bad += 1
                if file_bad <= 3:
                    report_lines.append(f"MISMATCH {os.path.basename(f)} {v['name']} data={v['data']}: {problem}")
    for line in report_lines:
        print(line)
    for f, err in gen_failed:
        print(f"GENERATE FAILED {f}:\n{err}")
    for f in compile_failed:
        print(f"COMPILE FAILED {f}")
    for f, why in skipped:
        print(f"skipped (cantools strict refuses it) {os.path.basename(f)}: {why}")
    print(f"files: {len(files)} given, {len(loaded)} loaded strictly by cantools, "
          f"{len(generated)} generated, {len(generated) - len(compile_failed)} compiled")
    print(f"frames compared: {frames}, decoded bit-exact: {exact}, encodes compared: {encodes}, "
          f"refusals compared: {refused}, mismatches: {mismatches}")
    ok = not gen_failed and not compile_failed and mismatches == 0
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
