#!/usr/bin/env python3
"""Test vectors from cantools, the reference DBC implementation.

For every message of each DBC file: random raw values (respecting multiplexing, biased towards
the edges of each signal's range) are encoded by cantools; cantools decodes the frame back to
physical values (choices not decoded) and re-encodes those physical values in strict mode. Each
vector is one JSON line:

    {"name": ..., "id": ..., "extended": ..., "data": "hex",
     "signals": {name: number or null}, "encoded": "hex" or null}

`encoded` is null when cantools' strict encoder refuses the values (out of range), so the
generated encoder must refuse them too. NaN and infinities become null (JSON has neither).
Rounding ties cannot occur: physical values come from whole raw values.

With --candump LOG, the vectors are instead every distinct frame of a recorded candump log
(`(time) bus ID#DATA`) whose message name starts with --prefix, decoded and re-encoded the same
way: the frames a real session carries, written to DIR/<log>_<prefix>.jsonl.

Usage: cantools_vectors.py [--frames N] [--seed S] --out DIR FILE.dbc...
       cantools_vectors.py --candump LOG [--prefix P] --out DIR FILE.dbc
"""

import argparse
import json
import math
import os
import random
import struct

import cantools


def raw_value(rng, sig):
    """A random raw value for a signal, biased to the edges where codecs break."""
    if sig.is_float:
        while True:
            if sig.length == 32:
                v = struct.unpack("<f", struct.pack("<I", rng.getrandbits(32)))[0]
            else:
                v = struct.unpack("<d", struct.pack("<Q", rng.getrandbits(64)))[0]
            pick = rng.random()
            if pick < 0.1:
                v = 0.0
            elif pick < 0.2:
                v = rng.uniform(-1000.0, 1000.0)
            if math.isfinite(v):
                return v
    if sig.is_signed:
        lo, hi = -(1 << (sig.length - 1)), (1 << (sig.length - 1)) - 1
    else:
        lo, hi = 0, (1 << sig.length) - 1
    choices = sig.choices or {}
    pick = rng.random()
    if choices and pick < 0.4:
        return int(rng.choice(list(choices.keys())))
    if pick < 0.5:
        return rng.choice([lo, hi, 0, min(hi, 1), max(lo, -1)])
    return rng.randint(lo, hi)


def active_raw_values(rng, msg):
    """Raw values for the signals present in one frame, choosing multiplexor values that select
    something most of the time."""
    by_name = {s.name: s for s in msg.signals}
    children = {}
    for s in msg.signals:
        if s.multiplexer_signal is not None:
            children.setdefault(s.multiplexer_signal, []).append(s)
    raw = {}
    pending = [s for s in msg.signals if s.multiplexer_signal is None]
    while pending:
        sig = pending.pop(0)
        if sig.is_multiplexer:
            ids = sorted({i for c in children.get(sig.name, []) for i in (c.multiplexer_ids or [])})
            if ids and rng.random() < 0.9:
                raw[sig.name] = rng.choice(ids)
            else:
                raw[sig.name] = raw_value(rng, sig)
            for c in children.get(sig.name, []):
                if raw[sig.name] in (c.multiplexer_ids or []):
                    pending.append(c)
        else:
            raw[sig.name] = raw_value(rng, sig)
    return {k: v for k, v in raw.items() if k in by_name}


SKIPPED = [0]


def number(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def vector(msg, data):
    """The vector for one frame, or None when cantools cannot decode it."""
    try:
        phys = msg.decode(data, decode_choices=False, scaling=True)
    except Exception:
        # cantools refuses frames whose multiplexor selects no signal; the generated codec
        # decodes them (multiplexed fields absent). Not comparable: skip.
        SKIPPED[0] += 1
        return None
    try:
        encoded = msg.encode(phys, scaling=True, strict=True, padding=False).hex()
    except Exception:
        encoded = None
    return {
        "name": msg.name,
        "id": msg.frame_id,
        "extended": msg.is_extended_frame,
        "data": data.hex(),
        "signals": {k: number(v) for k, v in phys.items()},
        "encoded": encoded,
    }


def vectors_for(db, rng, frames):
    for msg in db.messages:
        for _ in range(frames):
            raw = active_raw_values(rng, msg)
            try:
                data = msg.encode(raw, scaling=False, strict=False, padding=False)
            except Exception:
                SKIPPED[0] += 1
                continue
            v = vector(msg, data)
            if v is not None:
                yield v


def vectors_from_log(db, log, prefix):
    """Every distinct frame of a candump log of a message named `prefix...`, in log order."""
    by_id = {(m.is_extended_frame, m.frame_id): m for m in db.messages}
    seen = set()
    with open(log) as f:
        for line in f:
            parts = line.split()
            if len(parts) < 3 or "#" not in parts[2]:
                continue
            text_id, text_data = parts[2].split("#", 1)
            key = (len(text_id) == 8, int(text_id, 16), text_data.lower())
            msg = by_id.get(key[:2])
            if key in seen or msg is None or not msg.name.startswith(prefix):
                continue
            seen.add(key)
            v = vector(msg, bytes.fromhex(text_data))
            if v is not None:
                yield v


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument("--frames", type=int, default=200, help="frames per message")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--candump", help="vectors from this candump log's frames instead")
    ap.add_argument("--prefix", default="", help="with --candump: message names to keep")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    if args.candump:
        if len(args.files) != 1:
            ap.error("--candump takes one DBC file")
        db = cantools.database.load_file(args.files[0], strict=True)
        stem = os.path.splitext(os.path.basename(args.candump))[0]
        suffix = "_" + args.prefix.rstrip("_").lower() if args.prefix else ""
        out = os.path.join(args.out, stem + suffix + ".jsonl")
        with open(out, "w") as f:
            n = 0
            for v in vectors_from_log(db, args.candump, args.prefix):
                f.write(json.dumps(v, allow_nan=False) + "\n")
                n += 1
        print(f"{args.candump}: {n} distinct frames -> {out} ({SKIPPED[0]} cantools cannot decode skipped)")
        return
    for path in args.files:
        stem = os.path.splitext(os.path.basename(path))[0]
        db = cantools.database.load_file(path, strict=True)
        rng = random.Random(f"{args.seed}:{stem}")
        out = os.path.join(args.out, stem + ".jsonl")
        with open(out, "w") as f:
            n = 0
            for v in vectors_for(db, rng, args.frames):
                f.write(json.dumps(v, allow_nan=False) + "\n")
                n += 1
        print(f"{path}: {n} vectors -> {out} ({SKIPPED[0]} frames cantools cannot decode skipped)")
        SKIPPED[0] = 0


if __name__ == "__main__":
    main()
