#!/usr/bin/python3
"""One row per coupled run: what the element comparison needs beside the
slip sweep's traction statistics (issue 16, tet10 coupled).

usage: bench/post/run_costs.py OUT.csv LABEL=RUN_DIR [LABEL=RUN_DIR ...]

Columns: label, element, seed, interface_mass_min (from the run's
scene.sets), added_mass_fraction, fem dt and dt_limit (fem_run.json),
exchanges, simulated time (traction.csv's last t), the interface works seen
by each side at the end and their gap relative to the larger (traction.csv
W_dem, W_fem), the FEM's advance and loop wall and CPU seconds
(fem_server's profile, wheel.h5's profile_<stage>_s and _cpu_s), the advance's CPU seconds per
simulated second, the run's wall time (run_info.json, slip_sweep's), and
the tire's compression under the axle and lowest-point deflection
(bench/post/tire_deflection.py) when the run reached its steady part.
"""
import csv
import json
import os
import sys

import h5py

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import tire_deflection  # noqa: E402

COLS = ["label", "element", "seed", "interface_mass_min_kg", "added_mass_fraction", "fem_dt_s", "fem_dt_limit_s",
        "exchanges", "sim_time_s", "W_dem_J", "W_fem_J", "W_gap_rel", "advance_s", "advance_cpu_s", "loop_s",
        "loop_cpu_s", "advance_cpu_per_sim_s", "run_wall_s", "compression_mm", "compression_sd_mm",
        "lowest_deflection_mm", "lowest_deflection_sd_mm", "deflection_snapshots", "exit_code", "run_dir"]


def sets_of(d):
    out = {}
    p = os.path.join(d, "scene.sets")
    if os.path.exists(p):
        for line in open(p):
            if "=" in line:
                k, v = line.strip().split("=", 1)
                out[k] = v.strip('"')
    return out


def row(label, d):
    r = {c: "" for c in COLS}
    r.update(label=label, run_dir=d)
    s = sets_of(d)
    r["element"] = s.get("fem.element", "tet4")
    r["seed"] = s.get("dem.bed.seed", "")
    r["interface_mass_min_kg"] = s.get("fem.interface_mass_min", "0")
    fr = json.load(open(os.path.join(d, "fem_run.json")))
    r["added_mass_fraction"] = "%.4g" % fr.get("added_mass_fraction", 0.0)
    r["fem_dt_s"] = "%.4g" % fr["dt"]
    r["fem_dt_limit_s"] = "%.4g" % fr.get("dt_limit", float("nan"))
    r["exchanges"] = "%d" % fr["exchanges"]
    r["exit_code"] = "%d" % fr["exit_code"]
    last = None
    for last in csv.DictReader(open(os.path.join(d, "traction.csv"))):
        pass
    t = float(last["t"])
    wd, wf = float(last["W_dem"]), float(last["W_fem"])
    r.update(sim_time_s="%.5g" % t, W_dem_J="%.6g" % wd, W_fem_J="%.6g" % wf,
             W_gap_rel="%.3g" % ((wf - wd) / max(abs(wd), abs(wf))) if max(abs(wd), abs(wf)) > 0 else "0")
    prof = {}
    with h5py.File(os.path.join(d, "wheel.h5"), "r") as w:  # fem_server's profile: attributes of "/"
        for k, v in w.attrs.items():
            if k.startswith("profile_") and k.endswith("_s"):
                prof[k] = float(v)
    if "profile_advance_cpu_s" in prof:
        stages = [k for k in prof if not k.endswith("_cpu_s")]
        r["advance_s"] = "%.1f" % prof["profile_advance_s"]
        r["advance_cpu_s"] = "%.1f" % prof["profile_advance_cpu_s"]
        r["loop_s"] = "%.1f" % sum(prof[k] for k in stages)
        r["loop_cpu_s"] = "%.1f" % sum(prof[k[:-2] + "_cpu_s"] for k in stages)
        if t > 0:
            r["advance_cpu_per_sim_s"] = "%.0f" % (prof["profile_advance_cpu_s"] / t)
    info = os.path.join(d, "run_info.json")
    if os.path.exists(info):
        r["run_wall_s"] = "%.0f" % json.load(open(info))["wall_s"]
    summ = os.path.join(d, "summary.json")
    if os.path.exists(summ) and json.load(open(summ)).get("travelled"):
        m = tire_deflection.measure(d, 5.0)
        r.update(compression_mm="%.3f" % (1e3 * m["compression_m"]),
                 compression_sd_mm="%.3f" % (1e3 * m["compression_sd_m"]),
                 lowest_deflection_mm="%.3f" % (1e3 * m["lowest_m"]),
                 lowest_deflection_sd_mm="%.3f" % (1e3 * m["lowest_sd_m"]), deflection_snapshots=str(m["snapshots"]))
    return r


def main():
    if len(sys.argv) < 3 or any("=" not in a for a in sys.argv[2:]):
        print(__doc__, file=sys.stderr)
        return 2
    rows = [row(*a.split("=", 1)) for a in sys.argv[2:]]
    with open(sys.argv[1], "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLS)
        w.writeheader()
        w.writerows(rows)
    for r in rows:
        print(", ".join("%s %s" % (c, r[c]) for c in COLS if r[c] != ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
