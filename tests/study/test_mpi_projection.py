#!/usr/bin/python3
"""bench/mpi/project.py: the fit recovers a known per-grain cost from
scaling rows (oversubscribed rows left out), and the projection counts
grains, ghosts and the network terms as its model says, refusing slabs
thinner than a cell column.

usage: test_mpi_projection.py CASE"""
import csv
import math
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "bench", "mpi"))

import project  # noqa: E402

ALPHA, BETA, GAMMA, ALPHA_M = 1.0e-7, 3.0e-8, 2.0e-8, 1.0e-9
FIELDS = ["case", "ranks", "oversubscribed", "rank", "grains", "ghosts", "steps", "compute_s", "halo_s", "migrate_s",
          "surf_gather_s", "surf_bcast_s", "wait_s", "step_s", "wall_s", "cores", "load_avg_1min"]


def ensure(cond, what):
    if not cond:
        raise AssertionError(what)


def synthetic_csv(path):
    steps = 300
    rows = []
    for ranks, parts, over in ((1, [(20000, 0)], 0), (2, [(10100, 1500), (9900, 1500)], 0),
                               (3, [(6700, 1500), (6600, 3000), (6700, 1500)], 1)):
        for k, (g, gh) in enumerate(parts):
            slow = 5.0 if over else 1.0  # oversubscribed: the cores shared, nothing to fit on
            rows.append({"case": "bed", "ranks": ranks, "oversubscribed": over, "rank": k, "grains": g, "ghosts": gh,
                         "steps": steps, "compute_s": slow * steps * (ALPHA * g + BETA * gh),
                         "halo_s": slow * steps * GAMMA * gh, "migrate_s": steps * ALPHA_M * g,
                         "surf_gather_s": 0, "surf_bcast_s": 0, "wait_s": 0, "step_s": 0, "wall_s": 1, "cores": 2,
                         "load_avg_1min": 0.1})
    rows.append(dict(rows[0], case="paper", compute_s=1.0))  # another case: not read
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        w.writerows(rows)


def fit_known_costs():
    path = os.path.join(tempfile.mkdtemp(), "mpi_scaling.csv")
    synthetic_csv(path)
    m = project.fit(project.read_rows(path, "bed"))
    ensure(m["rows"] == 3, m)
    for k, v in (("alpha", ALPHA), ("beta", BETA), ("gamma", GAMMA), ("alpha_m", ALPHA_M)):
        ensure(abs(m[k] - v) <= 1e-9 * v, (k, m[k], v))
    ensure(m["max_rel_residual"] < 1e-9, m)


def projection_counts():
    m = {"alpha": ALPHA, "beta": BETA, "gamma": GAMMA, "alpha_m": ALPHA_M}
    grains, length, cell, steps, lat, bw = 91102.0, 1.47, 0.0158, 1.18e7, 2e-6, 1.2e10
    ncols, rows = project.project(m, grains, length, cell, steps, [1, 2, 8, 93, 94, 256], lat, bw)
    ensure(ncols == 93, ncols)
    by = {r["ranks"]: r for r in rows}
    ensure("refused" in by[94] and "refused" in by[256] and "refused" not in by[93], by)
    ensure(by[1]["ghosts"] == 0 and by[1]["halo_net_s"] == 0 and abs(by[1]["speedup"] - 1) < 1e-12, by[1])
    ensure(abs(by[2]["ghosts"] - grains / 93) < 1e-9, by[2])  # one neighbour
    r = by[8]
    gh = 2 * grains / 93
    ensure(abs(r["owned"] - grains / 8) < 1e-9 and abs(r["ghosts"] - gh) < 1e-9, r)
    ensure(abs(r["compute_s"] - (ALPHA * grains / 8 + BETA * gh)) < 1e-15, r)
    net = 2 * (lat + gh / 2 * 72 / bw) + 3 * lat
    ensure(abs(r["halo_net_s"] - net) < 1e-15, (r["halo_net_s"], net))
    ensure(abs(r["wall_h"] - r["step_s"] * steps / 3600) < 1e-9, r)
    # more ranks never slower in this regime, and efficiency falls as ghosts grow against owned grains
    ensure(by[93]["speedup"] > by[8]["speedup"] > by[2]["speedup"] > 1, by)
    ensure(by[93]["efficiency"] < by[8]["efficiency"], by)


def command_line():
    tmp = tempfile.mkdtemp()
    path = os.path.join(tmp, "mpi_scaling.csv")
    synthetic_csv(path)
    out = os.path.join(tmp, "proj.csv")
    p = subprocess.run([sys.executable, os.path.join(ROOT, "bench", "mpi", "project.py"), path, "--csv", out],
                       capture_output=True, text=True)
    ensure(p.returncode == 0, p.stderr)
    ensure("refused" in p.stdout and "1e+07 grain-steps/s" in p.stdout, p.stdout)
    rows = list(csv.DictReader(open(out)))
    ensure([int(r["ranks"]) for r in rows] == [1, 8, 16, 32, 64, 128, 256], rows)
    ensure(rows[-1]["refused"] and not rows[1]["refused"] and float(rows[1]["speedup"]) > 7, rows[:2])
    p = subprocess.run([sys.executable, os.path.join(ROOT, "bench", "mpi", "project.py"), path, "--case", "none"],
                       capture_output=True, text=True)
    ensure(p.returncode != 0 and "no rows of case none" in p.stderr, p.stderr)


CASES = {f.__name__: f for f in (fit_known_costs, projection_counts, command_line)}

if __name__ == "__main__":
    CASES[sys.argv[1]]()
    print("ok   %s" % sys.argv[1])
