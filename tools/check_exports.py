#!/usr/bin/env python3
"""Reads a session export back with independent readers and compares it with the store.

Foxglove's `mcap` reader, `polars` (Parquet, CSV) and the standard library's `sqlite3` and
`csv`: row counts, column names and types, and every value must equal what the store holds
for the session; the session's metadata must be in every file.

usage: check_exports.py --store STORE --out EXPORT_DIR --types TYPES_JSON --session N
TYPES_JSON: {"table": [["stored", "exported", "U8"], ...], ...}, every table's local columns
(tags, then columns) as the store names them, as the exports name them, and the exported type.
The exports rename the time (`ts` -> `ts_us`) and the fingerprints (text `0x...`), and unwrap
the CCM's 32-bit clock (`timestamp_us`); every other value is the store's.
"""

import argparse
import csv
import json
import sqlite3
import struct
import sys
from importlib.metadata import version
from pathlib import Path

import polars as pl
from mcap.reader import make_reader
from xml.etree import ElementTree

POLARS = {
    "Timestamp": pl.Datetime("us", "UTC"),
    "Bool": pl.Boolean,
    "I8": pl.Int8,
    "I16": pl.Int16,
    "I32": pl.Int32,
    "I64": pl.Int64,
    "U8": pl.UInt8,
    "U16": pl.UInt16,
    "U32": pl.UInt32,
    "U64": pl.UInt64,
    "F32": pl.Float32,
    "F64": pl.Float64,
}

failures = []


def fail(message):
    failures.append(message)
    if len(failures) <= 20:
        print("MISMATCH:", message, file=sys.stderr)


def f32(x):
    return struct.unpack("f", struct.pack("f", x))[0]


def same(ty, stored, read, column=None):
    """True when `read` (from an export) is the stored value of a column of type `ty`
    (`column`: the store's name, for the columns the exports convert)."""
    if stored is None or read is None:
        return stored is None and read is None
    if column == "schema_fingerprint":
        return read == f"0x{int(stored):08x}"
    if column == "timestamp_us":
        return int(read) % (1 << 32) == int(stored) and int(read) >= int(stored)
    if ty == "Bool":
        return bool(stored) == bool(read)
    if ty == "F32":
        return f32(float(stored)) == f32(float(read))
    if ty == "F64":
        return float(stored) == float(read)
    if ty.startswith("VarChar"):
        return str(stored) == str(read)
    return int(stored) == int(read)


def store_rows(db, table, columns, session):
    rng = db.execute(
        "SELECT first_id, last_id FROM session_rows WHERE session_id = ? AND table_name = ?",
        (session, table),
    ).fetchone()
    if rng is None:
        return []
    names = ", ".join(f'"{stored}"' for stored, _, _ in columns)
    return db.execute(
        f'SELECT {names} FROM "{table}" WHERE id BETWEEN ? AND ? ORDER BY id', rng
    ).fetchall()


def check_parquet(path, table, columns, rows, meta):
    df = pl.read_parquet(path)
    if df.height != len(rows):
        fail(f"{path}: {df.height} rows, the store has {len(rows)}")
        return
    if df.columns != [name for _, name, _ in columns]:
        fail(f"{path}: columns {df.columns}")
        return
    for (_, name, ty), dtype in zip(columns, df.dtypes):
        want = pl.String if ty.startswith("VarChar") else POLARS[ty]
        if dtype != want:
            fail(f"{path}: column {name} is {dtype}, the exported type {ty} is {want}")
    for index, (stored, name, ty) in enumerate(columns):
        series = df.get_column(name)
        if ty == "Timestamp":
            series = series.dt.epoch("us")
        for row, value in zip(rows, series.to_list()):
            if not same(ty, row[index], value, stored):
                fail(f"{path}: {name} = {value!r}, stored {row[index]!r}")
                break
    kv = pl.read_parquet_metadata(path)
    # A Parquet reader alone can name every enum value: the value names are in the metadata.
    for stored, name, ty in columns:
        if kv.get(f"aer.label.{name}") is None:
            fail(f"{path}: no aer.label.{name} in the metadata")
    for key, value in meta.items():
        if kv.get(f"aer.{key}") != value:
            fail(f"{path}: metadata aer.{key} = {kv.get(f'aer.{key}')!r}, want {value!r}")


def check_csv(path, table, columns, rows):
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        lines = list(reader)
    if header != [name for _, name, _ in columns]:
        fail(f"{path}: header {header}")
        return
    if len(lines) != len(rows):
        fail(f"{path}: {len(lines)} rows, the store has {len(rows)}")
        return
    for line, row in zip(lines, rows):
        for index, (stored, name, ty) in enumerate(columns):
            cell = line[index]
            value = None if cell == "" else (cell == "true" if ty == "Bool" else cell)
            if not same(ty, row[index], value, stored):
                fail(f"{path}: {name} = {cell!r}, stored {row[index]!r}")
                return
    # polars reads the same file with its default settings (type inference from the first 100
    # rows), with the same shape and every float column as floats.
    df = pl.read_csv(path)
    if df.height != len(rows) or df.width != len(columns):
        fail(f"{path}: polars reads {df.shape}")
    for _, name, ty in columns:
        if ty in ("F32", "F64") and not df.schema[name].is_float():
            fail(f"{path}: polars reads {name} as {df.schema[name]}, not a float")


