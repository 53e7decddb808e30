#!/usr/bin/python3
"""The second paper's test beside its reported results (Zhao & Zang, figs. 9-10).

usage: bench/post/zhao_zang.py RUNDIR [RUNDIR ...] --out OUT.png [--label TEXT ...]

Each RUNDIR is a run of scenes/zhao_zang.cfg (or a variant) at one slip.
Draws, against the wheel's travel (x from where the travel phase began):
  - the sinkage (traction.csv), with the paper's reading at 30 % slip: a
    steady ~45 mm after ~200 mm of travel (fig. 10; read from the text, the
    figure's scatter is not in hand), and the fem_server's steady mean with
    its 95 % interval (summary.json) where the run finished its travel
    (summary.json's travel_completed; an interrupted run's summary averages
    whatever part it had);
  - the drawbar pull T_P (traction.csv), a running mean over 50 mm;
  - the terrain replacements: where dem_series.csv's grain count drops (the
    rear cut of the window), as vertical lines.
Every figure comes from the run's own outputs; nothing is recomputed but the
running mean drawn.
"""
import argparse
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import runio  # noqa: E402

PAPER_SINKAGE_M = 0.045      # fig. 10, 30 % slip: "the mean is about 45 mm"
PAPER_SETTLED_AFTER_M = 0.2  # "after 200 mm of travel the sinkage is nearly steady"


def replacements(run_dir):
    """Times at which the grain count dropped (a rear cut), from
    dem_series.csv (time_s, grains)."""
    path = os.path.join(run_dir, "dem_series.csv")
    if not os.path.exists(path):
        return []
    t, n = [], []
    with open(path) as f:
        for r in csv.DictReader(f):
            t.append(float(r["time_s"]))
            n.append(float(r["grains"]))
    return [t[k] for k in range(1, len(n)) if n[k] < n[k - 1]]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument("--label", action="append", default=[])
    a = ap.parse_args()
    fig, (ax_z, ax_p) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for k, run in enumerate(a.runs):
        tr = runio.read_traction(os.path.join(run, "traction.csv"))
        travel = tr["phase"] >= 1
        if not travel.any():
            print(f"{run}: the wheel never reached the travel phase", file=sys.stderr)
            continue
        x0 = tr["x"][travel][0]
        x = tr["x"][travel] - x0
        label = a.label[k] if k < len(a.label) else os.path.basename(os.path.normpath(run))
        line, = ax_z.plot(x, 1e3 * tr["sinkage"][travel], lw=0.8, label=label)
        w = max(1, int(round(np.searchsorted(x, 0.05))))
        tp = np.convolve(tr["T_P"][travel], np.ones(w) / w, mode="same")
        ax_p.plot(x, tp, lw=0.8, color=line.get_color(), label=label)
        s = runio.read_summary(run)  # None while the run is still going
        finished = bool(s and s.get("travel_completed", (tr["phase"] == 2).any()))  # key: fem_server since session 9
        if not finished:
            line.set_label(label + " (stopped at %.2f m)" % x[-1])
        if finished and "sinkage" in s["stats"]:
            st = s["stats"]["sinkage"]
            ax_z.axhspan(1e3 * (st.mean - st.half_width), 1e3 * (st.mean + st.half_width),
                         color=line.get_color(), alpha=0.2)
        t = tr["t"]
        for tc in replacements(run):
            xc = np.interp(tc, t, tr["x"]) - x0
            if xc > 0:
                for ax in (ax_z, ax_p):
                    ax.axvline(xc, color=line.get_color(), ls=":", lw=0.8)
    ax_z.hlines(1e3 * PAPER_SINKAGE_M, PAPER_SETTLED_AFTER_M, 1.56, colors="k", lw=2,
                label="Zhao & Zang, 30 % slip: ~45 mm after 200 mm")
    ax_z.set_ylabel("sinkage [mm]")
    ax_z.legend(fontsize=8)
    ax_z.grid(alpha=0.3)
    ax_p.set_ylabel("drawbar pull T_P [N], 50 mm running mean")
    ax_p.set_xlabel("travel [m] (dotted: terrain replacements)")
    ax_p.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(a.out, dpi=120)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
