#!/usr/bin/env python3
"""Reports import cycles between a crate's modules.

Each file under SRC is a module (`a/b.rs` and `a/b/mod.rs` are `a::b`); every path in it
(in `use` lines or inline) that starts at `crate::`, `super::` (any number of them) or
`self::` is an edge to the longest module that path names, `super` and `self` resolved from
the module's own place. A module's children belong to it: an edge from `a::b` to `a` is a
child using its parent's items, not a cycle, and so is one from `a` to `a::b`. Usage:
import_cycles.py SRC [SRC...]; exits 1 and prints the cycle if one exists.
"""
import re
import sys
from pathlib import Path


def modules(src: Path) -> dict[str, Path]:
    found = {}
    for path in src.rglob("*.rs"):
        parts = list(path.relative_to(src).with_suffix("").parts)
        if parts[-1] == "mod":
            parts.pop()
        if parts in (["lib"], ["main"]) or "bin" in parts:
            continue
        found["::".join(parts)] = path
    return found


IDENT = r"[a-z_][a-z0-9_]*"
# A path's start (`crate::`, `self::`, `super::super::`...) and the rest of it, or a group.
START = r"\b(crate::|self::|(?:super::)+)"


def resolve(module: str, start: str) -> list[str]:
    """The segments a path's start stands for, seen from `module`."""
    if start == "crate::":
        return []
    own = module.split("::") if module else []
    if start == "self::":
        return own
    ups = start.count("super::")
    return own[: max(len(own) - ups, 0)]


def paths_in(text: str, module: str) -> list[list[str]]:
    found = []
    for start, rest in re.findall(START + rf"((?:{IDENT}::)*{IDENT})", text):
        found.append(resolve(module, start) + rest.split("::"))
    # `use crate::{a, b::c}` / `use super::{a, b}` groups: expand one level.
    for start, group in re.findall(START + r"\{([^}]*)\}", text):
        base = resolve(module, start)
        for item in group.split(","):
            item = item.strip().split(" ")[0]
            if item and item not in ("self", "*"):
                found.append(base + item.split("::"))
    return found


def edges(src: Path) -> dict[str, set[str]]:
    mods = modules(src)
    graph = {name: set() for name in mods}
    for name, path in mods.items():
        # Comments and doc links are not imports.
        text = re.sub(r"//.*", "", path.read_text(encoding="utf-8"))
        for segments in paths_in(text, name):
            for end in range(len(segments), 0, -1):
                target = "::".join(segments[:end])
                if target in mods:
                    related = name.startswith(target + "::") or target.startswith(name + "::")
                    if target != name and not related:
                        graph[name].add(target)
                    break
    return graph


def cycle(graph: dict[str, set[str]]):
    state = {}
    stack = []

    def visit(node):
        state[node] = "open"
        stack.append(node)
        for next_node in sorted(graph[node]):
            if state.get(next_node) == "open":
                return stack[stack.index(next_node):] + [next_node]
            if next_node not in state:
                found = visit(next_node)
                if found:
                    return found
        state[node] = "done"
        stack.pop()
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def main() -> int:
    failed = False
    for src in map(Path, sys.argv[1:]):
        graph = edges(src)
        found = cycle(graph)
        if found:
            print(f"{src}: import cycle: {' -> '.join(found)}")
            failed = True
        else:
            count = sum(len(targets) for targets in graph.values())
            print(f"{src}: {len(graph)} modules, {count} imports, no cycle")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
