#!/usr/bin/python3
"""Ensemble statistics over runs of one scene on independently settled beds
(./run SCENE --seeds N): the one place of this analysis.

Each run's summary.json (fem_server/fem_summary.c) gives per quantity the
mean over its steady part and the 95 % half-width of that mean from the
run's own time scatter. Over N runs (seeds):

* ensemble mean m = average of the run means;
* its 95 % interval t_{N-1} s / sqrt(N), s the standard deviation of the run
  means. The run means scatter by the bed-to-bed differences AND by each
  run's finite averaging, so s (and the interval) includes both;
* the within-run part: the rms of the runs' own standard errors
  (half_width / 1.96), w; the bed-to-bed part: b^2 = max(s^2 - w^2, 0).
  Whichever is larger dominates;
* seeds for a target half-width h: N >= (t s / h)^2 (t of the needed N,
  iterated); if the within-run part dominates, longer travel helps more than
  seeds.

A modelling choice against a base (--against BASE_RUN...): run i of both
lists on the same bed (the same seed, matched by folder name: ./run --seeds
writes seed1..N), so the difference d_i = variant_i - base_i cancels the
bed's own effect, which dominates the scatter of either ensemble alone:

* mean difference over the beds, 95 % interval t_{N-1} s_d / sqrt(N), s_d
  the standard deviation of the d_i (what is left: each run's averaging and
  how the choice interacts with the bed);
* "resolved" when the interval excludes zero, "within the noise" otherwise;
  and the unpaired interval (both ensembles' half-widths in quadrature) for
  what the same seeds would give unpaired.

A run may also be given as a row of bench/slip_sweep's result file (which
holds the same statistics, copied from each run's summary.json): FILE.csv
(a file of one row) or FILE.csv@SLIP[,TIRE] (the row of that slip in
percent, tire "elastic" unless given). Such runs are paired in the order
given (the file does not say which bed it ran on).

usage: ensemble.py RUN... [--target Q=H ...] [--against BASE_RUN...] [--json OUT]
   e.g. ensemble.py out/default/seed1 out/default/seed2 out/default/seed3 --target T_P_per_W=0.02
        ensemble.py out/rigid-seeds/seed{1,2,3} --against out/default-seeds/seed{1,2,3}
        ensemble.py res/slip_sweep-rigid-seed{1,2,3}.csv@5 --against res/slip_sweep-base-seed{1,2,3}.csv@5
"""
import argparse
import csv
import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402

import runio  # noqa: E402

REPORTED = ("T_H", "T_R", "T_P", "load", "sinkage", "T_H_per_W", "T_R_per_W", "T_P_per_W", "sinkage_per_R",
            "static_sinkage")


def t95(dof):
    """Two-sided 95 % Student t quantile (the table of fem_server/steady.c, one source for both)."""
    table = (math.inf, 12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
             2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
             2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042)
    if dof < 1:
        return math.inf
    return table[dof] if dof <= 30 else 1.960 + 2.4 / dof


def seeds_needed(sd, target, start=2):
    """Smallest N with t_{N-1} sd / sqrt(N) <= target (None if sd or target unusable)."""
    if not (sd >= 0 and target > 0):
        return None
    if sd == 0:
        return 2
    n = max(2, start)
    while n < 100000:
        if t95(n - 1) * sd / math.sqrt(n) <= target:
            return n
        n += 1
    return None


def ensemble(means, half_widths):
    """Statistics of one quantity over runs: means[i] and half_widths[i] (95 %) of run i."""
    x = np.asarray(means, dtype=float)
    h = np.asarray(half_widths, dtype=float)
    n = len(x)
    out = {"runs": n, "mean": float(x.mean()) if n else math.nan}
    if n < 2:
        out.update(half_width=math.inf, sd_between_runs=math.nan, within_run_se=math.nan, bed_to_bed_sd=math.nan,
                   dominant="unknown (one run)")
        return out
    s = float(x.std(ddof=1))
    w = float(np.sqrt(np.mean((h / 1.96) ** 2)))
    b = math.sqrt(max(s * s - w * w, 0.0))
    out.update(half_width=t95(n - 1) * s / math.sqrt(n), sd_between_runs=s, within_run_se=w, bed_to_bed_sd=b,
               dominant="bed-to-bed scatter" if b >= w else "within-run time scatter")
    return out


