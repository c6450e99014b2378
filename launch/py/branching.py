#!/usr/bin/python3
"""Which saved state a study run can start from instead of from scratch.

A study runs many variants of one scene. Variants that share their first stages (the same
specimen, seed and gravity equilibrium, only a later stage or a free key differs) need not
compute them again: `launch/run SCENE [--set ...] --from CHECKPOINT` starts after a saved
stage-end state and gives the same bits as a run from scratch (docs/checkpoint-format.md).
Whether a variant may branch from a checkpoint is decided by the coordinator itself
(`coordinator SCENE --set ... --check --from=CHECKPOINT` exits 0 only when no key of the scene
with its overrides contradicts the saved state), so the studies never hold a second copy of
those rules.
"""
import os
import subprocess
import time


def finished(run_dir):
    """A run folder whose run ended normally (summary.json written, summary.txt not FAILED)."""
    if not os.path.isfile(os.path.join(run_dir, "summary.json")):
        return False
    try:
        with open(os.path.join(run_dir, "summary.txt")) as f:
            return not f.read().startswith("FAILED")
    except OSError:
        return False


def stage_end_checkpoints(run_dir):
    """[(step, path)] of the complete stage-end checkpoints of a run folder, latest first."""
    ck = os.path.join(run_dir, "checkpoints")
    out = []
    if not os.path.isdir(ck):
        return out
    for name in os.listdir(ck):
        if not name.endswith("-end") or not os.path.isfile(os.path.join(ck, name, "manifest.txt")):
            continue
        try:
            out.append((int(name[:-4].rsplit("-", 1)[1]), os.path.join(ck, name)))
        except (IndexError, ValueError):
            continue
    return sorted(out, reverse=True)


def branch_source(coordinator, scene, runs, exclude_last_stage=True):
    """The stage-end checkpoint among the finished `runs` (run folders) that `scene` may start
    from and that saves the most steps, or None. `coordinator` is the command that checks it
    (a list, e.g. [build/bin/coordinator]), followed by the variant's overrides when it has some
    ([build/bin/coordinator, "--set=KEY=VALUE", ...]: the scene with its overrides is what must
    agree with the saved state, as launch/run SCENE --from CHECKPOINT --set ... checks it). The
    checkpoint of a run's last stage is skipped when exclude_last_stage (a branch after the last
    stage would run nothing)."""
    best = None
    for run in runs:
        if not finished(run):
            continue
        cks = stage_end_checkpoints(run)
        if exclude_last_stage and cks:
            cks = cks[1:]
        for step, path in cks:
            if best is not None and step <= best[0]:
                break
            ok = subprocess.call(list(coordinator) + [scene, "--check", "--from=" + path],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) == 0
            if ok:
                best = (step, path)
                break
    return best[1] if best else None


def stop_runs(active):
    """Stops the launch/run processes of a study after Ctrl-C or SIGTERM: `active` holds
    (key, process, log file, start time) entries. After Ctrl-C the runs have the signal too;
    otherwise (SIGTERM, or SIGINT ignored in a background job) each launch/run is asked to stop
    with SIGTERM (its trap stops its own processes), then killed after 15 s. Logs are closed."""
    t_end = time.time() + 2
    for _, p, _, _ in active:
        try:
            p.wait(timeout=max(0.0, t_end - time.time()))
        except subprocess.TimeoutExpired:
            p.terminate()
    for _, p, log, _ in active:
        try:
            p.wait(timeout=15)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
        log.close()


def coordinator_command():
    """The coordinator of the build launch/run uses ($DEMFDM_BUILD/bin, else build/bin)."""
    root = os.environ.get("DEMFDM_ROOT", os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    build = os.environ.get("DEMFDM_BUILD", os.path.join(root, "build"))
    return [os.path.join(build, "bin", "coordinator")]
