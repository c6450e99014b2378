#!/usr/bin/env python3
"""Weak-scaling projection of the DEM on MPI ranks (docs/scaling.md, issue 17 item 5).

A cost model per step and rank, fed with figures measured by bench_dist on this machine (the
defaults below, each named with where it was measured) and a stated network model (Hockney:
a message of m bytes costs alpha + m / beta). Bricks are cubes of n balls at the packing's
density; the ghost shell is the halo 2 R_max + skin around a brick. Prints, for each rank count,
the time per step split by part and the weak-scaling efficiency T(1) / T(P), for four designs:

  today: this code: the incremental exchange (measured), its records in one message to and from
         each neighbour brick (26 for cubic bricks) and one allreduce that confirms no record
         goes further (else all-to-all, not modelled: after cuts moved far); the forward
         exchange point to point; RCB cuts balanced by rcb_cuts (2,048 bins per cut; session 20,
         before it shifted cuts of a brick grid); ghosts integrated; the walls' sums gathered on
         rank 0.
  order-free: today with run.order_free_sums (session 20): the walls' sums folded on every
         rank, a maximum-allreduce of one double and a sum-allreduce of four per wall value
         (the node's measurements likewise, not modelled: they are not the engine's).
  newton: order-free with dem.newton (session 23): each pair across a face computed once, on the
         owner of its lower-id ball; the ghosts' forces and torques sent back to their owners
         after the pass (a reverse message of 48 bytes per ghost to each neighbour brick, every
         step); since session 27 the ghosts in rows of their own, not integrated (the motion
         phase loses GHOSTS_OUT_SAVED of the ghosts' modelled share; the exchange costs
         NEWTON_EXCHANGE_RATIO of newton off's).
  next:  newton's, with the walls' sums as exact (order-free) accumulators in one allreduce.
An allreduce is costed with the algorithm Open MPI 4.1.4 picks for its size and rank count
(allreduce_us; before session 26: recursive doubling with the whole vector at 2 log2 P stages).

Two sets of measured figures (--machine): "avx2", session 14 (AMD EPYC, 2 vCPUs, AVX2, the
exchange of that session), and "avx512", session 19 (AMD EPYC, 2 vCPUs, AVX-512, the exchange of
ad830ea and the rebuild of eec388e). The efficiency falls where the compute per ball is faster and the network is not.
Two workloads (--workload): "bench", the above (the strained periodic bench packing, linear law,
one rebuild per 23 steps, a fixed set of wall contacts); "footing", the default scene's
penetration measured in session 25 on the AVX2 machine (soft bond, one rebuild per 699 steps, the
interface's facet contacts and vertices growing with the block's surface, P^(2/3)).
Without --csv it also prints newton's efficiency at 64 ranks with its standard error, from those
of its two measured inputs (newton_uncertainty).
Usage: project_scaling.py [--machine avx2|avx512] [--workload bench|footing] [--network ib|ethernet]
                          [--balls N] [--newton-ghost-coeff C] [--time-per-weight X]
                          [--compute-scale F] [--csv]
"""
import argparse
import math

