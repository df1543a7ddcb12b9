#!/usr/bin/env python3
"""schema/aer.dbc opens unchanged in two independent DBC tools (a stand-in for CANalyzer's
import): cantools in strict mode and canmatrix, and both read the same layout as aer-codegen.

Usage: python tools/test_dbc_opens.py [--codegen target/debug/aer-codegen]
"""

import os
import re
import subprocess
import sys
import unittest

import canmatrix.formats
import cantools

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DBC = os.path.join(ROOT, "schema", "aer.dbc")
CODEGEN = os.environ.get("AER_CODEGEN", os.path.join(ROOT, "target", "debug", "aer-codegen"))


class CarDbcOpensElsewhere(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.cantools = cantools.database.load_file(DBC, strict=True)
        cls.canmatrix = canmatrix.formats.loadp_flat(DBC)

    def test_cantools_strict_reads_every_message(self):
        self.assertGreaterEqual(len(self.cantools.messages), 16)
        for m in self.cantools.messages:
            self.assertTrue(m.signals, m.name)
            # A message sent on demand says so (GenMsgSendType NoMsgSendType); every other one
            # declares its cycle.
            if m.send_type == "Cyclic":
                self.assertIsNotNone(m.cycle_time, f"{m.name} has no GenMsgCycleTime")
            else:
                self.assertEqual(m.send_type, "NoMsgSendType", m.name)
                self.assertIsNone(m.cycle_time, f"{m.name} is sent on demand but has a cycle time")
        on_demand = {m.name for m in self.cantools.messages if m.send_type != "Cyclic"}
        self.assertIn("IMD_Request", on_demand)

    def test_canmatrix_reads_the_same_layout(self):
        frames = {(f.arbitration_id.id, f.arbitration_id.extended): f for f in self.canmatrix.frames}
        for m in self.cantools.messages:
            f = frames[(m.frame_id, m.is_extended_frame)]
            self.assertEqual(f.name, m.name)
            self.assertEqual(f.size, m.length)
            theirs = {s.name: s for s in f.signals}
            for s in m.signals:
                c = theirs[s.name]
                self.assertEqual(c.size, s.length, s.name)
                self.assertEqual(c.is_little_endian, s.byte_order == "little_endian", s.name)
                self.assertEqual(c.is_signed, s.is_signed, s.name)
                self.assertAlmostEqual(float(c.factor), s.scale, msg=s.name)
                self.assertAlmostEqual(float(c.offset), s.offset, msg=s.name)
                self.assertEqual(c.unit or None, s.unit or None, s.name)

    def test_enums_and_comments_survive(self):
        mcu1 = self.cantools.get_message_by_name("MCU1")
        self.assertEqual(str(mcu1.get_signal_by_name("MCU_MainState").choices[3]), "RUN")
        self.assertIn("260 Nm maximum", mcu1.get_signal_by_name("MCU_ActualTorque").comment)
        imd = self.cantools.get_message_by_name("IMD_InfoVoltage")
        self.assertTrue(imd.is_extended_frame)
        self.assertEqual(imd.frame_id, 0x18FF03F4)

    def test_aer_codegen_agrees_on_the_counts(self):
        out = subprocess.run([CODEGEN, "check", "--deny-warnings", DBC], capture_output=True, text=True, check=True)
        match = re.search(r"(\d+) messages, (\d+) signals", out.stdout)
        self.assertIsNotNone(match, out.stdout)
        self.assertEqual(int(match.group(1)), len(self.cantools.messages))
        self.assertEqual(int(match.group(2)), sum(len(m.signals) for m in self.cantools.messages))


if __name__ == "__main__":
    unittest.main(verbosity=2)
