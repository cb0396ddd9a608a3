#!/usr/bin/env python3
"""Reads a heap_layout.c log: prints every block of at least 8 MB with its offset in the heap
(from the lowest block) and the first functions of its call stack, and marks each new high-water
mark (docs/benchmarks.md, issue 20, branch paper16).
    python3 tests/tools/heap_layout_report.py LOG EXECUTABLE"""
import re
import subprocess
import sys


def main():
    log, exe = sys.argv[1], sys.argv[2]
    base = None
    rows = []
    for line in open(log):
        if line.startswith('M ') and base is None and 'r--p 00000000' in line:
            base = int(line.split()[1].split('-')[0], 16)
        elif line[:1] in 'AF':
            head, stack = line.split('|')
            p = head.split()
            rows.append((p[0], int(p[1]), int(p[2], 16), [int(a, 16) for a in stack.split()]))
    inside = lambda a: base is not None and base <= a < base + 0x10000000
    addrs = sorted({a - base - 1 for r in rows for a in r[3] if inside(a)})
    out = subprocess.run(['addr2line', '-f', '-C', '-e', exe] + [hex(a) for a in addrs],
                         capture_output=True, text=True).stdout.split('\n')
    names = {a: out[2 * i] for i, a in enumerate(addrs)}
    skip = re.compile(r'Eigen|std::|aligned|conditional')
    lowest = min(r[2] for r in rows) if rows else 0
    top = 0
    for op, size, ptr, stack in rows:
        start, end = ptr - lowest, ptr - lowest + size
        frames = [re.sub(r'\(.*', '', names.get(a - base - 1, '?')).replace('monolith::', '')
                  for a in stack if inside(a)]
        frames = [f for f in frames if not skip.search(f)][:3]
        mark = ''
        if op == 'A' and end > top:
            top = end
            mark = '  <- high-water mark %.0f MB' % (top / 1e6)
        print('%s %7.1f MB at %7.1f .. %7.1f%s | %s' % (op, size / 1e6, start / 1e6, end / 1e6, mark,
                                                         ' < '.join(frames)))


if __name__ == '__main__':
    main()
