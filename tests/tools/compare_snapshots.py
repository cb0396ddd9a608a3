#!/usr/bin/env python3
"""compare_snapshots.py A B [--ignore KEY]...

Compares two snapshots of tests/tools/snapshot.sh file by file: pictures and other files byte for
byte, stats.jsonl and summary.json as JSON without what depends on the machine or the moment (wall
times: `timing`, keys naming seconds, wall or cpu time, memory, threads, build and version).
`--ignore KEY` also leaves out a key wherever it stands (e.g. a statistic one side adds).
Prints `identical N different N missing N`, the differing files, and the runs of A that did not
exit 0; exit status 0 when nothing differs or is missing, 1 otherwise, 2 for bad arguments.
"""
import json
import os
import sys

MACHINE_WORDS = ("second", "wall", "timing", "memory", "rss", "thread", "build", "version", "cpu", "host", "date")
# bookkeeping of a snapshot folder, not results (COMMIT: a note of the commit it was taken on)
SKIPPED_FILES = ("rc.txt", "DONE", "scenes.txt", "COMMIT")


def strip(value, ignored):
    if isinstance(value, dict):
        return {k: strip(v, ignored) for k, v in value.items()
                if k not in ignored and not any(w in k for w in MACHINE_WORDS)}
    if isinstance(value, list):
        return [strip(v, ignored) for v in value]
    return value


def load(path, ignored):
    if path.endswith(".jsonl"):
        with open(path) as f:
            return [strip(json.loads(line), ignored) for line in f if line.strip()]
    if path.endswith(".json"):
        with open(path) as f:
            return strip(json.load(f), ignored)
    with open(path, "rb") as f:
        return f.read()


def main(argv):
    args, ignored = [], set()
    i = 0
    while i < len(argv):
        if argv[i] == "--ignore" and i + 1 < len(argv):
            ignored.add(argv[i + 1])
            i += 2
        else:
            args.append(argv[i])
            i += 1
    if len(args) != 2 or not all(os.path.isdir(a) for a in args):
        print(__doc__.strip().splitlines()[0], file=sys.stderr)
        return 2
    a, b = args
    same = 0
    differ, missing = [], []
    for root, _, files in os.walk(a):
        for name in sorted(files):
            if name in SKIPPED_FILES or name.endswith((".stdout", ".stderr", ".mckpt")):
                continue
            rel = os.path.relpath(os.path.join(root, name), a)
            other = os.path.join(b, rel)
            if not os.path.exists(other):
                missing.append(rel)
            elif load(os.path.join(a, rel), ignored) == load(other, ignored):
                same += 1
            else:
                differ.append(rel)
    print(f"identical {same} different {len(differ)} missing {len(missing)}")
    for rel in differ:
        print("  differs", rel)
    for rel in missing:
        print("  missing", rel)
    rc_file = os.path.join(a, "rc.txt")
    if os.path.exists(rc_file):
        with open(rc_file) as f:
            failed = [line.strip() for line in f if line.strip() and not line.strip().endswith(" rc 0")]
        if failed:
            print("runs of A that did not exit 0:", ", ".join(failed))
    return 0 if not differ and not missing else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
