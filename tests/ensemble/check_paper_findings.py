#!/usr/bin/python3
"""paper_findings.py on stand-in run folders (no simulator): loads linear in displacement with a
known slope per scene and seed, so every verdict is known in advance.
- 100g_sbm: slope 1000 (1 + 0.02 e_k); 1g_sbm: the same slopes -> "not resolved" against 100 g;
- 200g_sbm: slope 500 (1 + 0.02 e_k) -> "differs", about -50 %;
- 100g_pbm: the SBM slope of the same seed times 0.8 -> paired "differs" by +25 % (SBM over PBM).
Usage: check_paper_findings.py LAUNCH_PY_DIR TESTS_ENSEMBLE_DIR"""
import os
import re
import shutil
import sys
import tempfile

sys.path.insert(0, sys.argv[1])
sys.path.insert(0, sys.argv[2])
import check_ensemble  # noqa: E402  (fake_run: a run folder as launch/run leaves it)
import paper_findings  # noqa: E402

E = [0.3, -1.1, 0.8, -0.2, 0.5]
tmp = tempfile.mkdtemp(prefix="demfdm-findings-")
ok = False
try:
    for scene, slope in [("100g_sbm", 1000.0), ("1g_sbm", 1000.0), ("200g_sbm", 500.0), ("100g_pbm", 800.0)]:
        for k, e in enumerate(E, start=1):
            check_ensemble.fake_run(os.path.join(tmp, scene, "seed-%d" % k), k, slope * (1 + 0.02 * e), 1.0)
    text = paper_findings.findings(tmp)
    rows = {l.split("|")[1].strip(): l for l in text.splitlines() if l.startswith("| ")}
    # the first-quarter mean load (column 2 after g and the peak; the stand-ins' load spike sits in the middle of the
    # stroke): verdicts against 100 g
    def col(row, i):
        return [c.strip() for c in row.split("|")[1:-1]][i]
    assert "## The same, paired by seed" in text, text
    g1, g200 = rows["1"], rows["200"]  # the paired rows (the last with that key)
    assert col(g1, 2).startswith("not resolved"), g1
    assert col(g200, 2).startswith("differs"), g200
    pct = float(re.search(r"\(([-+][0-9.]+) ±", col(g200, 2)).group(1))
    assert abs(pct + 50.0) < 3.0, ("200 g against 100 g should be about -50 %", pct)
    sbm = [l for l in text.splitlines() if l.startswith("| ") and "differs" in l and l not in (g1, g200)]
    assert sbm, text
    pct = float(re.search(r"\(([-+][0-9.]+) ±", [c.strip() for c in sbm[-1].split("|")[1:-1]][1]).group(1))
    assert abs(pct - 25.0) < 1e-6 * 100 + 0.5, ("SBM over PBM should be +25 % exactly (paired)", pct)
    assert os.path.exists(os.path.join(tmp, "findings.csv"))
    ok = True
    print("paper findings: 1 g not resolved, 200 g -50 %, SBM over PBM +25 % (paired): as built")
    print("1 passed, 0 failed")
finally:
    if ok:
        shutil.rmtree(tmp)
    else:
        print("kept", tmp)
