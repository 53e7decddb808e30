#!/usr/bin/python3
"""The tire's deflection in a coupled run, from its snapshots (fem.h5).

usage: bench/post/tire_deflection.py RUN_DIR [RUN_DIR ...] [--window DEG] [--json]

For each snapshot in the summary's steady window (summary.json
steady.start_time .. end_time), in the wheel's x-z plane about the axle
(traction.csv's x and z at the snapshot's time):
  compression  the mean, over the surface nodes touching grains (contact
               force != 0) within +-DEG (default 5) of straight below the
               axle, of how much nearer the axle each is than in the first
               snapshot without contact (the inflated tire, same node): the
               radial compression of the contact's centre;
  lowest       the outermost inflated radius (a lug tip) minus the axle's
               height above the tire's lowest point: the floor's
               definition of the deflection (bench/fem/bench_deflection),
               which on a lugged tire also moves with the lug phase.
Prints the means over the steady snapshots with their spread (sd) and count.
"""
import argparse
import csv
import json
import math
import os
import sys

import h5py
import numpy as np


def centre_at(rows, t):
    best = min(rows, key=lambda r: abs(float(r["t"]) - t))
    return float(best["x"]), float(best["z"]), float(best["t"])


def measure(run_dir, window_deg):
    summ = json.load(open(os.path.join(run_dir, "summary.json")))
    t0, t1 = summ["steady"]["start_time"], summ["steady"]["end_time"]
    rows = list(csv.DictReader(open(os.path.join(run_dir, "traction.csv"))))
    f = h5py.File(os.path.join(run_dir, "fem.h5"), "r")
    steps = sorted(f["steps"].keys())
    ref_r = None
    comp, low = [], []
    for k in steps:
        g = f["steps"][k]
        t = float(g.attrs["time"])
        pos = g["position"][:]
        fc = np.linalg.norm(g["contact_force"][:], axis=1)
        xc, zc, tr = centre_at(rows, t)
        if abs(tr - t) > 1e-3:
            continue
        dx, dz = pos[:, 0] - xc, pos[:, 2] - zc
        r = np.hypot(dx, dz)
        if ref_r is None:
            if fc.max() == 0.0:
                ref_r = r
            continue
        if not (t0 <= t <= t1):
            continue
        ang = np.degrees(np.arctan2(dx, -dz))
        sel = (fc > 0) & (np.abs(ang) < window_deg)
        if sel.sum() == 0:
            continue
        comp.append(float(np.mean(ref_r[sel] - r[sel])))
        low.append(float(ref_r.max() - (zc - pos[:, 2].min())))
    f.close()
    out = {"run_dir": run_dir, "snapshots": len(comp)}
    for name, v in (("compression_m", comp), ("lowest_m", low)):
        out[name] = float(np.mean(v)) if v else math.nan
        out[name.replace("_m", "_sd_m")] = float(np.std(v, ddof=1)) if len(v) > 1 else math.nan
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0], epilog=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dirs", nargs="+")
    ap.add_argument("--window", type=float, default=5.0)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    res = [measure(d, a.window) for d in a.run_dirs]
    if a.json:
        json.dump(res, sys.stdout, indent=1)
        print()
        return 0
    for o in res:
        print("%s: compression %.3f +- %.3f mm (sd), lowest point %.3f +- %.3f mm (sd), %d steady snapshots" % (
            o["run_dir"], 1e3 * o["compression_m"], 1e3 * o["compression_sd_m"], 1e3 * o["lowest_m"],
            1e3 * o["lowest_sd_m"], o["snapshots"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
