#!/usr/bin/env python3
"""import_cycles.py finds a circle however its imports are written: `crate::`, `super::`
(one or several) and `self::` paths, plain or in `{...}` groups."""
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path

SCRIPT = Path(__file__).with_name("import_cycles.py")


def run(files: dict[str, str]) -> subprocess.CompletedProcess:
    with tempfile.TemporaryDirectory() as src:
        for name, text in files.items():
            path = Path(src, name)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
        return subprocess.run(
            [sys.executable, str(SCRIPT), src], capture_output=True, text=True, check=False
        )


class ImportCycles(unittest.TestCase):
    def test_a_two_file_circle_through_super_is_found(self):
        result = run(
            {
                "store/mod.rs": "pub mod compact;\npub mod schema;\n",
                "store/compact.rs": "fn f() { super::schema::release(); }\n",
                "store/schema.rs": "use super::{compact, session};\nconst T: &str = compact::BLOCKS;\n",
                "store/session.rs": "",
            }
        )
        self.assertEqual(result.returncode, 1, result.stdout)
        self.assertIn("store::compact -> store::schema -> store::compact", result.stdout)

    def test_self_and_nested_super_paths_resolve_from_the_module(self):
        result = run(
            {
                "a/mod.rs": "use self::inner::x;\n",
                "a/inner.rs": "use super::super::b::y;\n",
                "b.rs": "use crate::a::inner::x;\n",
            }
        )
        self.assertEqual(result.returncode, 1, result.stdout)
        self.assertIn("a::inner -> b -> a::inner", result.stdout)

    def test_parents_and_children_are_not_circles(self):
        result = run(
            {
                "a/mod.rs": "use self::inner::x;\n",
                "a/inner.rs": "use super::helper;\n",
                "c.rs": "use crate::a::inner;\n",
            }
        )
        self.assertEqual(result.returncode, 0, result.stdout)
        self.assertIn("no cycle", result.stdout)


if __name__ == "__main__":
    unittest.main()
