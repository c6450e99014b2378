#!/usr/bin/python3
"""launch/py/converge_study.py branch_source: which saved state a study variant starts from.

A fake study folder (plan.json, finished and unfinished run folders with checkpoint manifests)
stands in for real runs: variants that differ only in [[stage]] keys share the stage-end
checkpoint before the penetration of the first finished run of the same seed; a variant that
changes a key outside the stages (dem.dt_safety) does not; an unfinished or failed run, a
checkpoint without a manifest, and another seed are never used.
"""
import json
import os
import shutil
import sys
import tempfile

sys.path.insert(0, sys.argv[1])
import converge_study as cs  # noqa: E402

fails = []


def check(cond, what):
    if not cond:
        fails.append(what)


root = tempfile.mkdtemp(prefix="demfdm-converge-branch-")
try:
    rate = lambda r: {"stage:penetrate.inertial_number": r, "stage+:penetrate.damping": "0.1"}
    variants = [{"name": "rate_a", "edits": rate("1e-2")}, {"name": "rate_b", "edits": rate("1e-3")},
                {"name": "dt_04", "edits": dict(rate("1e-3"), **{"dem.dt_safety": "0.4"})}]
    with open(os.path.join(root, "plan.json"), "w") as f:
        json.dump({"variants": variants}, f)

    def run(variant, seed, checkpoints, finished=True, failed=False):
        d = os.path.join(root, variant, "seed-%d" % seed)
        for c, manifest in checkpoints:
            os.makedirs(os.path.join(d, "checkpoints", c))
            if manifest:
                open(os.path.join(d, "checkpoints", c, "manifest.txt"), "w").write("demfdm checkpoint 1\n")
        if finished:
            open(os.path.join(d, "summary.json"), "w").write("{}")
            open(os.path.join(d, "summary.txt"), "w").write("FAILED: x\n" if failed else "stage ...\n")
        return d

    d1 = run("rate_a", 1, [("replicate-3-end", True), ("gravity-460-end", True), ("penetrate-900-end", True),
                           ("penetrate-700", True)])
    got = cs.branch_source(root, rate("3.3e-4"), 1)
    check(got == os.path.join(d1, "checkpoints", "gravity-460-end"), "same group, seed 1: %s" % got)
    check(cs.branch_source(root, dict(rate("1e-3"), **{"dem.dt_safety": "0.4"}), 1) is None,
          "another dem.dt_safety must not share the gravity state")
    check(cs.branch_source(root, rate("1e-3"), 2) is None, "no finished run of seed 2")
    run("rate_a", 2, [("gravity-470-end", True)], finished=False)
    check(cs.branch_source(root, rate("1e-3"), 2) is None, "an unfinished run is not a source")
    shutil.rmtree(os.path.join(root, "rate_a", "seed-2"))
    run("rate_a", 2, [("gravity-470-end", True)], failed=True)
    check(cs.branch_source(root, rate("1e-3"), 2) is None, "a failed run is not a source")
    run("rate_b", 3, [("gravity-480-end", False), ("replicate-3-end", True)])
    got = cs.branch_source(root, rate("1e-2"), 3)
    check(got is not None and got.endswith("replicate-3-end"), "a checkpoint without manifest is skipped: %s" % got)
    d4 = run("dt_04", 4, [("gravity-490-end", True)])
    check(cs.branch_source(root, dict(rate("1e-2"), **{"dem.dt_safety": "0.4"}), 4) ==
          os.path.join(d4, "checkpoints", "gravity-490-end"), "the dt group shares its own state")
finally:
    shutil.rmtree(root, ignore_errors=True)

if fails:
    print("FAILED:\n  " + "\n  ".join(fails))
    sys.exit(1)
print("converge branch source: all checks passed")
