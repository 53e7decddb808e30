#!/usr/bin/python3
"""The ramped-slip rig's curve (wheel.slip_end; fem_server/drive.h): the
travel rows of one run's traction.csv binned by the realised slip, each bin's
traction per its own load.

usage: bench/post/ramp.py RUN_DIR [--bins N] [--out PREFIX]

Per bin of realised slip (equal widths over the ramp's range): the mean
slip, the mean vertical load W (Fz) and T_H/W, T_R/W, T_P/W (the means of
the forces over the bin divided by the bin's mean load), the sinkage (mm),
and the number of rows. Writes PREFIX.csv and PREFIX.png (default
RUN_DIR/ramp). The curve lags the steady (fixed-slip) one by about
K L ds/dx, K the slope dF/ds and L the distance the soil needs to build up
its force (test_drive.slip_ramp_lag): compare a ramp with fixed-slip runs
before trusting it, and ramp slower where they differ."""
import argparse
import csv
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import runio  # noqa: E402

TRAVEL = 1  # traction.csv's phase of the travel (runio.PHASE_NAMES)


def ramp_curve(tr, bins=10):
    """tr: traction.csv as runio.read_traction returns it. Returns a dict of
    arrays, one entry per bin that holds rows."""
    travel = tr["phase"] == TRAVEL
    s = tr["slip"][travel]
    if len(s) == 0:
        raise ValueError("no rows of the travel phase")
    edges = np.linspace(s.min(), s.max(), bins + 1)
    idx = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, bins - 1)
    out = {k: [] for k in ("slip", "load", "TH_W", "TR_W", "TP_W", "sinkage_mm", "rows")}
    for b in range(bins):
        m = idx == b
        if not np.any(m):
            continue
        W = np.mean(tr["Fz"][travel][m])
        out["slip"].append(np.mean(s[m]))
        out["load"].append(W)
        out["TH_W"].append(np.mean(tr["T_H"][travel][m]) / W)
        out["TR_W"].append(np.mean(tr["T_R"][travel][m]) / W)
        out["TP_W"].append(np.mean(tr["T_P"][travel][m]) / W)
        out["sinkage_mm"].append(1e3 * np.mean(tr["sinkage"][travel][m]))
        out["rows"].append(int(np.count_nonzero(m)))
    return {k: np.array(v) for k, v in out.items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run")
    ap.add_argument("--bins", type=int, default=10)
    ap.add_argument("--out")
    a = ap.parse_args()
    prefix = a.out or os.path.join(a.run, "ramp")
    c = ramp_curve(runio.read_traction(os.path.join(a.run, "traction.csv")), a.bins)
    cols = ["slip", "load", "TH_W", "TR_W", "TP_W", "sinkage_mm", "rows"]
    with open(prefix + ".csv", "w") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for i in range(len(c["slip"])):
            w.writerow(["%.6g" % c[k][i] for k in cols])
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(6, 6), sharex=True)
    for k, lab in (("TH_W", "T_H/W"), ("TR_W", "T_R/W"), ("TP_W", "T_P/W")):
        ax.plot(100 * c["slip"], c[k], "o-", ms=3, label=lab)
    ax.axhline(0, color="0.6", lw=0.5)
    ax.set_ylabel("traction per actual load")
    ax.legend(fontsize=8)
    bx.plot(100 * c["slip"], c["sinkage_mm"], "o-", ms=3)
    bx.set_xlabel("realised slip (%)")
    bx.set_ylabel("sinkage (mm)")
    fig.suptitle("ramped slip: %s" % os.path.basename(os.path.abspath(a.run)), fontsize=9)
    fig.tight_layout()
    fig.savefig(prefix + ".png", dpi=120)
    print("wrote %s.csv and .png" % prefix)


if __name__ == "__main__":
    main()
