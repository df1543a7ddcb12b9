#!/usr/bin/env python3
"""The calibration engineer's scenarios, played with the real pyxcp master against the CCM's
XCP slave in the closed-loop car model: XCP on TCP (the host's tests) or XCP on CAN through
python-can's socketcan interface (a vcan in the virtual Pi).

Run by `aer-car-node scenarios` (car-node/src/scenarios.rs), which drives the car. The two talk over this script's
stdin and stdout, one JSON object per line: the script writes a request, the harness answers
with exactly one line (`{"ok": true, ...}` or `{"ok": false, "error": ...}`). Requests:
start_up, drive_until_moving, drive {ms}, restart, corrupt, result {name, value}, done. While
a request is outstanding the harness reads no XCP commands, so none are sent then.

Environment: AER_XCP_TRANSPORT (tcp: AER_XCP_HOST, AER_XCP_PORT, and AER_XCP_PADDED=1 through
the Pi's gateway, whose packets are the slave's CAN frames; can: AER_XCP_CAN_CHANNEL,
AER_XCP_CAN_ID_MASTER, AER_XCP_CAN_ID_SLAVE, AER_XCP_CAN_BIT_RATE), AER_XCP_SECRET (32 bytes, hex: the key is the first 16 bytes of
HMAC-SHA256(secret, seed)), AER_XCP_EXPECTED (JSON written by the harness: EPK, A2L path,
addresses, parameters, internals).

Every diagnostic goes to stderr: stdout carries the protocol only, so the file descriptor the
harness reads is kept private and everything else written to "stdout" (pyxcp's rich logging,
the A2L parser) is sent to stderr. Exits 0 after `done`, non-zero on anything unexpected.

With `--seed-key-library PATH` the script plays one scenario instead, and asks the harness
nothing: pyxcp unlocks calibration by itself through the team's seed-and-key library
(xcp-seedkey/, the .so built for Linux) named in its `seed_n_key_dll` option, which reads the
secret beside itself or from AER_XCP_SECRET_FILE (AER_XCP_SECRET is not used). By default
pyxcp runs the library in its `asamkeydll` helper program; `--same-bit-width` sets
`seed_n_key_dll_same_bit_width`, and pyxcp loads it into Python with ctypes. The script writes
traction_kp while locked, unlocks, writes it again, reads it back, and prints one JSON object
on stdout: locked_before, locked_write (the refusal's error code), unlock_error (null, or what
pyxcp raised), unlocked, value, write (null when accepted), read_back. Run by
car-node/tests/pyxcp.rs against the desk server (`aer-car-node serve`).
"""

import os
import sys

# Keep the protocol channel private before any library can print to it.
_PROTOCOL_OUT = os.fdopen(os.dup(1), "w", encoding="utf-8")
os.dup2(2, 1)
sys.stdout = sys.stderr

import argparse  # noqa: E402
import hashlib  # noqa: E402
import hmac  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import re  # noqa: E402
import shutil  # noqa: E402
import struct  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import traceback  # noqa: E402

from pyxcp import types  # noqa: E402
from pyxcp.config import create_application_from_config  # noqa: E402
from pyxcp.master import Master  # noqa: E402
from pyxcp.transport.transport_ext import FrameCategory  # noqa: E402

# XCP numbers used here (ASAM MCD-1 XCP part 2).
RESOURCE_CAL_PAG = 0x01
GET_ID_EPK = 5
STORE_CAL_REQ = 0x01
PAGE_MODE_ECU = 0x01
DAQ_MODE_TIMESTAMP = 0x10
DAQ_LIST_STOP, DAQ_LIST_START, DAQ_LIST_SELECT = 0, 1, 2
SYNCH_STOP_ALL, SYNCH_START_SELECTED = 0, 1
BIT_OFFSET_NONE = 0xFF
EVENT_CONTROL = 0
DTO_TIMESTAMP_LEN = 4
MAX_ODT_ENTRY_SIZE = 4  # the slave's (GET_DAQ_RESOLUTION_INFO checks it below)

KEY_LEN = 16
CAN_DLC = 8


class Failure(Exception):
    """Something the scenarios did not expect: the script stops with this message."""