# Measured on an AMD EPYC, 2 vCPUs, AVX2 (session 14), bench_dist, the bench packing, linear law:
MEASURED_AVX2 = dict(
    # compute per ball-step, one rank (no exchange), strong mode, 600 steps, 3 rounds of
    # bench_dist runs (docs/scaling.md, the table of the incremental exchange): motion 0.643 ms + forces
    # 5.907 ms per step for 25,835 balls
    compute_us=(0.643 + 5.907) * 1e3 / 25835,
    motion_us=0.643 * 1e3 / 25835,
    # the pair work of the ghost pairs (computed on both sides): forces at 2 ranks 3.145 ms
    # against 5.907 / 2 ms, at 0.236 ghosts per owned ball
    ghost_pair_coeff=(3.145 / (5.907 / 2) - 1.0) / 0.236,
    # the incremental exchange at 2 ranks: 0.44-0.56 ms per step, one rebuild per 23 steps,
    # about 15,900 local balls (owned and ghosts) per rank -> 0.72 us per local ball and rebuild
    exchange_us_per_ball=0.72,
    # rebuild interval of the strained bench (26 rebuilds in 600 steps)
    steps_per_rebuild=600 / 26,
    # the exchange's messages per rebuild and neighbour brick (one each way, counted once: the
    # send overlaps the receive)
    exchange_messages=1,
    # packing density [balls / mm^3]: 25,835 balls in 3.551 x 3.551 x 1.775 mm
    density=25835 / (3.5504 * 3.5504 * 1.7752),
    # halo [mm]: 2 R_max + skin = 2 x 0.0905 + 0.0116
    halo=2 * 0.0905 + 0.0116,
    # forward record per ghost: x, v, omega (9 doubles)
    ghost_bytes=72,
    # exchange record per ball that becomes a ghost or changes owner: a whole row (about 220
    # bytes); the fraction of the ghost shell that is new at a rebuild (the strong bench: 879
    # migrations in 26 rebuilds at 2 ranks, about 34 per rebuild, and a comparable number of new
    # ghosts): 1 %
    row_bytes=220,
    new_ghost_fraction=0.01,
    # imbalance, model grid 4x4x4 over the default scene's DEM block at the end of penetration
    # (bench_dist --state, 595 balls per brick): even 1.20, shifted 1.09, RCB 1.003
    imbalance_even=1.20,
    imbalance_shift=1.09,
    imbalance_rcb=1.003,
    # RCB as the code cuts it (rcb_cuts, 2,048 bins per cut; session 20, bench_dist --state on
    # session 17's default-scene checkpoints, 4x4x4 = 64 bricks): 1.0088 at the end of gravity,
    # 1.0066 at the end of penetration; the larger is used
    imbalance_rcb_code=1.0088,
    # walls' sums on rank 0: wall contacts of the one-rank block (bench footing: 1,404 for five
    # box faces and the footing, 23,790 balls), growing with the block's surface, P^(2/3) in
    # weak scaling; root work per record (2 ranks: 0.016 ms for 1,404 records, sums and
    # broadcast); bytes per record (a plane share)
    wall_records_one=1404,
    wall_root_us=0.016e3 / 1404,
    # rank 0's ordering of the shares per share [us] against the rank count (session 20,
    # bench_dist --merge P N, 351 shares per rank at 64: order_wall_shares, merged pairwise below
    # 8 ranks, a radix order from 8); replaces wall_root_us where given. Before session 20 the
    # shares were merged into a growing front: 0.190 us per share at 64 ranks, 4.43 at 1,024
    # (the "front" column), which the flat 11 ns above did not see.
    wall_root_us_at={2: 0.0050, 4: 0.0116, 8: 0.0112, 16: 0.0125, 64: 0.0184, 256: 0.0236, 1024: 0.0390},
    wall_record_bytes=48,
    # "next": exact (order-free) accumulators per wall value, one allreduce of the sums; values
    # per step: the bench's 5 planes x 4 + footing 3 (an interface of 400 vertices adds 1,600),
    # 3 words each
    wall_values=1623,
)

