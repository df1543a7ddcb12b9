"""Compares an A2L's XCP description (its IF_DATA, parsed by pya2ldb) with what the slave
really answers (a JSON file of raw answers: car-node/tests/a2l_truth.rs writes it).

Usage: check_a2l_slave.py FILE.a2l ANSWERS.json

Every answer is decoded as ASAM MCD-1 XCP 1.x lays it out; every difference is printed, and
the exit status is 1 if there is any.
"""

import json
import os
import re
import sys

from check_a2l import import_a2l

# Commands every slave has: the A2L lists only the optional ones.
MANDATORY = {"CONNECT", "DISCONNECT", "GET_STATUS", "SYNCH"}
# GET_DAQ_RESOLUTION_INFO's timestamp size code -> the A2L's name.
TIMESTAMP_SIZES = {1: "SIZE_BYTE", 2: "SIZE_WORD", 4: "SIZE_DWORD"}
# Its unit code -> the A2L's name.
TIMESTAMP_UNITS = {0: "UNIT_1NS", 1: "UNIT_10NS", 2: "UNIT_100NS", 3: "UNIT_1US",
                   4: "UNIT_10US", 5: "UNIT_100US", 6: "UNIT_1MS", 7: "UNIT_10MS",
                   8: "UNIT_100MS", 9: "UNIT_1S"}
# DAQ_PROPERTIES bits 6-7 -> the A2L's overload indication.
OVERLOADS = {0: "NO_OVERLOAD_INDICATION", 1: "OVERLOAD_INDICATION_PID",
             2: "OVERLOAD_INDICATION_EVENT"}
# DAQ_KEY_BYTE bits 6-7 -> the identification field type.
IDENTIFICATIONS = {0: "IDENTIFICATION_FIELD_TYPE_ABSOLUTE",
                   1: "IDENTIFICATION_FIELD_TYPE_RELATIVE_BYTE",
                   2: "IDENTIFICATION_FIELD_TYPE_RELATIVE_WORD",
                   3: "IDENTIFICATION_FIELD_TYPE_RELATIVE_WORD_ALIGNED"}
# DAQ_KEY_BYTE bits 4-5 -> the address extension rule.
EXTENSIONS = {0: "ADDRESS_EXTENSION_FREE", 1: "ADDRESS_EXTENSION_ODT",
              3: "ADDRESS_EXTENSION_DAQ"}
# PAGE_PROPERTIES, two bits each: (without the other side, with it).
ECU_ACCESS = {0: "ECU_ACCESS_NOT_ALLOWED", 1: "ECU_ACCESS_WITHOUT_XCP_ONLY",
              2: "ECU_ACCESS_WITH_XCP_ONLY", 3: "ECU_ACCESS_DONT_CARE"}
XCP_READ = {0: "XCP_READ_ACCESS_NOT_ALLOWED", 1: "XCP_READ_ACCESS_WITHOUT_ECU_ONLY",
            2: "XCP_READ_ACCESS_WITH_ECU_ONLY", 3: "XCP_READ_ACCESS_DONT_CARE"}
XCP_WRITE = {0: "XCP_WRITE_ACCESS_NOT_ALLOWED", 1: "XCP_WRITE_ACCESS_WITHOUT_ECU_ONLY",
             2: "XCP_WRITE_ACCESS_WITH_ECU_ONLY", 3: "XCP_WRITE_ACCESS_DONT_CARE"}
# BUILD_CHECKSUM's type code -> the A2L's checksum name.
CHECKSUMS = {0x01: "XCP_ADD_11", 0x02: "XCP_ADD_12", 0x03: "XCP_ADD_14", 0x04: "XCP_ADD_22",
             0x05: "XCP_ADD_24", 0x06: "XCP_ADD_44", 0x07: "XCP_CRC_16", 0x08: "XCP_CRC_16_CITT",
             0x09: "XCP_CRC_32", 0xFF: "XCP_USER_DEFINED"}


def u16(data, at):
    return data[at] | data[at + 1] << 8


class Compare:
    def __init__(self):
        self.problems = []
        self.checked = 0

    def same(self, what, a2l, slave):
        self.checked += 1
        if a2l != slave:
            self.problems.append(f"{what}: the A2L says {a2l!r}, the slave answers {slave!r}")