def iid_interval(values):
    """(mean, 95 % half-width) of independent samples (e.g. sparse snapshots)."""
    e = ensemble(values, [0.0] * len(values))
    return e["mean"], e["half_width"]


def analyse(summaries, targets=None):
    """{quantity: ensemble stats} over the runs' summaries (dicts of summary.json)."""
    targets = targets or {}
    res = {}
    for q in REPORTED:
        rows = [s["quantities"][q] for s in summaries if s.get("travelled") and q in s.get("quantities", {})]
        if not rows:
            continue
        e = ensemble([r["mean"] for r in rows], [r["half_width"] for r in rows])
        e["unit"] = rows[0].get("unit", "")
        if q in targets:
            e["target_half_width"] = targets[q]
            e["seeds_needed"] = seeds_needed(e["sd_between_runs"], targets[q]) if e["runs"] >= 2 else None
        res[q] = e
    return res


def paired(variant, base):
    """{quantity: paired difference stats} of two lists of summaries, run i of both on the same bed."""
    if len(variant) != len(base):
        raise ValueError("paired comparison: %d runs against %d base runs" % (len(variant), len(base)))
    res = {}
    for q in REPORTED:
        pairs = [(v["quantities"][q], b["quantities"][q]) for v, b in zip(variant, base)
                 if v.get("travelled") and b.get("travelled") and q in v.get("quantities", {})
                 and q in b.get("quantities", {})]
        if len(pairs) < 2:
            continue
        d = np.array([v["mean"] - b["mean"] for v, b in pairs])
        n = len(d)
        hw = t95(n - 1) * float(d.std(ddof=1)) / math.sqrt(n)
        ev = ensemble([v["mean"] for v, _ in pairs], [v["half_width"] for v, _ in pairs])
        eb = ensemble([b["mean"] for _, b in pairs], [b["half_width"] for _, b in pairs])
        res[q] = {"pairs": n, "difference": float(d.mean()), "half_width": hw,
                  "unpaired_half_width": math.hypot(ev["half_width"], eb["half_width"]),
                  "variant_mean": ev["mean"], "base_mean": eb["mean"],
                  "resolved": bool(abs(float(d.mean())) > hw), "unit": pairs[0][0].get("unit", "")}
    return res


def report_paired(res, out=sys.stdout):
    out.write("against the base, paired by bed (variant - base, 95 %% intervals over %d beds):\n"
              % max([e["pairs"] for e in res.values()] or [0]))
    for q, e in res.items():
        out.write("  %-14s %+12.5g %-2s +- %-10.3g (unpaired +- %.3g): %s\n" % (
            q, e["difference"], e["unit"] if e["unit"] != "1" else "", e["half_width"], e["unpaired_half_width"],
            "resolved" if e["resolved"] else "within the noise"))


# slip_sweep's columns (bench/slip_sweep/run COLUMNS) of each reported
# quantity: mean, 95 % half-width, unit
SWEEP_COLUMNS = {"T_H": ("T_H_mean_N", "T_H_ci95_N", "N"), "T_R": ("T_R_mean_N", "T_R_ci95_N", "N"),
                 "T_P": ("T_P_mean_N", "T_P_ci95_N", "N"), "load": ("Fz_mean_N", "Fz_ci95_N", "N"),
                 "sinkage": ("sinkage_mean_m", "sinkage_ci95_m", "m"),
                 "T_H_per_W": ("T_H_per_W", "T_H_per_W_ci95", "1"), "T_R_per_W": ("T_R_per_W", "T_R_per_W_ci95", "1"),
                 "T_P_per_W": ("T_P_per_W", "T_P_per_W_ci95", "1")}


def is_sweep_row(arg):
    return arg.partition("@")[0].endswith(".csv")


