#!/usr/bin/python3
"""The terrain ladder in one chart: drawbar pull, gross traction and sinkage
against slip, and the wall time per point, for each (terrain, tire) of the
slip sweeps given (bench/slip_sweep/run's CSVs, which hold the steady means
and 95 % intervals that fem_server's statistics give).

usage: bench/post/ladder.py OUT.png [--title TEXT] LABEL=FILE.csv [LABEL=FILE.csv ...]

A CSV without a `tire` column is an elastic-tire sweep. Each LABEL names the
terrain (e.g. "DEM", "SCM calibrated"); the tire is added from the file, and
several files may share a LABEL (e.g. one sweep per slip). Each LABEL gets
its own line style, in the order given (dashed, solid, dotted, dash-dot),
each tire its marker. Points are plotted with their 95 % intervals; wall
time on a log axis.
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read(path):
    rows = []
    with open(path) as f:
        for r in csv.DictReader(f):
            if r.get("status", "ok") != "ok":
                continue
            rows.append(r)
    return rows


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    out = sys.argv[1]
    args = sys.argv[2:]
    title = "terrain ladder"
    if len(args) >= 2 and args[0] == "--title":
        title, args = args[1], args[2:]
    series = {}
    label_style, styles = {}, {}
    for arg in args:
        label, path = arg.split("=", 1)
        label_style.setdefault(label, ["--", "-", ":", "-."][len(label_style) % 4])
        for r in read(path):
            key = "%s, %s tire" % (label, r.get("tire", "elastic"))
            series.setdefault(key, []).append(r)
            styles[key] = label_style[label]
    fig, axes = plt.subplots(2, 2, figsize=(11, 8), sharex=True)
    panels = [("T_P_mean_N", "T_P_ci95_N", "drawbar pull T_P [N]", 1.0),
              ("T_H_mean_N", "T_H_ci95_N", "gross traction T_H [N]", 1.0),
              ("sinkage_mean_m", "sinkage_ci95_m", "sinkage [mm]", 1e3)]
    markers = {"elastic": "o", "rigid": "s"}
    for key in sorted(series):
        rows = sorted(series[key], key=lambda r: float(r["slip_percent"]))
        slip = [float(r["slip_percent"]) for r in rows]
        tire = "rigid" if "rigid" in key else "elastic"
        ls = styles[key]
        for ax, (col, ci, name, scale) in zip(axes.flat, panels):
            y = [scale * float(r[col]) for r in rows]
            e = [scale * float(r[ci]) for r in rows]
            ax.errorbar(slip, y, yerr=e, marker=markers[tire], ls=ls, capsize=3, label=key)
            ax.set_ylabel(name)
        axes.flat[3].plot(slip, [float(r["wall_s"]) for r in rows], marker=markers[tire], ls=ls, label=key)
    axes.flat[3].set_yscale("log")
    axes.flat[3].set_ylabel("wall time per point [s]")
    for ax in axes.flat:
        ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("slip [%]")
    axes.flat[0].axhline(0, color="k", lw=0.5)
    axes.flat[0].legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print("wrote", out)


if __name__ == "__main__":
    main()
