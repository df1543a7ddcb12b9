#!/usr/bin/env python3
"""Reads the generated A2L with pya2ldb, a parser independent of the generator, and compares
every CHARACTERISTIC and MEASUREMENT (name, address, data type, limits, unit, conversion), the
EPK and the memory segments with what the generated crate's own constants say they are.

    check_a2l.py A2L EXPECTED_JSON

EXPECTED_JSON is written by tests/a2l.rs from aer::calibration (PARAMETERS, INTERNALS, the
xcp module) and aer::telemetry (the packet's field metadata). Exits 0 when everything agrees,
1 naming every difference (and every error or warning the parser logged), 2 on bad usage.
"""

import json
import logging
import os
import shutil
import sys
import tempfile


class Collect(logging.Handler):
    """Keeps the parser's warnings and errors."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages = []

    def emit(self, record):
        self.messages.append(f"{record.levelname} {record.name}: {record.getMessage()}")


def import_a2l(path, problems):
    """The A2L as a pya2ldb session. The native parser logs to the process's stdout/stderr,
    so both are captured while it runs and its warnings and errors are reported."""
    collect = Collect()
    logging.basicConfig(level=logging.WARNING, handlers=[collect])
    import pya2l

    workdir = tempfile.mkdtemp(prefix="check_a2l")
    copy = os.path.join(workdir, "aer.a2l")
    shutil.copyfile(path, copy)
    captured = os.path.join(workdir, "parser.log")
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with open(captured, "w", encoding="utf-8") as log:
        os.dup2(log.fileno(), 1)
        os.dup2(log.fileno(), 2)
        try:
            session = pya2l.import_a2l(
                copy,
                in_memory=True,
                progress_bar=False,
                loglevel="WARN",
                encoding="utf-8",
            )
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
    with open(captured, encoding="utf-8", errors="replace") as log:
        for line in log:
            if any(level in line for level in ("[error]", "[critical]", "[warning]")):
                problems.append(f"parser: {line.strip()}")
    problems.extend(f"parser: {m}" for m in collect.messages)
    shutil.rmtree(workdir, ignore_errors=True)
    return session


def same(actual, expected):
    """Numbers equal as the doubles they denote (the A2L writes them exactly)."""
    if actual is None or expected is None:
        return actual is expected
    return float(actual) == float(expected)


class Checker:
    def __init__(self, session):
        from pya2l import model

        self.model = model
        self.session = session
        self.problems = []
        self.methods = {m.name: m for m in session.query(model.CompuMethod)}
        self.tables = {t.name: t for t in session.query(model.CompuVtab)}
        self.layouts = {r.name: r for r in session.query(model.RecordLayout)}

    def differ(self, what, field, actual, expected):
        self.problems.append(f"{what}: {field} {actual!r}, expected {expected!r}")

    def number(self, what, field, actual, expected):
        if not same(actual, expected):
            self.differ(what, field, actual, expected)

    def linear(self, what, conversion, expected_coeffs, expected_unit):
        """A LINEAR COMPU_METHOD with these coefficients and unit."""
        method = self.methods.get(conversion)
        if method is None:
            self.problems.append(f"{what}: conversion {conversion!r} is not defined")
            return
        if method.conversionType != "LINEAR" or method.coeffs_linear is None:
            self.differ(what, "conversion type", method.conversionType, "LINEAR")
            return
        actual = [method.coeffs_linear.a, method.coeffs_linear.b]
        if not all(same(a, e) for a, e in zip(actual, expected_coeffs)):
            self.differ(what, "conversion coefficients", actual, expected_coeffs)
        if method.unit != expected_unit:
            self.differ(what, "unit", method.unit, expected_unit)

    def table(self, what, conversion, expected):
        """A TAB_VERB COMPU_METHOD naming these raw values."""
        method = self.methods.get(conversion)
        if method is None or method.conversionType != "TAB_VERB":
            self.differ(what, "conversion", conversion, "a TAB_VERB table")
            return
        table = self.tables.get(method.compu_tab_ref.conversionTable)
        if table is None:
            self.problems.append(f"{what}: its value table is not defined")
            return
        actual = {str(int(p.inVal)): p.outVal for p in table.pairs}
        if actual != expected:
            self.differ(what, "value names", actual, expected)

    def characteristic(self, c, e):
        what = f"CHARACTERISTIC {e['name']}"
        if c.type != e["type"]:
            self.differ(what, "type", c.type, e["type"])
        self.number(what, "address", c.address, e["address"])
        layout = self.layouts.get(c.deposit)
        datatype = layout.fnc_values.datatype if layout and layout.fnc_values else None
        if datatype != e["datatype"]:
            self.differ(what, "data type", datatype, e["datatype"])
        self.number(what, "lower limit", c.lowerLimit, e["lower"])
        self.number(what, "upper limit", c.upperLimit, e["upper"])
        if c.extended_limits is not None:
            self.number(what, "extended lower limit", c.extended_limits.lowerLimit, e["lower"])
            self.number(what, "extended upper limit", c.extended_limits.upperLimit, e["upper"])
        self.linear(what, c.conversion, e["coeffs"], e["unit"])
        if e["type"] == "VAL_BLK":
            count = c.matrix_dim.numbers[0] if c.matrix_dim else None
            self.number(what, "element count", count, e["count"])
        if e["type"] == "CURVE":
            axis = c.axis_descr[0] if c.axis_descr else None
            if axis is None or axis.attribute != "COM_AXIS" or axis.axis_pts_ref is None:
                self.problems.append(f"{what}: no tunable axis (COM_AXIS with AXIS_PTS_REF)")
            else:
                self.number(what, "axis points", axis.maxAxisPoints, e["count"])
                if axis.axis_pts_ref.axisPoints != e["axis"]:
                    self.differ(what, "axis", axis.axis_pts_ref.axisPoints, e["axis"])
                if axis.inputQuantity != e["axis_input"]:
                    self.differ(what, "axis input", axis.inputQuantity, e["axis_input"])
                self.linear(f"{what} axis", axis.conversion, [1, 0], e["axis_unit"])

    def axis_points(self, a, e):
        what = f"AXIS_PTS {e['name']}"
        self.number(what, "address", a.address, e["address"])
        layout = self.layouts.get(a.depositAttr)
        datatype = layout.axis_pts_x.datatype if layout and layout.axis_pts_x else None
        if datatype != e["datatype"]:
            self.differ(what, "data type", datatype, e["datatype"])
        self.number(what, "lower limit", a.lowerLimit, e["lower"])
        self.number(what, "upper limit", a.upperLimit, e["upper"])
        self.number(what, "points", a.maxAxisPoints, e["count"])
        if a.inputQuantity != e["input"]:
            self.differ(what, "input", a.inputQuantity, e["input"])
        self.linear(what, a.conversion, [1, 0], e["unit"])

    def measurement(self, m, e):
        what = f"MEASUREMENT {e['name']}"
        if m.datatype != e["datatype"]:
            self.differ(what, "data type", m.datatype, e["datatype"])
        address = m.ecu_address.address if m.ecu_address else None
        self.number(what, "address", address, e["address"])
        self.number(what, "lower limit", m.lowerLimit, e["lower"])
        self.number(what, "upper limit", m.upperLimit, e["upper"])
        mask = m.bit_mask.mask if m.bit_mask else None
        self.number(what, "bit mask", mask, e["bit_mask"])
        if e["coeffs"] is not None:
            self.linear(what, m.conversion, e["coeffs"], e["unit"])
        elif e["values"] is not None:
            self.table(what, m.conversion, e["values"])
        elif m.conversion != "NO_COMPU_METHOD":
            self.differ(what, "conversion", m.conversion, "NO_COMPU_METHOD")

    def module(self, expected):
        model = self.model
        mod_par = self.session.query(model.ModPar).one()
        epk = mod_par.epk.identifier if mod_par.epk else None
        if epk != expected["epk"]:
            self.differ("MOD_PAR", "EPK", epk, expected["epk"])
        addresses = [a.address for a in mod_par.addr_epk]
        if addresses != [expected["epk_address"]]:
            self.differ("MOD_PAR", "ADDR_EPK", addresses, [expected["epk_address"]])
        segments = {s.name: [s.address, s.size] for s in mod_par.memory_segment}
        if segments != expected["memory_segments"]:
            self.differ("MOD_PAR", "memory segments", segments, expected["memory_segments"])

    def objects(self, kind, query, expected, check):
        actual = {o.name: o for o in self.session.query(query)}
        for e in expected:
            found = actual.pop(e["name"], None)
            if found is None:
                self.problems.append(f"{kind} {e['name']} is missing")
            else:
                check(found, e)
        for name in sorted(actual):
            self.problems.append(f"{kind} {name} is not in the crate's tables")


def main(argv):
    if len(argv) != 3:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    a2l, expected_path = argv[1], argv[2]
    with open(expected_path, encoding="utf-8") as f:
        expected = json.load(f)
    problems = []
    session = import_a2l(a2l, problems)
    checker = Checker(session)
    checker.problems = problems
    checker.module(expected)
    checker.objects(
        "CHARACTERISTIC",
        checker.model.Characteristic,
        expected["characteristics"],
        checker.characteristic,
    )
    checker.objects(
        "AXIS_PTS",
        checker.model.AxisPts,
        expected["axis_points"],
        checker.axis_points,
    )
    checker.objects(
        "MEASUREMENT",
        checker.model.Measurement,
        expected["measurements"],
        checker.measurement,
    )
    if problems:
        print(f"{a2l}: {len(problems)} difference(s) from the crate:")
        for p in problems:
            print(f"  {p}")
        return 1
    print(
        f"{a2l}: {len(expected['characteristics'])} characteristics, "
        f"{len(expected['axis_points'])} axis point lists and "
        f"{len(expected['measurements'])} measurements as the crate says"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