def load_sweep_row(arg):
    """A summary (as summary.json's) from a slip_sweep result row: FILE.csv[@SLIP[,TIRE]]."""
    path, _, sel = arg.partition("@")
    if not os.path.exists(path):
        raise SystemExit("ensemble: %s: no such file" % path)
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if sel:
        slip, _, tire = sel.partition(",")
        try:
            slip = float(slip)
        except ValueError:
            raise SystemExit("ensemble: %s: expected FILE.csv@SLIP[,TIRE], SLIP in percent" % arg)
        rows = [r for r in rows if abs(float(r["slip_percent"]) - slip) < 1e-9 and r.get("tire", "elastic") == (tire or "elastic")]
    if len(rows) != 1:
        raise SystemExit("ensemble: %s: %d rows match; name one with FILE.csv@SLIP[,TIRE]" % (arg, len(rows)))
    r = rows[0]
    if r["status"] != "ok":
        return {"travelled": False, "quantities": {}}
    q = {}
    for name, (mean, half, unit) in SWEEP_COLUMNS.items():
        try:
            q[name] = {"mean": float(r[mean]), "half_width": float(r[half]), "unit": unit}
        except (KeyError, ValueError):
            raise SystemExit("ensemble: %s: column %s or %s missing or not a number" % (arg, mean, half))
    return {"travelled": True, "quantities": q}


def load_summaries(dirs):
    out = []
    for d in dirs:
        if is_sweep_row(d):
            out.append(load_sweep_row(d))
            continue
        p = os.path.join(d, "summary.json")
        if not os.path.exists(p):
            raise SystemExit("ensemble: %s has no summary.json (the run failed or is still running)" % d)
        with open(p) as f:
            out.append(with_static_sinkage(json.load(f)))
    return out


def with_static_sinkage(s):
    """The summary with its set-down sinkage (summary.json's set_down, the
    sinkage when the travel began) as the quantity "static_sinkage": one
    value per run, no interval of its own (its interval is the beds')."""
    sd = runio.set_down(s) if s.get("travelled") else None
    if sd is not None:
        s.setdefault("quantities", {})["static_sinkage"] = {"mean": sd[1], "half_width": 0.0, "unit": "m"}
    return s


def report(res, out=sys.stdout):
    out.write("ensemble over %d runs (independently settled beds); 95 %% intervals include the bed-to-bed "
              "scatter:\n" % max([e["runs"] for e in res.values()] or [0]))
    for q, e in res.items():
        line = "  %-14s %12.5g %-2s +- %-10.3g (bed-to-bed sd %.3g, within-run se %.3g: %s dominates)" % (
            q, e["mean"], e["unit"] if e["unit"] != "1" else "", e["half_width"], e["bed_to_bed_sd"],
            e["within_run_se"], e["dominant"])
        if "target_half_width" in e:
            line += "; +-%g needs %s seeds" % (e["target_half_width"], e["seeds_needed"])
        out.write(line + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", help="run folders (summary.json) or slip_sweep rows FILE.csv[@SLIP[,TIRE]]")
    ap.add_argument("--target", action="append", default=[], help="QUANTITY=HALF_WIDTH, e.g. T_P_per_W=0.02")
    ap.add_argument("--json", help="write the result here")
    ap.add_argument("--against", nargs="+", metavar="BASE_RUN",
                    help="base runs on the same beds, in the same order (folder names must match pairwise)")
    a = ap.parse_args(argv)
    if a.against:
        if len(a.against) != len(a.runs):
            ap.error("--against: %d base runs for %d runs" % (len(a.against), len(a.runs)))
        for r, b in zip(a.runs, a.against):
            if is_sweep_row(r) or is_sweep_row(b):
                continue  # result rows: paired in the order given
            rn, bn = os.path.basename(os.path.normpath(r)), os.path.basename(os.path.normpath(b))
            if rn != bn:
                ap.error("--against: %s and %s are not the same bed (folder names %s and %s differ)" % (r, b, rn, bn))
    targets = {}
    for t in a.target:
        k, _, v = t.partition("=")
        try:
            targets[k] = float(v)
        except ValueError:
            ap.error("--target %s: expected QUANTITY=NUMBER" % t)
    summaries = load_summaries(a.runs)
    res = analyse(summaries, targets)
    report(res)
    out = {"runs": a.runs, "quantities": res}
    if a.against:
        diff = paired(summaries, load_summaries(a.against))
        report_paired(diff)
        out.update(against=a.against, difference=diff)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
