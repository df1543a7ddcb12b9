#!/usr/bin/env python3
"""Reads an export's bus-logging files back with independent readers and compares every frame
with the log the export was made from.

python-can reads the reference (candump -l text) and the BLF and ASC files; asammdf reads the
MF4 file's frames and, given the DBC, extracts signals that must equal the export's decoded
rows (its Parquet files). Each frame is compared by receive time (to the microsecond), bus,
identifier, extended flag and data.

usage: check_frame_exports.py --reference LOG --channels 1=can0,2=can1 --dir EXPORT_DIR
                              [--dbc schema/aer.dbc --messages MESSAGES_JSON]
MESSAGES_JSON: {"CCM_Status": {"table": "can_ccm_status", "signals": {"CCM_VehicleState":
"ccm_vehicle_state", ...}}, ...}: each DBC message's table and columns in the export.
"""

import argparse
import json
import os
import sys
from pathlib import Path

# The exports' times are UTC; python-can reads ASC header dates as local time.
os.environ["TZ"] = "UTC"
import datetime  # noqa: E402
import time  # noqa: E402

time.tzset()

import can  # noqa: E402
import polars as pl  # noqa: E402
from asammdf import MDF  # noqa: E402

EPOCH = datetime.datetime(1970, 1, 1, tzinfo=datetime.timezone.utc)

failures = []


def fail(message):
    failures.append(message)
    if len(failures) <= 20:
        print("MISMATCH:", message, file=sys.stderr)


def key(message, bus):
    return (
        round(message.timestamp * 1e6),
        bus,
        message.arbitration_id,
        message.is_extended_id,
        bytes(message.data),
    )


def reference_frames(path):
    return [key(m, m.channel) for m in can.CanutilsLogReader(path)]


def compare(name, frames, reference):
    if len(frames) != len(reference):
        fail(f"{name}: {len(frames)} frames, the log has {len(reference)}")
    for index, (got, want) in enumerate(zip(frames, reference)):
        if got != want:
            fail(f"{name}: frame {index} is {got}, the log has {want}")
            break
    else:
        if len(frames) == len(reference):
            print(f"{name}: {len(frames)} frames equal to the log")


def check_vector(directory, reference, bus_of_channel):
    blf = [
        key(m, bus_of_channel.get(m.channel + 1))
        for m in can.BLFReader(directory / "session.blf")
    ]
    compare("session.blf (python-can BLFReader)", blf, reference)
    asc = [
        key(m, bus_of_channel.get(m.channel + 1))
        for m in can.ASCReader(directory / "session.asc", relative_timestamp=False)
    ]
    compare("session.asc (python-can ASCReader)", asc, reference)


def start_us(mdf):
    """The MF4 header's start as microseconds since the epoch."""
    return (mdf.header.start_time - EPOCH) // datetime.timedelta(microseconds=1)


def check_mf4_frames(directory, reference, bus_of_channel):
    mdf = MDF(directory / "session.mf4")
    start = start_us(mdf)
    ids = mdf.get("CAN_DataFrame.ID")
    buses = mdf.get("CAN_DataFrame.BusChannel").samples
    ide = mdf.get("CAN_DataFrame.IDE").samples
    length = mdf.get("CAN_DataFrame.DataLength").samples
    data = mdf.get("CAN_DataFrame.DataBytes").samples
    frames = [
        (
            start + round(float(t) * 1e6),
            bus_of_channel.get(int(bus)),
            int(raw) & 0x1FFFFFFF,
            bool(extended),
            bytes(payload[:n].tolist()),
        )
        for t, raw, bus, extended, n, payload in zip(
            ids.timestamps, ids.samples, buses, ide, length, data
        )
    ]
    compare("session.mf4 (asammdf)", frames, reference)


def check_mf4_signals(directory, dbc, messages, bus_of_channel):
    """asammdf decodes the MF4's frames with the DBC; every signal of every message must
    equal the export's decoded rows (Parquet), frame by frame."""
    mdf = MDF(directory / "session.mf4")
    start = start_us(mdf)
    decoded = mdf.extract_bus_logging({"CAN": [(dbc, 0)]})
    signals = 0
    groups = 0
    for index, group in enumerate(decoded.groups):
        # "CAN1 - message CCM_Status 0xA0 EXT=False"
        words = group.channel_group.comment.split()
        bus = bus_of_channel.get(int(words[0].removeprefix("CAN")))
        name = words[3]
        wanted = messages.get(name)
        if wanted is None:
            fail(f"session.mf4: asammdf decoded {name}, which the export has no table for")
            continue
        table = pl.read_parquet(directory / "parquet" / f"{wanted['table']}.parquet")
        rows = table.filter(pl.col("bus") == bus)
        times = rows.get_column("ts_us").dt.epoch("us").to_list()
        groups += 1
        for channel in group.channels:
            if channel.name not in wanted["signals"]:
                continue
            signal = decoded.get(channel.name, group=index)
            if signal.samples.dtype.kind in "SUO":
                # A signal with named values comes back as its names; the export keeps the
                # numbers, which are the raw values.
                signal = decoded.get(channel.name, group=index, raw=True)
            column = wanted["signals"][channel.name]
            ours = rows.get_column(column).to_list()
            if len(signal.samples) != len(ours):
                fail(f"{name}.{channel.name} on {bus}: asammdf {len(signal.samples)} values, the export {len(ours)}")
                continue
            for t, theirs, mine, at in zip(signal.timestamps, signal.samples, ours, times):
                if start + round(float(t) * 1e6) != at:
                    fail(f"{name}.{channel.name} on {bus}: at {t} s, the export's row is at {at} us")
                    break
                if mine is None or not close(float(theirs), float(mine)):
                    fail(f"{name}.{channel.name} on {bus}: asammdf {theirs}, the export {mine}")
                    break
            signals += 1
    if groups == 0:
        fail("session.mf4: asammdf decoded no message with the DBC")
    print(f"session.mf4 (asammdf with the DBC): {signals} signals of {groups} messages equal to the export")


def close(a, b):
    """Equal as the export stores it: 32-bit floats keep about 7 digits."""
    return a == b or abs(a - b) <= 1e-6 * max(abs(a), abs(b))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--reference", required=True)
    parser.add_argument("--channels", required=True)
    parser.add_argument("--dir", required=True, type=Path)
    parser.add_argument("--dbc")
    parser.add_argument("--messages")
    args = parser.parse_args()
    bus_of_channel = {}
    for pair in args.channels.split(","):
        channel, bus = pair.split("=")
        bus_of_channel[int(channel)] = bus
    reference = reference_frames(args.reference)
    check_vector(args.dir, reference, bus_of_channel)
    check_mf4_frames(args.dir, reference, bus_of_channel)
    if args.dbc and args.messages:
        messages = json.loads(Path(args.messages).read_text())
        check_mf4_signals(args.dir, args.dbc, messages, bus_of_channel)
    if failures:
        print(f"{len(failures)} mismatches", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
