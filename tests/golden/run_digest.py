#!/usr/bin/python3
"""Digest of a run folder's CSV files, the golden data of a whole run (issue 15 item 1).

A restructure must keep the paper scenes' histories byte for byte. Their runs take minutes, so
they are a command, not a test:

  launch/run scenes/default.toml --run-dir /tmp/default-now
  /usr/bin/python3 tests/golden/run_digest.py compare /tmp/default-now tests/golden/data/default_scene.golden
  /usr/bin/python3 tests/golden/run_digest.py write RUN_DIR GOLDEN     # only for a deliberate change of physics

The digest has the format of tests/stability/determinism_test.cpp (which holds the reduced coupled
footing's): per CSV file (sorted by name) its size, line count and FNV-1a 64 of the bytes, then
every 200th line and the last line in full, so that a difference can be located. `compare` exits 0
when the digests are equal, else 1 and prints the first differing lines.
"""
import os
import sys


def fnv1a64(data):
    h = 0xcbf29ce484222325
    for c in data:
        h ^= c
        h = (h * 0x100000001b3) & 0xFFFFFFFFFFFFFFFF
    return h


def digest(run_dir, title):
    names = sorted(n for n in os.listdir(run_dir) if n.endswith(".csv"))
    out = ["# demfdm golden data: the CSV files of %s" % title,
           "# (tests/golden/run_digest.py): size, lines, FNV-1a 64, every 200th line and the last"]
    for n in names:
        data = open(os.path.join(run_dir, n), "rb").read()
        lines = data.decode().split("\n")
        if lines and lines[-1] == "":
            lines.pop()
        out.append("file %s bytes %d lines %d fnv1a64 %016x" % (n, len(data), len(lines), fnv1a64(data)))
        for i, l in enumerate(lines):
            if i % 200 == 0 or i + 1 == len(lines):
                out.append("%s:%d %s" % (n, i + 1, l))
    return "\n".join(out) + "\n"


def main(argv):
    if len(argv) != 4 or argv[1] not in ("compare", "write"):
        print(__doc__.strip().split("\n\n")[1], file=sys.stderr)
        print("usage: run_digest.py compare|write RUN_DIR GOLDEN", file=sys.stderr)
        return 2
    mode, run, gold = argv[1:]
    if not os.path.isdir(run):
        print("run_digest: no run folder %s" % run, file=sys.stderr)
        return 2
    if mode == "write":
        title = os.path.basename(os.path.normpath(run))
        if os.path.exists(gold):
            title = open(gold).readline().split("the CSV files of ", 1)[-1].strip() or title
        open(gold, "w").write(digest(run, title))
        print("run_digest: wrote %s" % gold)
        return 0
    if not os.path.exists(gold):
        print("run_digest: no golden file %s" % gold, file=sys.stderr)
        return 2
    want = open(gold).read()
    title = want.split("\n", 1)[0].split("the CSV files of ", 1)[-1]
    now = digest(run, title)
    if now == want:
        print("run_digest: %s matches %s byte for byte" % (run, gold))
        return 0
    a, b = want.split("\n"), now.split("\n")
    shown = 0
    for i in range(max(len(a), len(b))):
        x = a[i] if i < len(a) else "<end of file>"
        y = b[i] if i < len(b) else "<end of digest>"
        if x != y:
            print("line %d:\n  golden: %s\n  now:    %s" % (i + 1, x[:300], y[:300]))
            shown += 1
            if shown == 6:
                break
    return 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))
