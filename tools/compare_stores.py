#!/usr/bin/env python3
"""Compares two stores of the Pi service (SQLite) that replayed the same log: every data
table must hold the same number of rows with the same values (every column, in row order).
The service's bookkeeping (sessions and their times, the forwarder's cursor) is left out:
it records when the replay ran, not what the car sent.

Usage: compare_stores.py REFERENCE.sqlite OTHER.sqlite
"""

import hashlib
import sqlite3
import sys

BOOKKEEPING = {"sessions", "session_rows", "forward_cursor", "forward_set_aside"}
# Tables kept one row per key and added to with every commit: the order rows were first
# written follows the writer's batches, which follow timing, so they compare in key order.
KEY_ORDER = {"session_messages": "session_id, bus, message"}


def tables(db):
    names = db.execute(
        "SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%'"
    ).fetchall()
    return sorted(n for (n,) in names if n not in BOOKKEEPING)


def summary(db, table):
    """Row count and a digest of every row's values (repr keeps floats exact)."""
    digest = hashlib.sha256()
    count = 0
    order = KEY_ORDER.get(table, "rowid")
    for row in db.execute(f'SELECT * FROM "{table}" ORDER BY {order}'):
        digest.update(repr(row).encode())
        count += 1
    return count, digest.hexdigest()[:16]


def main(argv):
    if len(argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    reference, other = (sqlite3.connect(f"file:{p}?mode=ro", uri=True) for p in argv[1:])
    names = tables(reference)
    if names != tables(other):
        print(f"different tables: {names} / {tables(other)}", file=sys.stderr)
        return 1
    failures = 0
    total = 0
    print(f"{'table':<24} {'rows':>8} {'rows':>8}  values")
    for name in names:
        (count_a, digest_a), (count_b, digest_b) = summary(reference, name), summary(other, name)
        same = count_a == count_b and digest_a == digest_b
        failures += not same
        total += count_a
        print(f"{name:<24} {count_a:>8} {count_b:>8}  {'equal' if same else 'DIFFERENT'}")
    if total == 0:
        print("the reference store holds no rows", file=sys.stderr)
        return 1
    if failures:
        print(f"{failures} table(s) differ", file=sys.stderr)
        return 1
    print(f"{len(names)} tables, {total} rows: equal")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
