"""What the bench scripts beside this file share (ghost_coeff.py, fit_costs.py): the bench_dist
binary of a build folder and the environment its mpirun runs in (launch/run's defaults: one host,
loopback; as root, Open MPI's consent)."""
import os
import sys


def bench_dist(build, script):
    """The bench_dist of `build`, or exit naming `script` and the folder."""
    exe = os.path.join(build, "bin", "bench_dist")
    if not os.access(exe, os.X_OK):
        sys.exit(f"{script}: no bench_dist at {exe} (--build DIR)")
    return exe


def mpi_env(**extra):
    """os.environ with `extra` and Open MPI's one-host settings (kept where the caller set them)."""
    env = dict(os.environ, **extra)
    for k, v in (("OMPI_MCA_btl", "self,vader"), ("OMPI_MCA_btl_vader_single_copy_mechanism", "none"),
                 ("OMPI_MCA_oob_tcp_if_include", "lo")):
        env.setdefault(k, v)
    if os.geteuid() == 0:
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env