# Measured on an AMD EPYC, 2 vCPUs, AVX-512 (session 19, after eec388e: the exchange of ad830ea,
# the rebuild without page faults), bench_dist, the bench packing, linear law, 600 steps, three
# rounds each (docs/scaling.md); the figures that do not depend on the machine are those above.
MEASURED_AVX512 = dict(
    MEASURED_AVX2,
    # one rank, strong: motion 0.349 ms + forces 3.163 ms per step for 25,835 balls
    compute_us=(0.349 + 3.163) * 1e3 / 25835,
    motion_us=0.349 * 1e3 / 25835,
    # two ranks, strong: forces 1.686 ms against 3.163 / 2, at 0.236 ghosts per owned ball
    ghost_pair_coeff=(1.686 / (3.163 / 2) - 1.0) / 0.2364,
    # two ranks, strong: exchange 0.187 ms per step, 26 rebuilds in 600 steps, 15,971 local balls
    # per rank (12,918 owned, 0.236 ghosts each) -> 0.27 us per local ball and rebuild
    exchange_us_per_ball=0.187e3 * (600 / 26) / 15971,
)
# `newton on`: the forces phase's coefficient per ghost per owned ball, forces = F1/P (1 + c g).
# Until session 27 it was derived from newton off's strong comparison (session 23: newton's forces
# phase 0.978, s.e. 0.006, of newton off's at 0.2364 ghosts per owned ball, so c_newton =
# (0.978 (1 + c g) - 1) / g: 0.176 on AVX2), which a halved working set and the two processes'
# sharing of the machine confound. Session 28 measured it directly in weak form with the same
# machine load on both sides (docs/scaling.md): 2 ranks, each with one copy of the bench packing
# (copies along z, cut across z: 0.2159 ghosts per owned ball), against two 1-rank runs of one
# copy at once, one per core; newton on, linear, 600 steps, 160 alternated pairs (AVX2 AMD EPYC,
# 2 vCPUs): forces phase 0.9998 (s.e. 0.0049), c = -0.001 (0.023); the pair pass 0.9810
# (0.0049), the rebuild 1.162 (0.005). The reference's periodic wraps across z (3,605 pairs of
# its 119,136) are ghost pairs at 2 ranks; the footing's block has no wraps, so the model takes
# the whole pair-pass gain as theirs: c = -0.001 + 0.088 = 0.087 (s.e. 0.023), an upper estimate.
# (Session 27's weak form across x, 80 pairs, 0.1194 ghosts per owned ball: 0.07, s.e. 0.09.)
# Session 29 ran 160 more pairs (bench/dem/ghost_coeff.py, another build): forces 0.9956 (s.e.
# 0.0036), pair pass 0.9747 (0.0036), c = -0.020 + 0.117 = 0.097 (0.017). The two sessions'
# 320 pairs, each phase's mean weighted by its inverse variance: forces 0.9971 (0.0029), pair
# pass 0.9769 (0.0029): c = (0.9971 - 0.9769) / 0.2159 = 0.093 (s.e. 0.013, the forces phase's).
# --newton-ghost-coeff overrides it (`project_scaling.py --workload footing` prints newton at 64
# ranks with the standard errors of this and of the time per weight below).
NEWTON_GHOST_COEFF = 0.093
NEWTON_GHOST_COEFF_SE = 0.013
# newton cannot balance by measured time (its results follow the cuts; time-weighted cuts differ
# from run to run), only by a deterministic weight, and what it leaves is a time per weight that
# differs between the bricks. Session 28 weighed a ball 1 plus its listed contacts (a facet contact
# 5); session 29 weighs it by the modelled cost of its contacts by kind (ContactCost in
# dem_node/dist: fitted to the per-rank phase times under five cuts). The default scene's
# penetration-end state (`bench_dist --run ... 2000 1`, order-free sums, newton on, 2 ranks, RCB
# balanced by the weight), 60 runs of each weight in alternated pairs over two builds: time
# imbalance (largest rank's compute over the mean, the noise of each run included) 1.0196 (s.e.
# 0.0019) with session 28's weights, 1.0128 (0.0017) with the costs; the ranks' compute ratio
# 1.0378 (0.0045) against 0.9995 (0.0047): the costs leave no bias that the runs resolve, so what
# is left is the runs' own noise, kept here as the time per weight (conservative). The cut is
# across depth; a time per weight that changes linearly with depth gives the two halves +-x/2 and
# the outer of four layers (a 4 x 4 x 4 grid) +-3x/4, so the newton designs multiply RCB's weight
# imbalance by 1 + 1.5 x (--time-per-weight overrides x). With the costs the modelled time of a
# brick is its weight, so RCB's 64 bricks carry the weight imbalance above in time too; session
# 28's weights cut those bricks to a modelled time imbalance of 1.078 (gravity end) and 1.092
# (penetration end) (`bench_dist --state ... 4,4,4` with BENCH_DIST_COST=1,1,1,1,5,1, its
# cost_imbalance_rcb_code; the interface's facet contacts weighed 5 and cost 9 bonded pair ends),
# where the projection had taken 1.0088 x 1.0285 = 1.038.
NEWTON_TIME_PER_WEIGHT_X = 0.0128
NEWTON_TIME_PER_WEIGHT_X_SE = 0.0017
REVERSE_BYTES = 48
# The ghosts in rows of their own, not integrated (session 27, AVX2 AMD EPYC, bench_dist linear,
# 600 steps, newton on): the motion phase against the build before, 8 alternated pairs each,
# strong (0.2364 ghosts per owned ball) 0.862 (s.e. 0.016) and weak (0.1194) 0.889 (s.e. 0.014),
# where leaving the whole modelled share out (g motion_us per ball) gives 1 / (1 + g): 0.809 and
# 0.893; and 2 ranks weak against 1 rank strong (the same balls per rank), 20 alternated pairs,
# 1.026 (s.e. 0.018) against 1.119 with the ghosts integrated. The saved fraction of the modelled
# share: 0.72 (0.08), 1.04 (0.13), 0.78 (0.15); their mean weighted by inverse variance 0.80
# (the motion phase also holds the critical step's scan, whose cost follows the contacts, not
# the rows). The exchange (its merges read the old rows and contacts in id order through merged
# index orders): 1.128 (s.e. 0.036) strong and 1.134 (0.017) weak of the build before.
GHOSTS_OUT_SAVED = 0.80
NEWTON_EXCHANGE_RATIO = 1.13
NEWTON_DESIGNS = ("newton", "next")
for _m in (MEASURED_AVX2, MEASURED_AVX512):
    _m["ghost_pair_coeff_newton"] = NEWTON_GHOST_COEFF  # (a property of the ghosts, not the machine)
    _m["time_per_weight_x"] = NEWTON_TIME_PER_WEIGHT_X