def check_mcap(path, types, db, session, meta):
    expected = {}
    for table, columns in types.items():
        rows = store_rows(db, table, columns, session)
        if rows:
            expected[table] = (columns, rows)
    seen = {}
    labels = {}
    metadata = {}
    last_time = 0
    with open(path, "rb") as f:
        reader = make_reader(f)
        for record in reader.iter_metadata():
            metadata[record.name] = dict(record.metadata)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            table = channel.metadata.get("table")
            if schema.encoding != "jsonschema" or channel.message_encoding != "json":
                fail(f"{path}: channel {channel.topic} is {schema.encoding}/{channel.message_encoding}")
            if table not in labels:
                properties = json.loads(schema.data)["properties"]
                labels[table] = {
                    name: {str(o["const"]): o["title"] for o in p.get("oneOf", [])}
                    for name, p in properties.items()
                }
                for _, name, ty in types.get(table, []):
                    if name not in properties or "title" not in properties[name]:
                        fail(f"{path}: {table} schema lacks a titled {name}")
            if message.log_time < last_time:
                fail(f"{path}: messages out of time order")
            last_time = message.log_time
            seen.setdefault(table, []).append((message.log_time, json.loads(message.data)))
    if metadata.get("session", {}) != {**metadata.get("session", {}), **meta}:
        fail(f"{path}: session metadata {metadata.get('session')}, want {meta}")
    if set(seen) != set(expected):
        fail(f"{path}: channels {sorted(seen)}, the store has {sorted(expected)}")
    for table, (columns, rows) in expected.items():
        messages = seen.get(table, [])
        if len(messages) != len(rows):
            fail(f"{path}: {table}: {len(messages)} messages, the store has {len(rows)}")
            continue
        ts = [stored for stored, _, _ in columns].index("ts")
        # Messages are in receive-time order; rows with one time keep their arrival order.
        ordered = sorted(range(len(rows)), key=lambda i: (rows[i][ts], i))
        for i, (log_time, data) in zip(ordered, messages):
            row = rows[i]
            if log_time != row[ts] * 1000:
                fail(f"{path}: {table} log_time {log_time}, stored ts {row[ts]} us")
                break
            for index, (stored, name, ty) in enumerate(columns):
                if not same(ty, row[index], data.get(name), stored):
                    fail(f"{path}: {table}.{name} = {data.get(name)!r}, stored {row[index]!r}")
                    break
                names = labels[table].get(name, {})
                if names and row[index] is not None:
                    want = names.get(str(row[index]))
                    if data.get(f"{name}_label") != want:
                        fail(f"{path}: {table}.{name}_label = {data.get(name + '_label')!r}, want {want!r}")
                        break
    return sum(len(v) for v in seen.values())


