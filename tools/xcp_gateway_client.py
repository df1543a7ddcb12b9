#!/usr/bin/env python3
"""A pit's calibration tool on the Pi's XCP gateway, played with pyxcp over XCP on TCP (the
virtual Pi runs it in the pit's network namespace, tools/virtual_pi/scenarios.py).

usage: xcp_gateway_client.py HOST PORT SECRET_HEX ACTION
ACTION:
  read       connect, print the working page's first 16 bytes (launch_slip_target) as hex
  cut        connect, unlock, set the MTA, send the first packet of a 16-byte block download
             and kill itself with SIGKILL before the rest (a tuner's laptop dying mid-write)
Everything pyxcp logs goes to stderr; stdout carries the result only.
"""

import hashlib
import hmac
import logging
import os
import signal
import struct
import sys

from pyxcp import types
from pyxcp.config import create_application_from_config
from pyxcp.master import Master

CALIBRATION_ADDRESS = 0x10000
KEY_LEN = 16


def master(host, port, secret):
    def seed_and_key(resource, seed):
        return hmac.new(secret, bytes(seed), hashlib.sha256).digest()[:KEY_LEN]

    app = create_application_from_config(
        {
            "Transport": {"Eth": {"host": host, "port": port, "protocol": "TCP", "tcp_nodelay": True}},
            "General": {"disable_error_handling": True, "seed_n_key_function": seed_and_key},
        },
        log_level=logging.WARNING,
    )
    app.transport.timeout = 5.0
    xcp = Master("eth", config=app)
    xcp.transport.connect()
    xcp.connect()
    return xcp


def main():
    host, port, secret, action = sys.argv[1], int(sys.argv[2]), bytes.fromhex(sys.argv[3]), sys.argv[4]
    sys.stdout = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    xcp = master(host, port, secret)
    if action == "read":
        data = b"".join(bytes(xcp.shortUpload(4, CALIBRATION_ADDRESS + at, 0)) for at in range(0, 16, 4))
        print(data.hex(), flush=True)
        xcp.disconnect()
        xcp.close()
        return 0
    if action == "cut":
        xcp.cond_unlock("calpag")
        xcp.setMta(CALIBRATION_ADDRESS)
        # The first packet of a master-block download of 16 bytes (0.2 as the first f32), as
        # pyxcp sends it: the slave waits for DOWNLOAD_NEXT, which never comes.
        first = struct.pack("<f", 0.2) + b"\x00\x00"
        xcp.transport.block_request(types.Command.DOWNLOAD, 16, *first)
        print("sent the first of three download packets", flush=True)
        os.kill(os.getpid(), signal.SIGKILL)
    print(f"unknown action {action}", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
