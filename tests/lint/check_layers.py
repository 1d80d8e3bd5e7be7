#!/usr/bin/env python3
"""Fails when a source file includes a header of a layer or room it may not use.

The layers, lowest first: core/ (the kernel, no I/O), io/, pipeline/, then tools/,
python/ and api/ (the public C++ API) on top. Inside pipeline/, each room (a sub-folder, a static library) may use
the rooms its CMakeLists.txt links (target_link_libraries ... tetstream_pipeline_ROOM),
and the rooms those use: the map is read from the build files, so it cannot drift from
what CMake links.

Usage: check_layers.py SOURCE_ROOT
"""
import pathlib
import re
import sys

root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ".").resolve()
include = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)

rooms = {}
for cmake in sorted((root / "pipeline").glob("*/CMakeLists.txt")):
    text = cmake.read_text()
    links = re.findall(r"tetstream_pipeline_([a-z_]+)", text)
    name = cmake.parent.name
    rooms[name] = {r for r in links if r != name}


def below(room, seen=None):
    seen = set() if seen is None else seen
    for r in rooms.get(room, ()):
        if r not in seen:
            seen.add(r)
            below(r, seen)
    return seen


# What each top-level layer may include (besides itself and third-party headers).
layer_may = {"core": set(), "io": {"core"}, "pipeline": {"core", "io"},
             "tools": {"core", "io", "pipeline"}, "python": {"core", "io", "pipeline"},
             "api": {"core", "io", "pipeline"}}

problems = []
for layer, allowed in layer_may.items():
    for path in sorted((root / layer).rglob("*")):
        if path.suffix not in {".cpp", ".hpp", ".ipp", ".h"} or "build" in path.parts:
            continue
        rel = path.relative_to(root)
        for target in include.findall(path.read_text(errors="replace")):
            top = target.split("/", 1)[0]
            if top not in layer_may:
                continue  # a header of the same folder by bare name, or a library's
            if top != layer and top not in allowed:
                problems.append(f"{rel}: includes {target} ({layer}/ may not use {top}/)")
            if layer == "pipeline" and top == "pipeline":
                here, there = rel.parts[1], target.split("/")[1]
                if here not in rooms:
                    problems.append(f"{rel}: pipeline/ holds only rooms (sub-folders with a CMakeLists.txt)")
                elif there != here and there not in below(here):
                    problems.append(f"{rel}: includes {target} (pipeline/{here}/ links only "
                                    f"{', '.join(sorted(below(here))) or 'no other room'})")

for p in problems:
    print(p)
print(f"check_layers: {len(rooms)} rooms, {len(problems)} problems")
sys.exit(1 if problems else 0)