def check_layouts(out):
    """Foxglove's and PlotJuggler's layouts parse, and every series they draw is a field of a
    channel of the MCAP beside them (its topic, a property of its JSON Schema)."""
    fields = {}
    with open(out / "session.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            fields[channel.topic] = set(json.loads(schema.data)["properties"])
    series = []
    layout = json.load(open(out / "foxglove-layout.json"))
    for panel, config in layout["configById"].items():
        for path in config.get("paths", []):
            topic, _, field = path["value"].rpartition(".")
            series.append(("foxglove " + panel, topic, field))
    if layout.get("layout") not in layout["configById"]:
        fail(f"foxglove-layout.json: the root panel {layout.get('layout')!r} is not configured")
    root = ElementTree.parse(out / "plotjuggler-layout.xml").getroot()
    for curve in root.iter("curve"):
        topic, _, field = curve.get("name").rpartition("/")
        series.append(("plotjuggler", topic, field))
    if not series:
        fail("the layouts draw nothing")
    for where, topic, field in series:
        if field not in fields.get(topic, set()):
            fail(f"{where}: {topic} {field} is no field of a channel of session.mcap")
    return len(series)


CALIBRATION = ["ts_us", "master", "kind", "parameter", "element", "old", "new", "accepted", "reason", "checksum"]


def check_calibration(out, db, session):
    """The session's calibration record (`session_calibration`) in `calibration.parquet`,
    `calibration.csv` and the MCAP's `calibration` metadata records, entry for entry."""
    stored = db.execute(
        "SELECT at_us, master, kind, parameter, element, old, new, accepted, reason, checksum "
        "FROM session_calibration WHERE session_id = ? ORDER BY rowid",
        (session,),
    ).fetchall()
    parquet = out / "parquet" / "calibration.parquet"
    csv_path = out / "csv" / "calibration.csv"
    if not stored:
        if parquet.exists() or csv_path.exists():
            fail("calibration: exported, but the session has no record")
        return 0
    types = {"ts_us": "Timestamp", "element": "I32", "old": "F64", "new": "F64", "accepted": "Bool", "checksum": "U32"}
    frame = pl.read_parquet(parquet)
    # The exports add the parameter's unit from the schema.
    if frame.columns != CALIBRATION[:5] + ["unit"] + CALIBRATION[5:]:
        fail(f"{parquet}: columns {frame.columns}")
    for name, ty in types.items():
        if frame.schema.get(name) != POLARS[ty]:
            fail(f"{parquet}: {name} is {frame.schema.get(name)}, want {POLARS[ty]}")
    rows = frame.to_dicts()
    with open(csv_path, newline="") as f:
        text = list(csv.DictReader(f))
    with open(out / "session.mcap", "rb") as f:
        records = [dict(r.metadata) for r in make_reader(f).iter_metadata() if r.name == "calibration"]
    for source, got in (("parquet", len(rows)), ("csv", len(text)), ("mcap", len(records))):
        if got != len(stored):
            fail(f"calibration.{source}: {got} entries, the store has {len(stored)}")
    for i, entry in enumerate(stored):
        want = dict(zip(CALIBRATION, entry))
        want["accepted"] = bool(want["accepted"])
        read = rows[i] if i < len(rows) else {}
        read = {**read, "ts_us": int(read["ts_us"].timestamp() * 1_000_000) if read.get("ts_us") else None}
        for name in CALIBRATION:
            if name == "ts_us":
                if abs((read["ts_us"] or 0) - want["ts_us"]) > 1:
                    fail(f"calibration.parquet[{i}].ts_us = {read['ts_us']}, stored {want['ts_us']}")
            elif read.get(name) != want[name]:
                fail(f"calibration.parquet[{i}].{name} = {read.get(name)!r}, stored {want[name]!r}")
        line = text[i] if i < len(text) else {}
        for name in CALIBRATION:
            value = want[name]
            shown = "" if value is None else str(value).lower() if name == "accepted" else str(value)
            if name in ("old", "new") and value is not None:
                ok = line.get(name) not in (None, "") and float(line[name]) == value
            else:
                ok = line.get(name) == shown
            if not ok:
                fail(f"calibration.csv[{i}].{name} = {line.get(name)!r}, stored {value!r}")
        record = records[i] if i < len(records) else {}
        if record.get("ts_us") != str(want["ts_us"]) or record.get("parameter") != want["parameter"] \
                or record.get("accepted") != str(want["accepted"]).lower() or record.get("reason") != want["reason"]:
            fail(f"session.mcap calibration[{i}] = {record}, stored {want}")
    return len(stored)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--store", required=True)
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--types", required=True)
    parser.add_argument("--session", required=True, type=int)
    args = parser.parse_args()
    types = {t: [tuple(c) for c in cols] for t, cols in json.load(open(args.types)).items()}
    db = sqlite3.connect(args.store)
    s = db.execute(
        "SELECT driver, track, run, notes FROM sessions WHERE id = ?", (args.session,)
    ).fetchone()
    meta = {
        "session": str(args.session),
        "driver": s[0],
        "track": s[1],
        "run": "" if s[2] is None else str(s[2]),
        "notes": s[3],
    }
    tables = 0
    rows_total = 0
    for table, columns in types.items():
        rows = store_rows(db, table, columns, args.session)
        parquet = args.out / "parquet" / f"{table}.parquet"
        csv_path = args.out / "csv" / f"{table}.csv"
        if not rows:
            if parquet.exists() or csv_path.exists():
                fail(f"{table}: exported, but the session has no rows")
            continue
        tables += 1
        rows_total += len(rows)
        check_parquet(parquet, table, columns, rows, meta)
        check_csv(csv_path, table, columns, rows)
    session_csv = dict(csv.reader(open(args.out / "csv" / "session.csv")))
    for key, value in meta.items():
        if session_csv.get(key) != value:
            fail(f"session.csv: {key} = {session_csv.get(key)!r}, want {value!r}")
    messages = check_mcap(args.out / "session.mcap", types, db, args.session, meta)
    entries = check_calibration(args.out, db, args.session)
    series = check_layouts(args.out)
    if failures:
        print(f"{len(failures)} mismatch(es)", file=sys.stderr)
        sys.exit(1)
    print(
        f"exports match the store: {tables} tables, {rows_total} rows in Parquet and CSV, "
        f"{messages} MCAP messages, calibration record of {entries} entries, "
        f"{series} series of the Foxglove and PlotJuggler layouts on the MCAP's fields "
        f"(mcap {version('mcap')}, polars {pl.__version__})"
    )


if __name__ == "__main__":
    main()
