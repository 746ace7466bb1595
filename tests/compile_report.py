"""Summarise ``REMIDI_TEST_COMPILE_REPORT`` output: per test file, the slowest tests, and the
programs compiled more than once (by several workers or files, where the persistent cache could
not share them: the same program compiled at the same time, or below its time threshold).

Usage: ``python tests/compile_report.py DIR [N]`` (N: how many tests to list, default 25).
"""

import json
import sys
from collections import defaultdict
from pathlib import Path


def main(folder: str, top: int = 25) -> None:
    rows = [json.loads(line) for f in sorted(Path(folder).glob("*.jsonl")) if not f.name.endswith(".programs.jsonl")
            for line in open(f)]
    files = defaultdict(lambda: defaultdict(float))
    for r in rows:
        entry = files[r["test"].split("::")[0]]
        for key in ("wall_s", "compile_s", "trace_s", "compiles"):
            entry[key] += r[key]
        entry["tests"] += 1
    total = {k: sum(e[k] for e in files.values()) for k in ("wall_s", "compile_s", "trace_s", "compiles")}
    print(f"{len(rows)} tests: wall {total['wall_s']:.0f} s, XLA compile {total['compile_s']:.0f} s "
          f"({total['compiles']:.0f} programs), tracing {total['trace_s']:.0f} s\n")
    print(f"{'file':40s} {'tests':>5s} {'wall s':>7s} {'compile s':>9s} {'programs':>8s} {'trace s':>7s}")
    for name, e in sorted(files.items(), key=lambda kv: -kv[1]["wall_s"]):
        print(f"{name:40s} {e['tests']:5.0f} {e['wall_s']:7.1f} {e['compile_s']:9.1f} {e['compiles']:8.0f} {e['trace_s']:7.1f}")
    print(f"\nslowest {top} tests:")
    for r in sorted(rows, key=lambda r: -r["wall_s"])[:top]:
        print(f"  {r['wall_s']:6.1f} s  compile {r['compile_s']:5.1f} s ({r['compiles']:3d})  {r['test']}")
    programs = [json.loads(line) for f in sorted(Path(folder).glob("*.programs.jsonl")) for line in open(f)]
    by_key = defaultdict(list)
    for prog in programs:
        by_key[prog["key"]].append(prog)
    repeated = sorted(((sum(p["compile_s"] for p in ps[1:] if not p["hit"]), ps) for ps in by_key.values()
                       if sum(not p["hit"] for p in ps) > 1), key=lambda x: -x[0])
    print(f"\nprograms compiled more than once: {len(repeated)}, "
          f"{sum(w for w, _ in repeated):.0f} s of compiling beyond the first; the largest:")
    for wasted, ps in repeated[:top]:
        files = sorted({p["test"].split("::")[0].split("/")[-1] for p in ps if not p["hit"]})
        print(f"  {wasted:6.1f} s  {sum(not p['hit'] for p in ps)}x {ps[0]['name'][:40]:40s} {', '.join(files)}")


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 25)
