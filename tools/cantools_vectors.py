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

Usage: cantools_vectors.py [--frames N] [--seed S] --out DIR FILE.dbc...
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


def vectors_for(db, rng, frames):
    for msg in db.messages:
        for _ in range(frames):
            raw = active_raw_values(rng, msg)
            try:
                data = msg.encode(raw, scaling=False, strict=False, padding=False)
                phys = msg.decode(data, decode_choices=False, scaling=True)
            except Exception:
                # cantools refuses frames whose multiplexor selects no signal; the generated
                # codec decodes them (multiplexed fields absent). Not comparable: skip.
                SKIPPED[0] += 1
                continue
            try:
                encoded = msg.encode(phys, scaling=True, strict=True, padding=False).hex()
            except Exception:
                encoded = None
            yield {
                "name": msg.name,
                "id": msg.frame_id,
                "extended": msg.is_extended_frame,
                "data": data.hex(),
                "signals": {k: number(v) for k, v in phys.items()},
                "encoded": encoded,
            }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument("--frames", type=int, default=200, help="frames per message")
    ap.add_argument("--seed", type=int, default=2026)
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
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
