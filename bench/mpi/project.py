#!/usr/bin/python3
"""The DEM's time per step over MPI ranks: a model fitted to bench/mpi/run's
measurements, and its projection to a bigger scene on more ranks (issue 17
item 7). The one place of this analysis.

Model, per step and rank (dem_mpi.c: slabs of cell columns along x, each
rank's ghosts the grains of the one column beside each of its sides):

  compute = alpha * owned + beta * ghosts   (fitted: the rows of every rank
            count that did not oversubscribe the cores, least squares;
            alpha: one owned grain's step, beta: a ghost's share of its
            pairs)
  halo    = measured here: gamma * ghosts (shared memory, fitted on the
            rows with 2+ ranks); on a cluster: per step two neighbour
            exchanges of the ghosts' state (GHOST_BYTES each) at the given
            latency and bandwidth, and the agreed rebuild decision, an
            allreduce of log2(P) latencies
  migrate = the measured share per owned grain (grains change slabs at
            rebuilds; alpha_m * owned)

Projection of a scene of N grains spread over a road of length L along x
with cells of width h (cell >= 2 r_max + skin): ncols = L / h columns,
owned = N / P, ghosts = 2 N / ncols (one column each side, one for the end
ranks: the model takes the inner ranks, the slowest), and P <= ncols: slabs
cannot be thinner than one column (dem_mpi refuses more ranks). Balanced
slabs are assumed (dem_mpi moves the boundaries with the grain counts).
What is not modelled: the surface reduction onto rank 0 (the coupled case's
surf_gather_s and surf_bcast_s columns measure it on the paper scene), the
FEM side (rigid in the second paper's scene: microseconds per exchange), the
hardware's cache effects when N / P fits a core's cache (faster: the model is
conservative there) and the network's contention.

usage: project.py SCALING_CSV [--case bed] [--grains 91102] [--length 1.47]
                  [--cell 0.0158] [--steps 1.18e7] [--ranks 1 8 16 32 64 128 256]
                  [--latency 2e-6] [--bandwidth 1.2e10] [--csv OUT]
Defaults: the second paper's faithful scene (scenes/zhao_zang_full.cfg):
91 102 grains over 1.47 m of road (the window's behind + ahead), 6-7 mm
grains with the 0.3 r_min skin (cells of 15.8 mm), 1.56 m of travel at
omega 0.5 rad/s and 30 % slip (16.7 s + ~1 s of sinking at dt 1.5e-6 s:
1.18e7 steps); an InfiniBand-class network (2 us, 12 GB/s).
"""
import argparse
import csv
import math
import sys

import numpy as np

GHOST_BYTES = 8 * 9  # position, velocity, angular velocity: dem_mpi.c's HALO_REC doubles per ghost


def read_rows(path, case):
    rows = []
    with open(path) as f:
        for r in csv.DictReader(f):
            if r["case"] != case:
                continue
            rows.append({k: (float(v) if k not in ("case",) else v) for k, v in r.items()})
    if not rows:
        raise SystemExit("project: %s has no rows of case %s" % (path, case))
    return rows


def fit(rows):
    """alpha, beta (s per grain-step: owned, ghost), gamma (s per ghost-step of halo, shared memory),
    alpha_m (s per owned grain-step of migration) from the rows that did not oversubscribe."""
    good = [r for r in rows if r["oversubscribed"] == 0]
    if not good:
        raise SystemExit("project: every row oversubscribed the cores: nothing to fit")
    a = np.array([[r["grains"], r["ghosts"]] for r in good])
    c = np.array([r["compute_s"] / r["steps"] for r in good])
    if np.all(a[:, 1] == 0):  # one rank only: no ghost term
        alpha, beta = float(np.sum(c * a[:, 0]) / np.sum(a[:, 0] ** 2)), 0.0
    else:
        (alpha, beta), *_ = np.linalg.lstsq(a, c, rcond=None)
    multi = [r for r in good if r["ghosts"] > 0]
    gamma = float(np.mean([r["halo_s"] / r["steps"] / r["ghosts"] for r in multi])) if multi else math.nan
    alpha_m = float(np.mean([r["migrate_s"] / r["steps"] / r["grains"] for r in good]))
    resid = [float(alpha * r["grains"] + beta * r["ghosts"] - r["compute_s"] / r["steps"]) for r in good]
    return {"alpha": float(alpha), "beta": float(beta), "gamma": gamma, "alpha_m": alpha_m,
            "rows": len(good), "max_rel_residual": max(abs(e) / (r["compute_s"] / r["steps"])
                                                      for e, r in zip(resid, good))}