def log(message):
    print(f"xcp_scenarios: {message}", file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------------------------
# The harness protocol.


def ask(request):
    """Sends one request line and returns the harness's answer (only if it says ok)."""
    _PROTOCOL_OUT.write(json.dumps(request) + "\n")
    _PROTOCOL_OUT.flush()
    line = sys.stdin.readline()
    if not line:
        raise Failure(f"the harness closed stdin instead of answering {request!r}")
    try:
        answer = json.loads(line)
    except json.JSONDecodeError as error:
        raise Failure(f"unreadable answer to {request!r}: {line!r} ({error})") from None
    if not isinstance(answer, dict) or answer.get("ok") is not True:
        raise Failure(f"the harness refused {request!r}: {answer!r}")
    return answer


def result(name, value):
    log(f"result {name} = {json.dumps(value)}")
    ask({"cmd": "result", "name": name, "value": value})


# ---------------------------------------------------------------------------------------------
# Values and checksums.


def f32s(data):
    """Little-endian f32 elements as Python floats (each exactly the f32's value)."""
    return [value for (value,) in struct.iter_unpack("<f", bytes(data))]


def f32_bytes(values):
    return b"".join(struct.pack("<f", value) for value in values)


def as_f32(value):
    return struct.unpack("<f", struct.pack("<f", value))[0]


def crc16_ccitt(data):
    """CRC-16 CCITT: polynomial 0x1021, initial 0xFFFF, no reflection, no final XOR."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def key_for(secret, seed):
    return hmac.new(secret, bytes(seed), hashlib.sha256).digest()[:KEY_LEN]


def error_code(error):
    """The numeric ERR_* code of an XCP error packet pyxcp raised."""
    code = error.get_error_code()
    try:
        return int(code)
    except (TypeError, ValueError):
        return int(types.XcpError.encmapping[str(code)])


def a2l_epk(path):
    """The A2L's EPK through pya2ldb (an independent parser), else from its `EPK "..."` line."""
    try:
        import pya2l
        from pya2l import model

        workdir = tempfile.mkdtemp(prefix="xcp_scenarios")
        try:
            copy = os.path.join(workdir, "aer.a2l")
            shutil.copyfile(path, copy)
            session = pya2l.import_a2l(copy, in_memory=True, progress_bar=False, loglevel="ERROR", encoding="utf-8")
            mod_par = session.query(model.ModPar).one()
            if mod_par.epk is not None:
                return mod_par.epk.identifier
        finally:
            shutil.rmtree(workdir, ignore_errors=True)
    except Exception as error:  # noqa: BLE001 - the regex below is the documented fallback
        log(f"pya2ldb could not read the A2L ({error!r}); reading its EPK line instead")
    with open(path, encoding="utf-8") as a2l:
        match = re.search(r'^\s*EPK\s+"([^"]*)"', a2l.read(), re.MULTILINE)
    if match is None:
        raise Failure(f"no EPK in {path}")
    return match.group(1)


# ---------------------------------------------------------------------------------------------
# DAQ packets as pyxcp hands them over.


class DtoCollector:
    """A frame acquisition policy for pyxcp's transport: the transport calls `feed` from its
    listener thread with every frame it sees (commands, responses, errors, DTOs). The DTOs
    (FrameCategory.DAQ: the packet from its PID on, framing header removed) are kept in
    arrival order with the transport counter they came with."""

    def __init__(self):
        self._lock = threading.Lock()
        self._dtos = []
        self.xcp_master = None  # pyxcp sets this on every policy

    def feed(self, category, counter, timestamp, payload):
        if category == FrameCategory.DAQ:
            with self._lock:
                self._dtos.append((int(counter), bytes(payload)))

    def finalize(self):
        pass

    def take(self):
        with self._lock:
            dtos, self._dtos = self._dtos, []
        return dtos


# ---------------------------------------------------------------------------------------------
# One XCP session with the slave.


class Session:
    """A pyxcp Master connected to the slave, with the few operations the scenarios use."""

    def __init__(self, app, expected, layer):
        self.expected = expected
        self.dtos = DtoCollector()
        # The harness listens before the script starts and again before it answers `restart`:
        # the connection is accepted from the listen queue, so one attempt is enough.
        self.master = Master(layer, config=app, policy=self.dtos)
        self.master.transport.connect()
        response = self.master.connect()
        props = self.master.slaveProperties
        log(
            f"CONNECT: resources {response.resource}, MAX_CTO {props.maxCto}, MAX_DTO {props.maxDto}, "
            f"byte order {props.byteOrder}"
        )
        if props.optionalCommMode:
            info = self.master.getCommModeInfo()
            log(f"GET_COMM_MODE_INFO: master block mode {info.commModeOptional.masterBlockMode}, MAX_BS {info.maxBs}")
        if not props.get("masterBlockMode"):
            raise Failure("the slave does not offer master block mode: a multi-element write would not be one block")

    def close(self):
        if self.master is None:
            return
        try:
            self.master.disconnect()
        finally:
            self.master.close()
            self.master = None

    # Memory.

    def read(self, address, length):
        """`length` bytes at `address`: SHORT_UPLOAD when it fits one response, else SET_MTA
        and UPLOADs (pyxcp's fetch)."""
        if length <= self.master.slaveProperties.maxCto - 1:
            return bytes(self.master.shortUpload(length, address, 0))
        self.master.setMta(address, 0)
        return bytes(self.master.fetch(length))

    def write(self, address, data):
        """SET_MTA and one master-block-mode DOWNLOAD sequence (pyxcp's push): the slave
        gets the bytes as one block. Returns None, or the XCP error code of a refusal."""
        try:
            self.master.push(address, 0, bytes(data))
        except types.XcpResponseError as error:
            return error_code(error)
        return None

    def parameter(self, name):
        for parameter in self.expected["parameters"]:
            if parameter["name"] == name:
                return parameter
        raise Failure(f"no parameter {name!r} in the expected description")

    def read_parameter(self, name):
        parameter = self.parameter(name)
        return f32s(self.read(parameter["address"], 4 * parameter["count"]))

    def write_parameter(self, name, values):
        parameter = self.parameter(name)
        if len(values) != parameter["count"]:
            raise Failure(f"{name} has {parameter['count']} elements, not {len(values)}")
        return self.write(parameter["address"], f32_bytes(values))

    # Seed and key.

    def protection_locked(self):
        return bool(self.master.getStatus().resourceProtectionStatus.calpag)

    def unlock(self):
        """GET_SEED and UNLOCK through pyxcp's helper (cond_unlock) with our key function;
        True if the slave then reports calibration unlocked."""
        self.master.cond_unlock("calpag")
        return not self.protection_locked()


def seed_and_key(secret):
    def compute(resource, seed):
        if resource != RESOURCE_CAL_PAG:
            raise Failure(f"asked for the key of resource {resource:#x}")
        if len(seed) != 6:
            raise Failure(f"seed of {len(seed)} bytes: {bytes(seed).hex()}")
        return key_for(secret, seed)

    return compute


# ---------------------------------------------------------------------------------------------
# Unlocking through the seed-and-key library (--seed-key-library).


def unlock_with_library(app, expected, layer):
    """pyxcp unlocks by itself, with the library its configuration names: a write refused while
    locked, cond_unlock (GET_SEED, the library's key, UNLOCK), the same write accepted and read
    back. Returns what happened; a failed unlock is reported, not raised."""
    session = Session(app, expected, layer)
    try:
        # traction_kp may change at any time (even driving): only the lock can refuse it.
        kp = session.parameter("traction_kp")
        value = as_f32((kp["defaults"][0] + kp["max"]) / 2)
        outcome = {
            "locked_before": session.protection_locked(),
            "locked_write": session.write_parameter("traction_kp", [value]),
            "unlock_error": None,
        }
        try:
            session.master.cond_unlock("calpag")
        except Exception as error:  # noqa: BLE001 - the harness judges it; say what it was
            outcome["unlock_error"] = f"{type(error).__name__}: {error}"
            log(f"unlocking through the library failed: {outcome['unlock_error']}")
        # A wrong key ends the session: the slave answers nothing more then.
        outcome["unlocked"] = outcome["unlock_error"] is None and not session.protection_locked()
        outcome["value"] = value
        outcome["write"] = None
        outcome["read_back"] = None
        if outcome["unlocked"]:
            outcome["write"] = session.write_parameter("traction_kp", [value])
            outcome["read_back"] = session.read_parameter("traction_kp")[0]
    finally:
        try:
            session.close()
        except Exception as error:  # noqa: BLE001 - after a wrong key no DISCONNECT is answered
            log(f"closing the session: {error!r}")
    return outcome


# ---------------------------------------------------------------------------------------------
# DAQ.


def pack_odts(entries, timestamp):
    """Entries (name, address, size) packed in order into ODTs of MAX_DTO-1 data bytes (the
    first one less the timestamp)."""
    odts, current, room = [], [], 7 - (DTO_TIMESTAMP_LEN if timestamp else 0)
    for entry in entries:
        size = entry[2]
        if size > MAX_ODT_ENTRY_SIZE:
            raise Failure(f"entry {entry[0]} of {size} bytes exceeds the slave's ODT entry size")
        if size > room:
            odts.append(current)
            current, room = [], 7
        current.append(entry)
        room -= size
    odts.append(current)
    return odts


class DaqList:
    """One dynamic DAQ list on one event channel, configured with FREE_DAQ, ALLOC_DAQ,
    ALLOC_ODT, ALLOC_ODT_ENTRY, SET_DAQ_PTR, WRITE_DAQ and SET_DAQ_LIST_MODE."""

    def __init__(self, session, entries, event, prescaler, timestamp):
        master = session.master
        self.timestamp = timestamp
        self.odts = pack_odts(entries, timestamp=timestamp)
        master.freeDaq()
        master.allocDaq(1)
        master.allocOdt(0, len(self.odts))
        for number, odt in enumerate(self.odts):
            master.allocOdtEntry(0, number, len(odt))
        for number, odt in enumerate(self.odts):
            master.setDaqPtr(0, number, 0)
            for _, address, size in odt:
                master.writeDaq(BIT_OFFSET_NONE, size, 0, address)
        master.setDaqListMode(DAQ_MODE_TIMESTAMP if timestamp else 0, 0, event, prescaler, 0)
        self.first_pid = None
        self.prescaler = prescaler
        self.master = master

    def start(self):
        """Selects the list (START_STOP_DAQ_LIST select, which answers FIRST_PID) and starts
        it with START_STOP_SYNCH start-selected."""
        self.first_pid = int(self.master.startStopDaqList(DAQ_LIST_SELECT, 0).firstPid)
        self.master.startStopSynch(SYNCH_START_SELECTED)

    def stop(self):
        self.master.startStopSynch(SYNCH_STOP_ALL)

    def decode(self, dtos, padded):
        """Samples out of DTOs in arrival order: the first ODT (PID, timestamp, entries) opens
        a sample, the following ODTs complete it in order. Anything out of order is reported
        and ends the run."""
        samples, current, next_odt = [], None, 0
        for index, (counter, packet) in enumerate(dtos):
            if not packet:
                raise Failure(f"empty DTO at {index}")
            odt = packet[0] - self.first_pid
            if odt < 0 or odt >= len(self.odts):
                raise Failure(f"DTO {index} (ctr {counter}) has PID {packet[0]:#x}: {packet.hex()}")
            if odt != next_odt:
                raise Failure(f"DTO {index} (ctr {counter}) is ODT {odt}, expected ODT {next_odt}: {packet.hex()}")
            at = 1
            if odt == 0:
                current = {}
                if self.timestamp:
                    current["timestamp_us"] = struct.unpack_from("<I", packet, at)[0]
                    at += DTO_TIMESTAMP_LEN
            expected_len = at + sum(size for _, _, size in self.odts[odt])
            # On CAN every frame is 8 bytes (MAX_DLC_REQUIRED): the padding follows the data.
            if len(packet) != expected_len and not (padded and len(packet) == CAN_DLC and expected_len < CAN_DLC):
                raise Failure(f"DTO {index} (ctr {counter}) has {len(packet)} bytes, not {expected_len}: {packet.hex()}")
            for name, _, size in self.odts[odt]:
                raw = packet[at : at + size]
                current[name] = struct.unpack("<H", raw)[0] if name == "sequence" else struct.unpack("<f", raw)[0]
                at += size
            next_odt = (odt + 1) % len(self.odts)
            if next_odt == 0:
                samples.append(current)
                current = None
        if next_odt != 0:
            log(f"the last sample is incomplete (ODT {next_odt} missing); left out")
        return samples


# ---------------------------------------------------------------------------------------------
# The scenarios.


def scenarios(app, expected, layer):
    params = {p["name"]: p for p in expected["parameters"]}
    internals = {i["name"]: i["offset"] for i in expected["internals"]}

    # 1. Connect; the EPK from the slave and from the A2L.
    session = Session(app, expected, layer)
    result("epk", session.master.identifier(GET_ID_EPK))
    result("a2l_epk", a2l_epk(expected["a2l"]))

    # 2. Every parameter as the slave has it.
    defaults = {name: session.read_parameter(name) for name in params}
    result("defaults", defaults)

    # 3. Writing before unlocking is refused; then seed and key.
    kp = params["traction_kp"]
    locked_value = as_f32((kp["min"] + kp["max"]) / 2)
    result("locked_write", session.write_parameter("traction_kp", [locked_value]))
    if not session.protection_locked():
        raise Failure("calibration reports unlocked before UNLOCK")
    result("unlocked", session.unlock())

    # 4. A value outside the limits is refused and changes nothing.
    code = session.write_parameter("launch_kp", [1e6])
    result("out_of_range", {"code": code, "after": session.read_parameter("launch_kp")[0]})

    # 5. BUILD_CHECKSUM over the working page, and the same CRC over the page as uploaded.
    page_address, page_len = expected["calibration_address"], expected["page_len"]
    session.master.setMta(page_address, 0)
    checksum = session.master.buildChecksum(page_len)
    page = session.read(page_address, page_len)
    result(
        "checksum",
        {"slave": int(checksum.checksum), "type": int(checksum.checksumType), "computed": crc16_ccitt(page)},
    )

    # 6. A curve written as one block.
    target = [0.03, 0.03, 0.03, 0.03]
    code = session.write_parameter("launch_slip_target", target)
    if code is not None:
        raise Failure(f"writing launch_slip_target was refused with {code:#04x}")
    result("launch_target", session.read_parameter("launch_slip_target"))

    # 7. Saved to the flash.
    try:
        session.master.setRequest(STORE_CAL_REQ, 0)
        result("stored", True)
    except types.XcpResponseError as error:
        code = error_code(error)
        log(f"SET_REQUEST STORE_CAL_REQ refused with error code {code:#04x}")
        result("stored", False)

    # 8. The tractive system is live: sensor calibration is locked out.
    ask({"cmd": "start_up"})
    apps = list(defaults["apps1_v"])
    apps[0] = as_f32(apps[0] + 0.01)
    result("tractive_off_write", session.write_parameter("apps1_v", apps))

    # 9. DAQ during a launch; writes while moving.
    # The list fills the slave's DAQ frame budget at the control rate exactly: two ODTs of up
    # to 7 bytes every 10 ms (200 DTOs/s). The telemetry sequence number, not a timestamp,
    # names the control step each sample belongs to.
    sequence_address = expected["telemetry_address"] + expected["telemetry_sequence_offset"]
    entries = [("sequence", sequence_address, 2)] + [
        (name, expected["internals_address"] + internals[name], 4)
        for name in ("launch_slip_target", "torque_command_nm")
    ]
    resolution = session.master.getDaqResolutionInfo()
    log(f"GET_DAQ_RESOLUTION_INFO: {dict(resolution)}")
    daq = DaqList(session, entries, EVENT_CONTROL, prescaler=1, timestamp=False)
    log(f"DAQ list: {[[name for name, _, _ in odt] for odt in daq.odts]} on event {EVENT_CONTROL}, prescaler 1")
    daq.start()
    session.dtos.take()
    ask({"cmd": "drive_until_moving"})

    launch_kp = params["launch_kp"]
    current = session.read_parameter("launch_kp")[0]
    changed = current + 10.0 if current + 10.0 <= launch_kp["max"] else current - 10.0
    code = session.write_parameter("launch_kp", [as_f32(changed)])
    result("moving_standstill_write", {"code": code, "after": session.read_parameter("launch_kp")[0]})
    code = session.write_parameter("traction_kp", [650.0])
    result("moving_driving_write", {"code": code, "after": session.read_parameter("traction_kp")[0]})
    try:
        session.master.setCalPage(PAGE_MODE_ECU, 0, 1)
        code = None
    except types.XcpResponseError as error:
        code = error_code(error)
    result("moving_page_switch", code)

    ask({"cmd": "drive", "ms": 300})
    # pyxcp's listener feeds every frame to the policy in arrival order before it queues a
    # response: once STOP's answer is back, every DTO sent before it has been collected.
    daq.stop()
    dtos = session.dtos.take()
    total = len(dtos)
    log(f"{total} DTOs collected (first PID {daq.first_pid}, prescaler {daq.prescaler})")
    # On CAN every DTO is a padded 8-byte frame; through the Pi's gateway it still is.
    padded = layer == "can" or os.environ.get("AER_XCP_PADDED") == "1"
    result("daq", daq.decode(dtos, padded=padded))

    # 10. Power cycle: the saved calibration comes back.
    session.close()
    # The harness answers, then waits for the new connection before it reads any request:
    # connect first, report after.
    answer = ask({"cmd": "restart"})
    session = Session(app, expected, layer)
    result("restart_startup", answer.get("startup"))
    result(
        "restored",
        {
            "launch_slip_target": session.read_parameter("launch_slip_target"),
            "traction_kp": session.read_parameter("traction_kp")[0],
        },
    )

    # 11. The reference page copied onto the working page restores the defaults.
    if not session.unlock():
        raise Failure("calibration still locked after UNLOCK (second session)")
    session.master.copyCalPage(0, 1, 0, 0)
    result("reverted", session.read_parameter("launch_slip_target"))

    # 12. Both saved copies corrupt: start-up falls back to the defaults.
    session.close()
    answer = ask({"cmd": "corrupt"})
    session = Session(app, expected, layer)
    result("corrupt_startup", answer.get("startup"))
    result("after_corrupt", session.read_parameter("launch_slip_target"))
    session.close()

    # 13.
    ask({"cmd": "done"})


def transport_config(env):
    """pyxcp's transport name and Transport section for the link the harness serves."""
    kind = env["AER_XCP_TRANSPORT"]
    if kind == "tcp":
        host, port = env["AER_XCP_HOST"], int(env["AER_XCP_PORT"])
        return "eth", {"Eth": {"host": host, "port": port, "protocol": "TCP", "tcp_nodelay": True}}
    if kind == "can":
        return "can", {
            # pyxcp reads this section under "CAN" (and Ethernet's under "Eth").
            "CAN": {
                "interface": "socketcan",
                "channel": env["AER_XCP_CAN_CHANNEL"],
                "can_id_master": int(env["AER_XCP_CAN_ID_MASTER"]),
                "can_id_slave": int(env["AER_XCP_CAN_ID_SLAVE"]),
                "bitrate": int(env["AER_XCP_CAN_BIT_RATE"]),
                # The DBC declares XCP_Cmd with 8 bytes: every command frame is padded.
                "max_dlc_required": True,
            },
        }
    raise ValueError(f"AER_XCP_TRANSPORT={kind!r}: tcp or can")


def arguments():
    parser = argparse.ArgumentParser(description="pyxcp against the CCM's XCP slave (see the module's docstring)")
    parser.add_argument(
        "--seed-key-library",
        metavar="PATH",
        help="play only the unlock scenario, pyxcp unlocking through this seed-and-key library",
    )
    parser.add_argument(
        "--same-bit-width",
        action="store_true",
        help="with --seed-key-library: pyxcp loads the library with ctypes, not in its asamkeydll helper",
    )
    return parser.parse_args()


def main():
    args = arguments()
    try:
        layer, transport = transport_config(os.environ)
        secret = None if args.seed_key_library else bytes.fromhex(os.environ["AER_XCP_SECRET"])
        with open(os.environ["AER_XCP_EXPECTED"], encoding="utf-8") as file:
            expected = json.load(file)
    except (KeyError, ValueError, OSError) as error:
        log(f"bad environment: {error!r} (see the docstring)")
        return 2
    if secret is not None and len(secret) != 32:
        log(f"AER_XCP_SECRET has {len(secret)} bytes, not 32")
        return 2

    # Error packets reach us as XcpResponseError with their code: the scenarios expect
    # refusals, and pyxcp's error matrix would otherwise retry or try to unlock by itself on
    # ERR_ACCESS_LOCKED.
    general = {"disable_error_handling": True}
    if args.seed_key_library:
        general["seed_n_key_dll"] = args.seed_key_library
        general["seed_n_key_dll_same_bit_width"] = args.same_bit_width
    else:
        general["seed_n_key_function"] = seed_and_key(secret)
    app = create_application_from_config({"Transport": transport, "General": general}, log_level=logging.WARNING)
    app.transport.timeout = 5.0

    try:
        if args.seed_key_library:
            outcome = unlock_with_library(app, expected, layer)
            log(f"unlock through {args.seed_key_library}: {json.dumps(outcome)}")
            _PROTOCOL_OUT.write(json.dumps(outcome) + "\n")
            _PROTOCOL_OUT.flush()
            return 0
        scenarios(app, expected, layer)
    except Failure as failure:
        log(f"FAILED: {failure}")
        return 1
    except Exception:  # noqa: BLE001 - anything else is unexpected: say where, then fail
        log("FAILED with an unexpected exception:")
        traceback.print_exc(file=sys.stderr)
        return 1
    log("all scenarios played")
    return 0


if __name__ == "__main__":
    sys.exit(main())