# The footing workload (session 25): the default scene's penetration, the soft-bond law, measured
# on the AVX2 AMD EPYC (2 vCPUs) with `bench_dist --run` on the default scene's penetration-end
# checkpoint (38,075 balls, 148,172 pairs, 4,828 facet contacts, 62 footing contacts; a run of
# session 21), 3,000 steps, three rounds (docs/scaling.md). The figures that are properties of
# the geometry and not of the law (the ghost pairs' coefficient, newton's saving, the records'
# bytes, the imbalance of RCB) are the bench's above: at 2 ranks the per-rank working set halves
# and the forces phase came out below half of one rank's (4.07-4.61 ms against 4.68-5.75), so a
# coefficient cannot be measured on this state.
MEASURED_FOOTING_AVX2 = dict(
    MEASURED_AVX2,
    # one rank: motion + forces 10.06 / 12.24 / 11.67 ms per step (median 11.67), motion 0.697
    compute_us=11.674e3 / 38075,
    motion_us=0.697e3 / 38075,
    # two ranks, RCB balanced by time, order-free sums: exchange 0.0247 / 0.0280 / 0.0267 ms per
    # step, 5 rebuilds in 3,000 steps, 20,279 local balls per rank (19,037 owned, 0.0652 ghosts
    # each) -> 0.79 us per local ball and rebuild (the soft bond's histories: 0.27-0.72 us for the
    # linear law)
    exchange_us_per_ball=0.0267e3 * (3000 / 5) / 20279,
    # the default scene's penetration: 67 rebuilds in 46,845 steps (the World's rebuild counter,
    # 77 at the gravity stage's end, 144 at the penetration's end)
    steps_per_rebuild=46845 / 67,
    # the block: 38,075 balls in 4 x 4 x 10 mm; halo 2 R_max + skin = 2 x 0.1368 + 0.0472 mm
    density=38075 / (4.0 * 4.0 * 10.0),
    halo=2 * 0.13677 + 0.04716,
    # walls: the interface facets and the footing of the block, 4,828 + 62 contacts for 38,075
    # balls; a block of n balls of the same shape has (n / 38,075)^(2/3) of them, a weakly scaled
    # one P^(2/3) more. FacetSumShare: 144 bytes. Rank 0 per share, everything included (its
    # shares packed, the others received, put in order, added; session 25's code at 2 ranks:
    # 0.36 ms for 4,828 shares): 75 ns, plus the ordering's growth with the rank count
    # (wall_root_us_at above, less its 2-rank 5 ns)
    wall_records_one=4828 + 62,
    wall_ref_balls=38075,
    wall_record_bytes=144,
    wall_share_root_us=0.36e3 / 4828,
    # order-free sums: each rank folds its own contacts' terms. Session 25: 0.28 ms for about 2,400
    # facet contacts on the rank that did not wait (2 ranks, bench_dist --run, BENCH_DIST_PER_RANK),
    # 0.12 us per contact. Session 27, the walls' path by its share of perf samples (wall_sum_terms,
    # the bounds, the folds: CPU only, no wait), 2 ranks on session 25's penetration-end
    # checkpoint, 2,414 facet contacts per rank: 0.196-0.215 ms per step and rank after the
    # boundaries were built from bits (28c5164), 0.232-0.288 ms before (3 alternated pairs; 0.096-
    # 0.119 us per contact, session 25's figure at its top): 0.085 us per contact. The largest rank
    # is a corner brick of the block, with three of its faces on the interface (the sides and the
    # floor; the top is free); slots: 4 per interface vertex (185 vertices) plus the totals, 746,
    # growing as the interface, P^(2/3)
    fold_us_per_contact=0.205e3 / 2414,
    wall_area_ref=4.0 * 4.0 + 4 * 4.0 * 10.0,  # [mm^2] the interface: four sides and the floor
    wall_values=746,
)
MACHINES = {"avx2": MEASURED_AVX2, "avx512": MEASURED_AVX512}
WORKLOADS = {"bench": None, "footing": MEASURED_FOOTING_AVX2}