def step_row(m, p, grains, ncols, latency, bandwidth):
    """The model's time per step on p ranks: {ranks, owned, ghosts, compute_s, halo_shm_s, halo_net_s,
    migrate_s, step_s} (inner ranks: two columns of ghosts, one for two ranks, none alone)."""
    owned = grains / p
    ghosts = 0.0 if p == 1 else (2.0 if p > 2 else 1.0) * grains / ncols
    compute = m["alpha"] * owned + m["beta"] * ghosts
    halo_shm = 0.0 if p == 1 else m["gamma"] * ghosts
    halo_net = 0.0 if p == 1 else 2 * (latency + ghosts / 2 * GHOST_BYTES / bandwidth) + \
        math.ceil(math.log2(p)) * latency
    migrate = m["alpha_m"] * owned
    return {"ranks": p, "owned": owned, "ghosts": ghosts, "compute_s": compute, "halo_shm_s": halo_shm,
            "halo_net_s": halo_net, "migrate_s": migrate, "step_s": compute + halo_net + migrate}


def project(m, grains, length, cell, steps, ranks, latency, bandwidth):
    """Rows of step_row with wall_h, speedup and efficiency (against one rank), or {ranks, refused} where
    slabs would be thinner than a column."""
    ncols = int(length / cell)
    serial = step_row(m, 1, grains, ncols, latency, bandwidth)["step_s"]
    out = []
    for p in ranks:
        if p > ncols:
            out.append({"ranks": p, "refused": "more ranks than the %d cell columns along x" % ncols})
            continue
        row = step_row(m, p, grains, ncols, latency, bandwidth)
        row.update(wall_h=row["step_s"] * steps / 3600, speedup=serial / row["step_s"])
        row["efficiency"] = row["speedup"] / p
        out.append(row)
    return ncols, out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scaling_csv")
    ap.add_argument("--case", default="bed")
    ap.add_argument("--grains", type=float, default=91102)
    ap.add_argument("--length", type=float, default=1.47)
    ap.add_argument("--cell", type=float, default=0.0158)
    ap.add_argument("--steps", type=float, default=1.18e7)
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 8, 16, 32, 64, 128, 256])
    ap.add_argument("--latency", type=float, default=2e-6)
    ap.add_argument("--bandwidth", type=float, default=1.2e10)
    ap.add_argument("--csv", help="write the projection here")
    a = ap.parse_args(argv)
    m = fit(read_rows(a.scaling_csv, a.case))
    print("fit on %d rows of %s (case %s): alpha %.3g s per owned grain-step (%.3g grain-steps/s), beta %.3g s "
          "per ghost, halo %.3g s per ghost (shared memory), migration %.3g s per owned grain-step; largest "
          "residual %.1f %% of a row's compute" % (m["rows"], a.scaling_csv, a.case, m["alpha"], 1 / m["alpha"],
                                                   m["beta"], m["gamma"], m["alpha_m"],
                                                   100 * m["max_rel_residual"]))
    ncols, rows = project(m, a.grains, a.length, a.cell, a.steps, a.ranks, a.latency, a.bandwidth)
    print("projection: %d grains over %.2f m (%d columns of %.1f mm), %.3g steps, network %.1f us / %.3g GB/s:"
          % (a.grains, a.length, ncols, 1e3 * a.cell, a.steps, 1e6 * a.latency, a.bandwidth / 1e9))
    cols = ["ranks", "owned", "ghosts", "compute_s", "halo_net_s", "halo_shm_s", "migrate_s", "step_s", "wall_h",
            "speedup", "efficiency", "refused"]
    for r in rows:
        if "refused" in r:
            print("  %4d ranks: refused (%s)" % (r["ranks"], r["refused"]))
        else:
            print("  %4d ranks: %8.0f owned %6.0f ghosts, step %.3g s (compute %.3g, halo %.3g), %.2f h, speedup "
                  "%.1f, efficiency %.2f" % (r["ranks"], r["owned"], r["ghosts"], r["step_s"], r["compute_s"],
                                             r["halo_net_s"], r["wall_h"], r["speedup"], r["efficiency"]))
    if a.csv:
        with open(a.csv, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=cols)
            w.writeheader()
            for r in rows:
                w.writerow({k: r.get(k, "") for k in cols})
    return 0


if __name__ == "__main__":
    sys.exit(main())
