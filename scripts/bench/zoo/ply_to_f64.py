#!/usr/bin/env python3
"""PLY vertices (x, y, z, whatever other scalar properties they carry) to a raw float64
xyz file, for the in-core CGAL peer, which reads raw files only.

    ply_to_f64.py IN.ply OUT.f64
"""
import struct
import sys

TYPES = {"char": "b", "int8": "b", "uchar": "B", "uint8": "B", "short": "h", "int16": "h",
         "ushort": "H", "uint16": "H", "int": "i", "int32": "i", "uint": "I", "uint32": "I",
         "float": "f", "float32": "f", "double": "d", "float64": "d"}


def main(src, dst):
    with open(src, "rb") as f:
        if f.readline().strip() != b"ply":
            sys.exit(f"{src}: not a PLY file")
        fmt, elements = None, []  # elements: [name, count, [(type, name)]]
        for raw in f:
            words = raw.decode("ascii").split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                elements.append([words[1], int(words[2]), []])
            elif words[0] == "property":
                if words[1] == "list":
                    sys.exit(f"{src}: list property before the vertices' end: not supported")
                elements[-1][2].append((words[1], words[2]))
            elif words[0] == "end_header":
                break
        if not elements or elements[0][0] != "vertex":
            sys.exit(f"{src}: the vertices are not the first element")
        _, count, props = elements[0]
        names = [p[1] for p in props]
        pick = [names.index(c) for c in ("x", "y", "z")]
        out = bytearray()
        if fmt == "ascii":
            for _ in range(count):
                v = f.readline().split()
                out += struct.pack("<3d", *(float(v[k]) for k in pick))
        else:
            order = "<" if fmt == "binary_little_endian" else ">"
            rec = struct.Struct(order + "".join(TYPES[p[0]] for p in props))
            data = f.read(rec.size * count)
            for v in rec.iter_unpack(data):
                out += struct.pack("<3d", *(float(v[k]) for k in pick))
    with open(dst, "wb") as g:
        g.write(out)


if __name__ == "__main__":
    main(*sys.argv[1:3])
