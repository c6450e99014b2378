#!/usr/bin/python3
"""launch/py/branching.py: which saved state a study run starts from.

Fake run folders (summary, checkpoint folders with and without manifest) stand in for real runs,
and a stub stands in for `coordinator SCENE --check --from=CHECKPOINT` (it accepts a checkpoint
when the scene file names it), so the selection is checked on its own: the accepted checkpoint
that saves the most steps, never the last stage of a run (nothing would be left to run), never
one of an unfinished or failed run or without a manifest, None when nothing is accepted. A study
variant's overrides reach the check (the command is the coordinator and the variant's --set
arguments, as the studies call it): a stub that accepts only with a given override. The
coordinator's own acceptance rules are tested in tests/integration/checkpoint_test.cpp and
tests/coord/checkpoint_test.cpp.
"""
import os
import shutil
import sys
import tempfile

sys.path.insert(0, sys.argv[1])
import branching  # noqa: E402

fails = []


def check(cond, what):
    if not cond:
        fails.append(what)


root = tempfile.mkdtemp(prefix="demfdm-branching-")
try:
    stub = os.path.join(root, "stub.py")
    with open(stub, "w") as f:
        f.write("import sys\nscene, arg = sys.argv[1], sys.argv[3]\n"
                "sys.exit(0 if arg.split('=', 1)[1] in open(scene).read() else 2)\n")
    coord = [sys.executable, stub]

    def run(name, checkpoints, finished=True, failed=False):
        d = os.path.join(root, name)
        for c, manifest in checkpoints:
            os.makedirs(os.path.join(d, "checkpoints", c))
            if manifest:
                open(os.path.join(d, "checkpoints", c, "manifest.txt"), "w").write("demfdm checkpoint 1\n")
        os.makedirs(d, exist_ok=True)
        if finished:
            open(os.path.join(d, "summary.json"), "w").write("{}")
            open(os.path.join(d, "summary.txt"), "w").write("FAILED: x\n" if failed else "stages:\n")
        return d

    def scene(name, accepted):
        p = os.path.join(root, name + ".toml")
        open(p, "w").write("\n".join("# " + a for a in accepted) + "\n")
        return p

    ck = lambda run_dir, c: os.path.join(run_dir, "checkpoints", c)  # noqa: E731
    a = run("a", [("replicate-3-end", True), ("gravity-460-end", True), ("penetrate-900-end", True),
                  ("penetrate-700", True)])
    b = run("b", [("replicate-3-end", True), ("gravity-470-end", True), ("penetrate-950-end", True)])
    got = branching.branch_source(coord, scene("s1", [ck(a, "gravity-460-end"), ck(b, "gravity-470-end"),
                                                      ck(a, "replicate-3-end")]), [a, b])
    check(got == ck(b, "gravity-470-end"), "the accepted checkpoint with the most steps: %s" % got)
    got = branching.branch_source(coord, scene("s2", [ck(a, "replicate-3-end")]), [a, b])
    check(got == ck(a, "replicate-3-end"), "an earlier stage when only it is accepted: %s" % got)
    got = branching.branch_source(coord, scene("s3", [ck(a, "penetrate-900-end"), ck(a, "penetrate-700")]), [a])
    check(got is None, "neither the last stage's checkpoint nor one inside a stage: %s" % got)
    check(branching.branch_source(coord, scene("s4", []), [a, b]) is None, "nothing accepted")
    u = run("u", [("replicate-3-end", True), ("gravity-480-end", True)], finished=False)
    f = run("f", [("replicate-3-end", True), ("gravity-490-end", True)], failed=True)
    n = run("n", [("replicate-3-end", True), ("gravity-499-end", False), ("penetrate-999-end", True)])
    got = branching.branch_source(coord, scene("s5", [ck(u, "replicate-3-end"), ck(f, "replicate-3-end"),
                                                      ck(n, "gravity-499-end"), ck(n, "replicate-3-end")]), [u, f, n])
    check(got == ck(n, "replicate-3-end"), "unfinished, failed and manifest-less are skipped: %s" % got)
    # The overrides of a variant go with the check: coordinator --set=... SCENE --check --from=...
    stub2 = os.path.join(root, "stub2.py")
    with open(stub2, "w") as f:
        f.write("import sys\nargs = sys.argv[1:]\nscene = [x for x in args if not x.startswith('--')][0]\n"
                "ck = [x for x in args if x.startswith('--from=')][0].split('=', 1)[1]\n"
                "ok = '--check' in args and '--set=stage.penetrate.damping=0.1' in args and ck in open(scene).read()\n"
                "sys.exit(0 if ok else 2)\n")
    s6 = scene("s6", [ck(a, "gravity-460-end")])
    got = branching.branch_source([sys.executable, stub2, "--set=stage.penetrate.damping=0.1"], s6, [a, b])
    check(got == ck(a, "gravity-460-end"), "the check with the variant's overrides: %s" % got)
    got = branching.branch_source([sys.executable, stub2, "--set=stage.penetrate.damping=0.3"], s6, [a, b])
    check(got is None, "other overrides must reach the check (refused): %s" % got)
    check(branching.stage_end_checkpoints(a) == [(900, ck(a, "penetrate-900-end")), (460, ck(a, "gravity-460-end")),
                                                 (3, ck(a, "replicate-3-end"))], "stage-end checkpoints, latest first")
finally:
    shutil.rmtree(root, ignore_errors=True)

if fails:
    print("FAILED:\n  " + "\n  ".join(fails))
    sys.exit(1)
print("branching: all checks passed")
