#!/usr/bin/python3
"""ctest sweep_unit: launch/py/sweep.py without a simulator. Commas split values only at bracket
depth 0 and outside quotes; --vary parsing and its errors; seeds; the run plan is the product of
the --vary lists (first slowest) times the seeds (fastest), with the fixed overrides first.
Usage: check_sweep_unit.py LAUNCH_PY_DIR
"""
import sys

sys.dont_write_bytecode = True
sys.path.insert(0, sys.argv[1])
import sweep  # noqa: E402

fails = []


def check(cond, what):
    if not cond:
        fails.append(what)


def raises(fn, *args):
    try:
        fn(*args)
    except sweep.SweepError as ex:
        return str(ex)
    return None


check(sweep.split_values("1,2,3") == ["1", "2", "3"], "plain values")
check(sweep.split_values("[1,1,2],[2,2,2]") == ["[1,1,2]", "[2,2,2]"], "lists keep their commas")
check(sweep.split_values("[[1,2],[3]], 4") == ["[[1,2],[3]]", "4"], "nested lists")
check(sweep.split_values('"a,b",c') == ['"a,b"', "c"], "quoted strings keep their commas")
check(sweep.split_values("{a=1,b=2},x") == ["{a=1,b=2}", "x"], "inline tables keep their commas")
check(sweep.split_values("1e-3") == ["1e-3"], "one value")
check(raises(sweep.split_values, "[1,2") is not None, "an unclosed bracket is an error")
check(raises(sweep.split_values, "1],2") is not None, "a stray closing bracket is an error")
check(sweep.parse_vary("dem.specimen.replicate=[1,1,2],[2,2,2]") ==
      ("dem.specimen.replicate", ["[1,1,2]", "[2,2,2]"]), "parse_vary with lists")
check(sweep.parse_vary("stage.penetrate.inertial_number = 1e-3, 1e-2") ==
      ("stage.penetrate.inertial_number", ["1e-3", "1e-2"]), "parse_vary trims")
check("expected KEY=V1,V2" in (raises(sweep.parse_vary, "dem.damping") or ""), "no '=' in --vary")
check("empty value" in (raises(sweep.parse_vary, "dem.damping=0.1,,0.2") or ""), "an empty value in --vary")
check(sweep.parse_seeds("3") == [1, 2, 3] and sweep.parse_seeds("2-4") == [2, 3, 4] and
      sweep.parse_seeds("5,1-2") == [1, 2, 5], "seeds")
check(raises(sweep.parse_seeds, "4-2") is not None and raises(sweep.parse_seeds, "0") is not None, "bad seeds")

plan = sweep.plan_runs([("a.x", ["1", "2"]), ("stage.s.steps", ["10", "20", "30"])], [7, 8], ["o.t=false"])
check(len(plan) == 12, "2 x 3 x 2 runs: %d" % len(plan))
check([p["run"] for p in plan] == list(range(1, 13)), "runs numbered from 1")
check(plan[0]["sets"] == ["o.t=false", "a.x=1", "stage.s.steps=10", "run.seed=7"], "sets of run 1: %s" % plan[0]["sets"])
check(plan[1]["sets"][-1] == "run.seed=8" and plan[1]["keys"] == plan[0]["keys"], "seeds vary fastest")
check(plan[2]["keys"] == {"a.x": "1", "stage.s.steps": "20"}, "then the last --vary")
check(plan[6]["keys"] == {"a.x": "2", "stage.s.steps": "10"}, "the first --vary slowest")
check(len({tuple(p["sets"]) for p in plan}) == 12, "every run different")
noseed = sweep.plan_runs([("a.x", ["1", "2"])], None)
check(len(noseed) == 2 and noseed[0]["seed"] is None and noseed[0]["sets"] == ["a.x=1"], "without seeds")
check(sweep.main(["--vary", "a=1"]) == 2, "no scene: exit 2")
check(sweep.main([__file__, "--jobs", "0", "--vary", "a=1"]) == 2, "--jobs 0: exit 2")

if fails:
    print("FAIL:\n  " + "\n  ".join(fails))
    sys.exit(1)
print("sweep_unit: all checks passed")
