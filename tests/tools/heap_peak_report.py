#!/usr/bin/env python3
"""Reads the output of tests/tools/heap_peak.c and prints the large blocks alive at the peak, grouped
by the call path into the executable (function names from `nm -C`), largest group first.
    python3 tests/tools/heap_peak_report.py build/bin/monolith peak.txt [frames]"""
import bisect
import subprocess
import sys
from collections import defaultdict


def symbols(binary):
    out = subprocess.run(["nm", "-C", "--defined-only", "-n", binary], capture_output=True,
                         text=True, check=True).stdout
    addrs, names = [], []
    for line in out.splitlines():
        parts = line.split(" ", 2)
        if len(parts) == 3 and parts[1] in "tTwW":
            addrs.append(int(parts[0], 16))
            names.append(parts[2])
    return addrs, names


def short(name):
    # drop template arguments and parameter lists: "monolith::foo<3>(...)" -> "foo"
    depth, out = 0, []
    for ch in name:
        if ch in "<(":
            depth += 1
        elif ch in ">)":
            depth -= 1
        elif depth == 0:
            out.append(ch)
    return "".join(out).replace("monolith::", "")


def main():
    binary, path = sys.argv[1], sys.argv[2]
    frames = int(sys.argv[3]) if len(sys.argv) > 3 else 4
    addrs, names = symbols(binary)
    groups = defaultdict(lambda: [0, 0])
    header = ""
    for line in open(path):
        if line.startswith("peak"):
            header = line.strip()
            continue
        parts = line.split()
        size = int(parts[1])
        path_names = []
        for a in parts[2:]:
            i = bisect.bisect_right(addrs, int(a, 16)) - 1
            if 0 <= i and int(a, 16) - addrs[i] < 1 << 20:
                n = short(names[i])
                if n.startswith(("std::", "Eigen::", "__gnu", "operator new")):
                    continue
                if not path_names or path_names[-1] != n:
                    path_names.append(n)
            if len(path_names) >= frames:
                break
        key = " <- ".join(path_names) or "?"
        groups[key][0] += size
        groups[key][1] += 1
    print(header)
    for key, (size, count) in sorted(groups.items(), key=lambda kv: -kv[1][0]):
        print(f"{size / 2**20:9.1f} MiB {count:4d}  {key}")


if __name__ == "__main__":
    main()