def xcp_sections(parsed):
    """The IF_DATA XCP sections' contents, merged."""
    merged = {}
    for entry in parsed:
        for section in entry.get("XCP", []):
            merged.update(section)
    return merged


def init_segments(raw):
    """Each PAGE's INIT_SEGMENT by page number, read from the IF_DATA text: pya2ldb's IF_DATA
    parser drops a taggedstruct inside a block's struct, which is where the A2ML puts it."""
    found = {}
    for page in re.finditer(r"/begin PAGE\s+(\w+)(.*?)/end PAGE", raw, re.S):
        init = re.search(r"INIT_SEGMENT\s+(\w+)", page.group(2))
        found[int(page.group(1), 0)] = int(init.group(1), 0) if init else None
    return found


def main(argv):
    if len(argv) != 3:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    a2l_path, answers_path = argv[1], argv[2]
    with open(answers_path, encoding="utf-8") as f:
        slave = json.load(f)
    problems = []
    session = import_a2l(a2l_path, problems)
    import pya2l.model as model

    module = session.query(model.Module).one()
    xcp = xcp_sections(session.parse_ifdata(module.if_data))
    c = Compare()
    c.problems = problems

    protocol = xcp["PROTOCOL_LAYER"]
    connect = slave["connect"]
    c.same("MAX_CTO", protocol[8], connect[3])
    c.same("MAX_DTO", protocol[9], u16(connect, 4))
    c.same("byte order", protocol[10],
           "BYTE_ORDER_MSB_LAST" if connect[2] & 0x01 == 0 else "BYTE_ORDER_MSB_FIRST")
    c.same("address granularity", protocol[11],
           {0: "ADDRESS_GRANULARITY_BYTE", 1: "ADDRESS_GRANULARITY_WORD",
            2: "ADDRESS_GRANULARITY_DWORD"}[(connect[2] >> 1) & 0x03])
    options = protocol[12]
    listed = set(options.get("OPTIONAL_CMD", []))
    unknown = set(slave["unknown"])
    for command in sorted(listed & unknown):
        c.problems.append(f"OPTIONAL_CMD {command}: the slave answers ERR_CMD_UNKNOWN")
    c.checked += len(listed)
    info = slave["comm_mode_info"]
    block = options.get("COMMUNICATION_MODE_SUPPORTED", {}).get("BLOCK", {}).get("MASTER")
    c.same("master block mode", block is not None, bool(info[2] & 0x01))
    if block is not None:
        c.same("MAX_BS", block[0], info[4])
        c.same("MIN_ST", block[1], info[5])

    daq = xcp["DAQ"]
    processor = slave["daq_processor"]
    properties = processor[1]
    c.same("DAQ config type", daq[0], "DYNAMIC" if properties & 0x01 else "STATIC")
    c.same("MAX_DAQ", daq[1], u16(processor, 2))
    c.same("MAX_EVENT_CHANNEL", daq[2], u16(processor, 4))
    c.same("MIN_DAQ", daq[3], processor[6])
    key = processor[7]
    c.same("optimisation type", daq[4],
           "OPTIMISATION_TYPE_DEFAULT" if key & 0x0F == 0 else f"type {key & 0x0F}")
    c.same("address extension", daq[5], EXTENSIONS.get((key >> 4) & 0x03))
    c.same("identification field", daq[6], IDENTIFICATIONS[(key >> 6) & 0x03])
    resolution = slave["daq_resolution"]
    c.same("ODT entry granularity", daq[7],
           {1: "GRANULARITY_ODT_ENTRY_SIZE_DAQ_BYTE", 2: "GRANULARITY_ODT_ENTRY_SIZE_DAQ_WORD",
            4: "GRANULARITY_ODT_ENTRY_SIZE_DAQ_DWORD"}.get(resolution[1]))
    c.same("MAX_ODT_ENTRY_SIZE_DAQ", daq[8], resolution[2])
    c.same("overload indication", daq[9], OVERLOADS.get(properties >> 6))
    extras = daq[-1] if isinstance(daq[-1], dict) else {}
    c.same("PRESCALER_SUPPORTED", bool(extras.get("PRESCALER_SUPPORTED")), bool(properties & 0x02))
    stamp = extras.get("TIMESTAMP_SUPPORTED")
    c.same("TIMESTAMP_SUPPORTED", stamp is not None, bool(properties & 0x10))
    if stamp is not None:
        mode = resolution[5]
        c.same("timestamp ticks", stamp[0], u16(resolution, 6))
        c.same("timestamp size", stamp[1], TIMESTAMP_SIZES.get(mode & 0x07))
        c.same("timestamp unit", stamp[2], TIMESTAMP_UNITS.get(mode >> 4))
    events = extras.get("EVENT", [])
    c.same("event channels", len(events), len(slave["events"]))
    for event, answer in zip(events, slave["events"]):
        info = answer["info"]
        what = f"EVENT {event[0]}"
        c.same(f"{what} name", event[0], answer["name"])
        c.same(f"{what} channel number", event[2], slave["events"].index(answer))
        c.same(f"{what} type", event[3], {0x04: "DAQ", 0x08: "STIM", 0x0C: "DAQ_STIM"}.get(info[1] & 0x0C))
        c.same(f"{what} MAX_DAQ_LIST", event[4], info[2])
        c.same(f"{what} cycle", event[5], info[4])
        c.same(f"{what} time unit", event[6], info[5])
        c.same(f"{what} priority", event[7], info[6])

    pag = xcp.get("PAG")
    c.same("MAX_SEGMENTS", pag[0] if pag else None, slave["pag_processor"][1])
    segments = []
    for segment in session.query(model.MemorySegment).all():
        sections = segment.if_data or []
        if not isinstance(sections, (list, tuple)) and not hasattr(sections, "__iter__"):
            sections = [sections]
        raw = "".join(section.raw or "" for section in sections)
        for entry in session.parse_ifdata(segment.if_data):
            for section in entry.get("XCP", []):
                if "SEGMENT" in section:
                    segments.append((segment.name, section["SEGMENT"], init_segments(raw)))
    c.same("segments with XCP pages", len(segments), len(slave["segments"]))
    for (name, described, inits), answer in zip(segments, slave["segments"]):
        standard = answer["standard"]
        what = f"SEGMENT {name}"
        c.same(f"{what} pages", described[1], standard[1])
        c.same(f"{what} address extension", described[2], standard[2])
        c.same(f"{what} compression", described[3], standard[4])
        c.same(f"{what} encryption", described[4], standard[5])
        extras = described[-1] if isinstance(described[-1], dict) else {}
        checksum = extras.get("CHECKSUM")
        if checksum:
            c.same(f"{what} checksum", checksum[0], CHECKSUMS.get(slave["checksum"][1]))
        pages = extras.get("PAGE", [])
        for page, reply in zip(pages, answer["pages"]):
            where = f"{what} PAGE {page[0]}"
            props = reply[1]
            c.same(f"{where} ECU access", page[1], ECU_ACCESS[props & 0x03])
            c.same(f"{where} XCP read access", page[2], XCP_READ[(props >> 2) & 0x03])
            c.same(f"{where} XCP write access", page[3], XCP_WRITE[(props >> 4) & 0x03])
            c.same(f"{where} INIT_SEGMENT", inits.get(page[0]), reply[2])
        c.same(f"{what} page count described", len(pages), len(answer["pages"]))

    stem = os.path.splitext(os.path.basename(a2l_path))[0]
    c.same("GET_ID 1 (the A2L's name)", stem, slave["a2l_name"])
    can = xcp.get("XCP_ON_CAN", [[None, {}]])[0][-1]
    c.same("CAN_ID_MASTER", can.get("CAN_ID_MASTER"), slave["can_id_master"])
    c.same("CAN_ID_SLAVE", can.get("CAN_ID_SLAVE"), slave["can_id_slave"])
    tcp = xcp.get("XCP_ON_TCP_IP", [[None, None]])[0]
    c.same("TCP port", tcp[1], slave["tcp_port"])

    if c.problems:
        print(f"{a2l_path}: {len(c.problems)} difference(s) from the slave:")
        for p in c.problems:
            print(f"  {p}")
        return 1
    print(f"{a2l_path}: {c.checked} values and {len(listed)} optional commands as the slave answers")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
