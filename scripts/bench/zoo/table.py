#!/usr/bin/env python3
"""The zoo's table from bench-pipeline --zoo's records (one JSON line a member).

    table.py RECORDS.jsonl MEMORY

x uniform: time over uniform's with the same number of input points, in the same run;
x CGAL: time over CGAL's in-core time on the same points (< 1: tetstream faster);
queries/pt, tested/pt: emptiness queries and points they tested, over the points;
check/build: the segments' check and kernel seconds, summed over threads;
peak: resident set (/usr/bin/time -v); held: peak <= --memory.
"""
import json
import sys

UNITS = {"K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}


def mib(budget):
    m = budget.upper().rstrip("B").rstrip("I")
    return float(m[:-1]) * UNITS[m[-1]] / 2**20 if m[-1] in UNITS else float(m) / 2**20


def main(path, memory):
    rows = [json.loads(line) for line in open(path) if line.strip()]
    uniform = {r["run"]["input_points"]: r["run"]["seconds"]["total"] for r in rows if r["member"] == "uniform"}
    budget = mib(memory)
    head = ("member", "points", "time_s", "x_unif", "cgal_s", "x_CGAL", "queries/pt", "tested/pt",
            "check/build_s", "seg", "zones", "peak_MiB", "held")
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for r in rows:
        s = r["run"]
        n, t = s["input_points"], s["seconds"]["total"]
        u = uniform.get(n)
        cg = r["cgal_s"]
        cells = (r["member"], f"{n}", f"{t:.1f}", f"{t / u:.2f}" if u else "-", f"{cg:.1f}" if cg else "-",
                 f"{t / cg:.2f}" if cg else "-", f"{s['queries'] / s['points']:.3f}", f"{s['query_points'] / s['points']:.3f}",
                 f"{s['seconds']['segments_check_summed']:.1f} / {s['seconds']['segments_build_summed']:.1f}",
                 f"{s['segments']}", f"{s['zones']}", f"{r['peak_mib']}", "yes" if r["peak_mib"] <= budget else "OVER")
        print("| " + " | ".join(cells) + " |")
    print(__doc__.split("\n\n", 2)[2].strip())


if __name__ == "__main__":
    main(*sys.argv[1:3])
