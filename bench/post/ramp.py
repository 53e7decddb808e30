#!/usr/bin/python3
"""The ramped-slip rig's curve (wheel.slip_end; fem_server/drive.h): the
travel rows of one run's traction.csv binned by the realised slip, each bin's
traction per its own load.

usage: bench/post/ramp.py RUN_DIR [--bins N] [--out PREFIX] [--fixed SWEEP.csv ...]

Per bin of realised slip (equal widths over the ramp's range): the mean
slip, the mean vertical load W (Fz) and T_H/W, T_R/W, T_P/W (the means of
the forces over the bin divided by the bin's mean load), the sinkage (mm),
and the number of rows. Writes PREFIX.csv and PREFIX.png (default
RUN_DIR/ramp). The curve lags the steady (fixed-slip) one by about
K L ds/dx, K the slope dF/ds and L the distance the soil needs to build up
its force (test_drive.slip_ramp_lag): compare a ramp with fixed-slip runs
before trusting it, and ramp slower where they differ.

--fixed: bench/slip_sweep CSVs of fixed-slip runs (same scene and beds) to
compare with: their points (with their 95 % intervals) go on the chart, and
PREFIX-vs-fixed.csv holds, per fixed-slip run, the ramp's curve at that slip
(linear between bin means) and the differences in units of the load."""
import argparse
import csv
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import runio  # noqa: E402

TRAVEL = 1  # traction.csv's phase of the travel (runio.PHASE_NAMES)
SLIP_TOL = 0.005  # a fixed slip this near the ramp's realised range counts as inside (its ends are reached only at the ends)


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
    out["range"] = [edges[0], edges[-1]]  # the realised slips the bins cover
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


def fixed_points(paths):
    """The ok rows of slip_sweep CSVs: slip (fraction), T_H/W, T_R/W, T_P/W
    with their 95 % half-widths, sinkage (mm) and its half-width, source."""
    rows = []
    for path in paths:
        with open(path) as f:
            for r in csv.DictReader(f):
                if r["status"] != "ok":
                    continue
                row = {"slip": float(r["slip_percent"]) / 100, "tire": r["tire"], "source": os.path.basename(path),
                       "sinkage_mm": 1e3 * float(r["sinkage_mean_m"]), "sinkage_ci": 1e3 * float(r["sinkage_ci95_m"])}
                for k in ("TH_W", "TR_W", "TP_W"):
                    name = "T_%s_per_W" % k[1]
                    row[k], row[k + "_ci"] = float(r[name]), float(r[name + "_ci95"])
                rows.append(row)
    return rows


def compare(c, fixed):
    """Per fixed-slip point inside the slips the ramp realised: the ramp's
    value there (linear between bin means; between the outermost bin's mean
    and the range's end, that bin's mean: end_bin says so, the value is then
    up to half a bin's width of slip away) and ramp - fixed, per quantity."""
    out = []
    for f in fixed:
        if not (c["range"][0] - SLIP_TOL <= f["slip"] <= c["range"][1] + SLIP_TOL):
            continue
        end_bin = not (c["slip"].min() <= f["slip"] <= c["slip"].max())
        row = {"source": f["source"], "tire": f["tire"], "slip": f["slip"], "end_bin": int(end_bin)}
        for k in ("TH_W", "TR_W", "TP_W", "sinkage_mm"):
            ramp = float(np.interp(f["slip"], c["slip"], c[k]))
            row["ramp_" + k], row["fixed_" + k], row["diff_" + k] = ramp, f[k], ramp - f[k]
        out.append(row)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run")
    ap.add_argument("--bins", type=int, default=10)
    ap.add_argument("--out")
    ap.add_argument("--fixed", nargs="*", default=[])
    a = ap.parse_args()
    prefix = a.out or os.path.join(a.run, "ramp")
    c = ramp_curve(runio.read_traction(os.path.join(a.run, "traction.csv")), a.bins)
    cols = ["slip", "load", "TH_W", "TR_W", "TP_W", "sinkage_mm", "rows"]
    with open(prefix + ".csv", "w") as f:  # (the per-bin columns; not the range)
        w = csv.writer(f)
        w.writerow(cols)
        for i in range(len(c["slip"])):
            w.writerow(["%.6g" % c[k][i] for k in cols])
    fixed = fixed_points(a.fixed)
    diffs = compare(c, fixed)
    if diffs:
        with open(prefix + "-vs-fixed.csv", "w") as f:
            w = csv.DictWriter(f, fieldnames=list(diffs[0].keys()))
            w.writeheader()
            for d in diffs:
                w.writerow({k: ("%.6g" % v if isinstance(v, float) else v) for k, v in d.items()})
        for d in diffs:
            print("slip %4.1f %% (%s, %s): ramp - fixed T_P/W %+.3f, T_H/W %+.3f, sinkage %+.1f mm%s" %
                  (100 * d["slip"], d["source"], d["tire"], d["diff_TP_W"], d["diff_TH_W"], d["diff_sinkage_mm"],
                   " (the end bin's mean)" if d["end_bin"] else ""))
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(6, 6), sharex=True)
    for k, lab in (("TH_W", "T_H/W"), ("TR_W", "T_R/W"), ("TP_W", "T_P/W")):
        line, = ax.plot(100 * c["slip"], c[k], "o-", ms=3, label=lab + " (ramp)")
        if fixed:
            ax.errorbar([100 * f["slip"] for f in fixed], [f[k] for f in fixed], yerr=[f[k + "_ci"] for f in fixed],
                        fmt="s", ms=5, mfc="none", color=line.get_color(), capsize=2,
                        label=lab + " (fixed slip, 95 %)")
    ax.axhline(0, color="0.6", lw=0.5)
    ax.set_ylabel("traction per actual load")
    ax.legend(fontsize=8)
    bx.plot(100 * c["slip"], c["sinkage_mm"], "o-", ms=3, label="ramp")
    if fixed:
        bx.errorbar([100 * f["slip"] for f in fixed], [f["sinkage_mm"] for f in fixed],
                    yerr=[f["sinkage_ci"] for f in fixed], fmt="s", ms=5, mfc="none", capsize=2, label="fixed slip")
        bx.legend(fontsize=8)
    bx.set_xlabel("realised slip (%)")
    bx.set_ylabel("sinkage (mm)")
    fig.suptitle("ramped slip: %s" % os.path.basename(os.path.abspath(a.run)), fontsize=9)
    fig.tight_layout()
    fig.savefig(prefix + ".png", dpi=120)
    print("wrote %s.csv and .png" % prefix)


if __name__ == "__main__":
    main()