NETWORKS = {
    # InfiniBand HDR class: 2 us latency, 10 GB/s
    "ib": dict(alpha_us=2.0, beta_gbs=10.0),
    # 10 Gigabit Ethernet with TCP: 25 us latency, 1.2 GB/s
    "ethernet": dict(alpha_us=25.0, beta_gbs=1.2),
}


def ghosts_per_ball(n, m):
    a = (n / m["density"]) ** (1.0 / 3.0)  # brick side [mm]
    h = m["halo"]
    return ((a + 2 * h) ** 3 - a ** 3) / a ** 3


def wall_root_us(P, m):
    """Rank 0's work per wall share at P ranks: the measured table, interpolated in log P."""
    tab = m.get("wall_root_us_at")
    if not tab:
        return m["wall_root_us"]
    ps = sorted(tab)
    if P <= ps[0]:
        return tab[ps[0]]
    if P >= ps[-1]:
        return tab[ps[-1]]
    for lo, hi in zip(ps, ps[1:]):
        if lo <= P <= hi:
            f = (math.log(P) - math.log(lo)) / (math.log(hi) - math.log(lo))
            return tab[lo] + f * (tab[hi] - tab[lo])


# Open MPI 4.1.4's allreduce choice for commutative operations (ompi_coll_tuned_allreduce_intra_dec_fixed):
# for communicators below each size, the first (message size limit in bytes, algorithm) whose
# limit the message is below; Rabenseifner's beyond the last. "ring" stands for the ring and the
# segmented ring alike.
OMPI_ALLREDUCE = [
    (4, [(8, "ring"), (4096, "rd"), (8192, "ring"), (16384, "rd"), (65536, "ring"), (262144, "ring")]),
    (8, [(16, "ring"), (8192, "rd")]),
    (16, [(8192, "rd")]),
    (32, [(64, "ring"), (4096, "rd")]),
    (64, [(128, "ring")]),
    (128, [(262144, "rd")]),
    (256, [(131072, "nonover"), (262144, "rd")]),
    (512, [(4096, "nonover")]),
    (2048, [(2048, "nonover"), (16384, "rd")]),
]


def allreduce_us(P, nbytes, net):
    """One MPI_Allreduce of nbytes over P ranks (a commutative operation: MPI_SUM, MPI_MAX) with
    the algorithm Open MPI 4.1.4 (Debian 12's) picks by default (coll/tuned's fixed decision,
    ompi_coll_tuned_allreduce_intra_dec_fixed, commutative branch), costed with Hockney's model:
      recursive doubling: log2 P (alpha + m / beta);
      ring and segmented ring: 2 (P - 1) (alpha + m / (P beta));
      Rabenseifner (reduce-scatter, then allgather): 2 log2 P alpha + 2 (P - 1) / P m / beta;
      nonoverlapping (a binomial reduce, then a binomial broadcast): 2 log2 P (alpha + m / beta).
    The local additions are left out (a few ns per double)."""
    a, beta = net["alpha_us"], net["beta_gbs"] * 1e3  # bytes per us
    if P <= 1:
        return 0.0
    lg = math.log2(P)
    rd = lg * (a + nbytes / beta)
    ring = 2 * (P - 1) * (a + nbytes / (P * beta))
    rab = 2 * lg * a + 2 * (P - 1) / P * nbytes / beta
    nonover = 2 * lg * (a + nbytes / beta)
    cost = dict(rd=rd, ring=ring, nonover=nonover)
    for below, table in OMPI_ALLREDUCE:
        if P < below:
            return next((cost[alg] for limit, alg in table if nbytes < limit), rab)
    return rab


