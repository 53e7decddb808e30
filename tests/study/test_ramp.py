#!/usr/bin/python3
"""The ramped-slip rig's analysis (bench/post/ramp.py) on a synthetic
traction.csv with a known traction-slip law: the binned curve recovers the
law per actual load, the rows outside the travel are left out, and fixed-slip
points are compared with the curve at their slip.

usage: test_ramp.py CASE"""
import os
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "bench", "post"))
import ramp  # noqa: E402
import runio  # noqa: E402

COLS = ["t", "phase", "x", "z", "angle", "omega", "v", "slip", "Fx", "Fy", "Fz", "My", "T_H", "T_R", "T_P",
        "contacts", "sinkage", "E_elastic", "E_kinetic", "W_dem", "W_fem"]


def law(s):
    """T_H/W, T_R/W and sinkage (m) of the synthetic soil."""
    th = 0.6 * (1 - np.exp(-s / 0.08))
    tr = -0.2 - 0.1 * s
    return th, tr, 0.03 + 0.02 * s


def write_run(d, n=20000):
    rng = np.random.default_rng(3)
    t = np.arange(n) * 1e-5
    phase = np.where(np.arange(n) < 2000, 0, 1)  # a sinkage phase first: not part of the curve
    s = np.where(phase == 1, np.linspace(-0.1, 0.6, n), 0.0)
    W = 400 + 80 * np.sin(2 * np.pi * t / 0.013)  # a load that swings (lug passage), fast against the ramp
    th, tr, sink = law(s)
    th, tr = th * W, tr * W
    th[phase == 0] = 1e6  # garbage outside the travel: must not leak into the bins
    rows = np.zeros((n, len(COLS)))
    col = {c: i for i, c in enumerate(COLS)}
    rows[:, col["t"]] = t
    rows[:, col["phase"]] = phase
    rows[:, col["slip"]] = s
    rows[:, col["Fz"]] = W
    rows[:, col["T_H"]] = th + rng.normal(0, 2.0, n)
    rows[:, col["T_R"]] = tr
    rows[:, col["T_P"]] = th + tr
    rows[:, col["sinkage"]] = sink
    with open(os.path.join(d, "traction.csv"), "w") as f:
        f.write(",".join(COLS) + "\n")
        np.savetxt(f, rows, delimiter=",", fmt="%.17g")


def recovers_law():
    with tempfile.TemporaryDirectory() as d:
        write_run(d)
        c = ramp.ramp_curve(runio.read_traction(os.path.join(d, "traction.csv")), bins=14)
        th, tr, sink = law(c["slip"])
        # a bin averages the law over its width (0.05 in slip): the curvature of
        # T_H's exponential is the largest term; 5e-3 of W bounds it here
        err = np.max(np.abs(c["TH_W"] - th)), np.max(np.abs(c["TR_W"] - tr)), np.max(np.abs(c["TP_W"] - (th + tr)))
        print("  14 bins: worst |error| T_H/W %.2e, T_R/W %.2e, T_P/W %.2e; sinkage %.2e mm" %
              (err[0], err[1], err[2], np.max(np.abs(c["sinkage_mm"] - 1e3 * sink))))
        assert c["slip"].min() > -0.1 and c["slip"].max() < 0.6 and np.sum(c["rows"]) == 18000, "bins"
        assert max(err) < 5e-3, "curve off the law: %s" % (err,)
        assert np.max(np.abs(c["sinkage_mm"] - 1e3 * sink)) < 1e-6, "sinkage"
        p = subprocess.run([sys.executable, os.path.join(ROOT, "bench", "post", "ramp.py"), d, "--bins", "14"],
                           capture_output=True, text=True)
        assert p.returncode == 0 and os.path.exists(os.path.join(d, "ramp.csv")), p.stderr
        with open(os.path.join(d, "ramp.csv")) as f:
            assert len(f.read().splitlines()) == 15, "ramp.csv rows"


def no_travel_refused():
    with tempfile.TemporaryDirectory() as d:
        with open(os.path.join(d, "traction.csv"), "w") as f:
            f.write(",".join(COLS) + "\n" + ",".join(["0"] * len(COLS)) + "\n")
        try:
            ramp.ramp_curve(runio.read_traction(os.path.join(d, "traction.csv")))
        except ValueError as e:
            assert "travel" in str(e)
            return
        raise AssertionError("a run without travel rows accepted")


def write_sweep(path, points):
    """A slip_sweep CSV (the columns ramp.py reads) of (slip, status, offset)
    points: the law's values plus offset in every traction coefficient."""
    cols = ["slip_percent", "tire", "status", "T_H_per_W", "T_H_per_W_ci95", "T_R_per_W", "T_R_per_W_ci95",
            "T_P_per_W", "T_P_per_W_ci95", "sinkage_mean_m", "sinkage_ci95_m"]
    with open(path, "w") as f:
        f.write(",".join(cols) + "\n")
        for s, status, off in points:
            th, tr, sink = law(s)
            vals = [100 * s, "elastic", status, th + off, 0.01, tr + off, 0.01, th + tr + off, 0.01, sink + 1e-3, 1e-4]
            f.write(",".join(str(v) for v in vals) + "\n")


def compares_with_fixed():
    with tempfile.TemporaryDirectory() as d:
        write_run(d)
        sweep = os.path.join(d, "slip_sweep-synthetic.csv")
        # two points off the law by a known amount, one failed run, one
        # outside the ramp's range, one inside it but beyond the last bin's
        # mean: the first two are compared, and the last with end_bin set
        write_sweep(sweep, [(0.2, "ok", 0.05), (0.4, "ok", -0.03), (0.3, "failed (exit 1)", 0.0), (0.8, "ok", 0.0),
                            (0.595, "ok", 0.0)])
        c = ramp.ramp_curve(runio.read_traction(os.path.join(d, "traction.csv")), bins=14)
        diffs = ramp.compare(c, ramp.fixed_points([sweep]))
        assert [round(x["slip"], 3) for x in diffs] == [0.2, 0.4, 0.595], diffs
        assert [x["end_bin"] for x in diffs] == [0, 0, 1], diffs
        for x, off in zip(diffs, (0.05, -0.03)):
            for k in ("TH_W", "TR_W", "TP_W"):
                assert abs(x["diff_" + k] + off) < 5e-3, (k, x)
            assert abs(x["diff_sinkage_mm"] + 1.0) < 0.05, x
        p = subprocess.run([sys.executable, os.path.join(ROOT, "bench", "post", "ramp.py"), d, "--bins", "14",
                            "--fixed", sweep], capture_output=True, text=True)
        assert p.returncode == 0, p.stderr
        with open(os.path.join(d, "ramp-vs-fixed.csv")) as f:
            assert len(f.read().splitlines()) == 4, "ramp-vs-fixed.csv rows"
        print("  " + p.stdout.strip().replace("\n", "\n  "))


CASES = {f.__name__: f for f in (recovers_law, no_travel_refused, compares_with_fixed)}

if __name__ == "__main__":
    for name in sys.argv[1:] or list(CASES):
        CASES[name]()
        print("ok   " + name)
