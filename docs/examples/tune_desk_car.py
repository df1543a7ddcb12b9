#!/usr/bin/env python3
"""A tuner's first pyxcp session with the CCM (docs/calibration.md, "A first session"): connect,
ask for the communication modes (pyxcp's block writes need them), unlock through the team's
seed-and-key library, read a parameter, try a value its limits refuse and print why the CCM
refused it, write an allowed value and read it back, then print what the slave counted.

    .venv/bin/python docs/examples/tune_desk_car.py --library target/release/libaer_xcp_seedkey.so

The desk car (`cargo run -p aer-car-node -- serve --secret-file ccm/xcp-secret.key`) serves at
the A2L's 127.0.0.1:5555; the secret must also lie beside the library as
`aer-xcp-secret.key` (or in the file AER_XCP_SECRET_FILE names). On the car, give `--can can0`
(the vehicle bus, through a SocketCAN adapter) instead. Addresses and names come from the A2L.
"""

import argparse
import logging
import re
import struct
import sys

from pyxcp.config import create_application_from_config
from pyxcp.master import Master
from pyxcp.types import XcpResponseError


def a2l_tables(path):
    """The A2L's parameter addresses and limits, the slave's status block address, and the
    value tables that name its codes."""
    text = open(path, encoding="utf-8").read()
    parameters = {}
    for match in re.finditer(
        r"/begin CHARACTERISTIC calibration\.(\w+) .*?\n\s+(\w+) (0x[0-9A-F]+) \S+ \S+ \S+ (\S+) (\S+)",
        text,
    ):
        name, kind, address, low, high = match.groups()
        parameters[name] = (int(address, 16), float(low), float(high))
    tables = {}
    for match in re.finditer(r"/begin COMPU_VTAB vtab\.xcp\.(\w+) .*?\n(.*?)/end COMPU_VTAB", text, re.S):
        tables[match.group(1)] = {int(raw): name for raw, name in re.findall(r'(\d+) "([^"]*)"', match.group(2))}
    status = int(re.search(r"MEMORY_SEGMENT xcp .*?\n\s+VARIABLES RAM INTERN (0x[0-9A-F]+)", text).group(1), 16)
    return parameters, tables, status


def read(master, address, length):
    """`length` bytes at `address` (SET_MTA, then UPLOADs)."""
    master.setMta(address, 0)
    return bytes(master.fetch(length))


def why(master, tables, status):
    """The slave's last refusal, from its status block (the A2L's xcp.refused_* measurements:
    count, command, error, reason, element, item, 2 spare bytes, value, limit)."""
    _count, command, error, reason, element, item, value, limit = struct.unpack(
        "<IBBBBH2xff", read(master, status, 20)
    )
    return (
        f"{tables['command'].get(command, command)} refused with {tables['error'].get(error, error)}: "
        f"{tables['item'].get(item, item)}[{element}] = {value:g}, {tables['reason'].get(reason, reason)} "
        f"(limit {limit:g})"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--library", required=True, help="the seed-and-key library (libaer_xcp_seedkey.so)")
    parser.add_argument("--a2l", default="generated/aer.a2l")
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=5555)
    parser.add_argument("--can", metavar="INTERFACE", help="XCP on CAN on this SocketCAN interface instead of TCP")
    args = parser.parse_args()
    parameters, tables, status = a2l_tables(args.a2l)

    if args.can:
        layer, transport = "can", {"CAN": {"interface": "socketcan", "channel": args.can, "can_id_master": 0x6F0,
                                           "can_id_slave": 0x6F1, "bitrate": 500000, "max_dlc_required": True}}
    else:
        layer, transport = "eth", {"Eth": {"host": args.host, "port": args.port, "protocol": "TCP"}}
    # Refusals reach this script as XcpResponseError with their code: pyxcp's default error
    # handling would retry some of them and turn others into a SystemExit.
    general = {"disable_error_handling": True, "seed_n_key_dll": args.library}
    app = create_application_from_config({"Transport": transport, "General": general}, log_level=logging.WARNING)
    with Master(layer, config=app) as master:
        try:
            master.connect()
        except XcpResponseError as error:
            print(f"connecting failed ({error}): another tool may hold the slave; close its session and retry",
                  file=sys.stderr)
            return 1
        # pyxcp's push() (block writes) needs MAX_BS from GET_COMM_MODE_INFO.
        info = master.getCommModeInfo()
        print(f"connected: MAX_CTO {master.slaveProperties.maxCto}, MAX_BS {info.maxBs}")
        try:
            master.cond_unlock("calpag")
        except XcpResponseError as error:
            print(
                f"unlocking failed ({error}): check that the library has the car's secret beside it "
                "(aer-xcp-secret.key) or in AER_XCP_SECRET_FILE; after a wrong key, wait the delay "
                "(docs/calibration.md, \"Unlocking\") and run this again",
                file=sys.stderr,
            )
            return 1
        print("calibration unlocked")

        address, low, high = parameters["traction_kp"]
        value = struct.unpack("<f", bytes(master.shortUpload(4, address, 0)))[0]
        print(f"traction_kp = {value:g} (limits {low:g} to {high:g})")
        try:
            master.push(address, 0, struct.pack("<f", high + 1.0))
            print("ERROR: a value above the maximum was accepted", file=sys.stderr)
            return 1
        except XcpResponseError as error:
            print(f"refused as expected: {why(master, tables, status)} ({error.get_error_code()})")
        new = min(high, value + 10.0)
        master.push(address, 0, struct.pack("<f", new))
        back = struct.unpack("<f", bytes(master.shortUpload(4, address, 0)))[0]
        print(f"traction_kp = {back:g} now")
        counters = struct.unpack("<8I", read(master, status + 20, 32))
        names = ["commands", "errors", "dtos_sent", "dtos_dropped", "overloads", "daq_faults", "idle_ends", "wrong_keys"]
        print("slave counters: " + ", ".join(f"{n} {c}" for n, c in zip(names, counters)))
        master.disconnect()
    return 0 if back == struct.unpack("<f", struct.pack("<f", new))[0] else 1


if __name__ == "__main__":
    sys.exit(main())