def step_time(P, n, m, net, design):
    a_us, beta = net["alpha_us"], net["beta_gbs"] * 1e3  # bytes per us
    one = P == 1
    g = 0.0 if one else ghosts_per_ball(n, m)
    parts = {}
    newton = design in NEWTON_DESIGNS
    coeff = m["ghost_pair_coeff_newton"] if newton else m["ghost_pair_coeff"]
    comp = n * m["compute_us"] * (1.0 + coeff * g)
    # the ghosts' motion: integrated (newton off), or in rows of their own and left out (newton)
    comp += n * g * m["motion_us"] * ((1.0 - GHOSTS_OUT_SAVED) if newton else 1.0)
    imb = 1.0 if one else m["imbalance_rcb_code"] * ((1.0 + 1.5 * m["time_per_weight_x"]) if newton else 1.0)
    parts["compute"] = comp * imb
    if one:  # one rank: no exchange, no messages
        parts["exchange"] = parts["forward"] = parts["reduce"] = parts["walls"] = 0.0
    else:
        local = n * (1.0 + g)
        # per rebuild: the local work, one message per neighbour brick and the allreduce that
        # decides it, the rows of the new ghosts and migrants
        msgs = m["exchange_messages"] * min(26, P - 1) + 2 * math.log2(P)
        per_rebuild = (local * m["exchange_us_per_ball"] + msgs * a_us +
                       n * g * m["new_ghost_fraction"] * m["row_bytes"] / beta)
        parts["exchange"] = per_rebuild / m["steps_per_rebuild"] * (NEWTON_EXCHANGE_RATIO if newton else 1.0)
        # forward: point to point with the ranks that share ghosts (26 for cubic bricks)
        parts["forward"] = min(26, P - 1) * a_us + n * g * m["ghost_bytes"] / beta
        if newton:  # the reverse: the same messages, 48 bytes per ghost
            parts["forward"] += min(26, P - 1) * a_us + n * g * REVERSE_BYTES / beta
        parts["reduce"] = 2 * math.log2(P) * a_us  # rebuild test, recursive doubling
        # the walls' contacts and values of the one-rank block: fixed (bench), or growing with the
        # block's surface (footing: a block of n balls of the reference block's shape)
        surf = (n / m["wall_ref_balls"]) ** (2.0 / 3.0) if "wall_ref_balls" in m else 1.0
        recs = m["wall_records_one"] * surf * P ** (2.0 / 3.0)
        values = m["wall_values"] * surf * (P ** (2.0 / 3.0) if "wall_ref_balls" in m else 1.0)
        fold = 0.0
        if "fold_us_per_contact" in m:  # the largest rank's own folding: a corner brick, three faces
            a = (n / m["density"]) ** (1.0 / 3.0)
            per_mm2 = m["wall_records_one"] / m["wall_area_ref"]
            fold = 3 * a * a * per_mm2 * m["fold_us_per_contact"]
        if design == "today":
            if "wall_share_root_us" in m:  # rank 0's measured cost per share, and the ordering's growth
                root = m["wall_share_root_us"] + max(0.0, wall_root_us(P, m) - wall_root_us(2, m))
            else:
                root = wall_root_us(P, m)
            parts["walls"] = (math.log2(P) * 2 * a_us + recs * m["wall_record_bytes"] / beta + recs * root)
        elif design in ("order-free", "newton"):  # two allreduces: the bounds (maximum, 1 double per
            # value), then the folds (sum, 4 doubles per value)
            parts["walls"] = fold + allreduce_us(P, values * 8, net) + allreduce_us(P, values * 4 * 8, net)
        else:  # one allreduce of exact accumulators, 3 words per value
            parts["walls"] = fold + allreduce_us(P, values * 24, net)
    parts["total"] = sum(v for k, v in parts.items())
    return parts


def scale_compute(m, f):
    """The figures `m` on a core that computes f times as long per ball (f < 1: faster)."""
    if not f > 0.0:
        raise SystemExit(f"--compute-scale: expected a positive factor, found {f}")
    keys = ("compute_us", "motion_us", "fold_us_per_contact")
    return dict(m, **{k: m[k] * f for k in keys if k in m})


def newton_uncertainty(P, n, m, net):
    """newton's efficiency at P ranks and its standard error from those of its two measured
    inputs (the ghost coefficient, the time per weight), propagated linearly (one standard error
    each way, in quadrature)."""
    def eff(mm):
        return step_time(1, n, mm, net, "newton")["total"] / step_time(P, n, mm, net, "newton")["total"]
    e = eff(m)
    var = 0.0
    for key, se in (("ghost_pair_coeff_newton", NEWTON_GHOST_COEFF_SE), ("time_per_weight_x", NEWTON_TIME_PER_WEIGHT_X_SE)):
        down = min(se, m[key]) if key == "time_per_weight_x" else se  # (an excess below 0 means nothing)
        hi, lo = eff(dict(m, **{key: m[key] + se})), eff(dict(m, **{key: m[key] - down}))
        var += ((hi - lo) / (se + down) * se) ** 2
    return e, math.sqrt(var)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--machine", choices=sorted(MACHINES), default="avx512")
    ap.add_argument("--workload", choices=sorted(WORKLOADS), default="bench",
                    help="bench: the strained periodic bench packing, linear law (--machine's figures); "
                         "footing: the default scene's penetration, soft bond, AVX2 (session 25; --machine ignored)")
    ap.add_argument("--network", choices=sorted(NETWORKS), default="ib")
    ap.add_argument("--balls", type=int, default=25835, help="balls per rank (weak scaling)")
    ap.add_argument("--newton-ghost-coeff", type=float, default=None,
                    help="newton's ghost coefficient of the forces phase instead of the model's "
                         "%.3f (docs/scaling.md: measured in weak form, s.e. %.3f)" % (NEWTON_GHOST_COEFF, NEWTON_GHOST_COEFF_SE))
    ap.add_argument("--time-per-weight", type=float, default=None,
                    help="newton's time per weight at 2 ranks, the excess x over 1, instead of the model's "
                         "%.4f (session 29, s.e. %.4f); the newton designs multiply RCB's weight imbalance "
                         "by 1 + 1.5 x" % (NEWTON_TIME_PER_WEIGHT_X, NEWTON_TIME_PER_WEIGHT_X_SE))
    ap.add_argument("--compute-scale", type=float, default=1.0,
                    help="the compute per ball (the step's, the motion's and the walls' fold) times this: "
                         "below 1 a faster core with the same network")
    ap.add_argument("--csv", action="store_true")
    args = ap.parse_args()
    m, net = WORKLOADS[args.workload] or MACHINES[args.machine], NETWORKS[args.network]
    if args.newton_ghost_coeff is not None:
        m = dict(m, ghost_pair_coeff_newton=args.newton_ghost_coeff)
    if args.time_per_weight is not None:
        m = dict(m, time_per_weight_x=args.time_per_weight)
    m = scale_compute(m, args.compute_scale)
    what = f"machine {args.machine}" if args.workload == "bench" else "workload footing (AVX2)"
    print(f"# {what}; network {args.network}: alpha {net['alpha_us']} us, beta {net['beta_gbs']} GB/s; "
          f"{args.balls} balls per rank; ghosts per owned ball in a cubic brick: "
          f"{ghosts_per_ball(args.balls, m):.3f}")
    hdr = "design,ranks,compute_ms,exchange_ms,forward_ms,reduce_ms,walls_ms,total_ms,efficiency"
    print(hdr if args.csv else "| " + " | ".join(hdr.split(",")) + " |")
    if not args.csv:
        print("|" + "---|" * len(hdr.split(",")))
    for design in ("today", "order-free", "newton", "next"):
        t1 = step_time(1, args.balls, m, net, design)["total"]
        for P in (1, 2, 8, 64, 256, 1024):
            p = step_time(P, args.balls, m, net, design)
            row = [design, str(P)] + [f"{p[k] / 1e3:.3f}" for k in
                                      ("compute", "exchange", "forward", "reduce", "walls", "total")]
            row.append(f"{t1 / p['total']:.3f}")
            print(",".join(row) if args.csv else "| " + " | ".join(row) + " |")
    if not args.csv:  # newton at 64 ranks with the standard errors of its two measured inputs
        e, se = newton_uncertainty(64, args.balls, m, net)
        print(f"\nnewton at 64 ranks: {e:.3f} +- {se:.3f} (the standard errors of the ghost coefficient, "
              f"{NEWTON_GHOST_COEFF_SE}, and of the time per weight, {NEWTON_TIME_PER_WEIGHT_X_SE}; "
              f"the network model and the depth trend not included)")


if __name__ == "__main__":
    main()
