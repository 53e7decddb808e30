#!/usr/bin/python3
"""Peak force, contact time and rebound energy of the sphere-on-block runs
(measure.sh) against Hertz for steel on a rubber half-space; with snapshots
(measure.sh writes them every 10 us), at the force peak: the approach
(grain centre below its touching height, dem_grains.h5), the FE block's
largest displacement (fem_series.csv umax) and the contact law's own
overlap (dem_series.csv max_overlap_surface), each against Hertz's
approach for the peak force.

    analyse.py [--ring=R1,R2] RUNDIR ...

With --ring (m), also the FE's deflection local to the contact: at the
loaded node less the mean of the nodes R1-R2 away (the structure's part).
"""
import json
import math
import os
import subprocess
import sys

import numpy as np

try:
    import h5py
except ImportError:  # the peak's split is then left out
    h5py = None

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
BUILD = os.environ.get("DEMFEM_BUILD_DIR", os.path.join(ROOT, "build"))


def grain_and_surface(d):
    """(R, m, v, E*) of the run's first grain against the surface material, from the
    resolved scene (dem_server --print-config=json with the run's --set
    overrides); E* with the FE material's modulus (the surface material's
    may be the contact rule under test)."""
    scene = open(os.path.join(d, "scene.path")).read().strip()
    sets = [l.strip() for l in open(os.path.join(d, "scene.sets")) if l.strip()]
    cmd = [os.path.join(BUILD, "dem_server", "dem_server"), "--scene", scene, "--print-config=json"]
    for kv in sets:
        cmd += ["--set", kv]
    c = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    g = c["dem"]["grains"][0]
    mats = {m["name"]: m for m in c["dem"]["materials"]}
    mg = mats[g["material"]]
    r = g["radius"]
    m = mg["density"] * 4.0 / 3.0 * math.pi * r**3
    v = math.sqrt(sum(x * x for x in g["velocity"]))
    es = 1.0 / ((1 - mg["poisson"] ** 2) / mg["young"] + (1 - c["fem"]["material"]["nu"] ** 2) / c["fem"]["material"]["E"])
    return r, m, v, es


def hertz(r, m, v, es):
    """Peak force, contact time and energy of the impact on a half-space of the FE material."""
    dmax = (15.0 * m * v * v / (16.0 * es * math.sqrt(r))) ** 0.4
    return 4.0 / 3.0 * es * math.sqrt(r) * dmax**1.5, 2.943 * dmax / v, 0.5 * m * v * v


def hertz_approach(f, r, es):
    """Hertz's approach under force f, m."""
    return (9.0 * f * f / (16.0 * es * es * r)) ** (1.0 / 3.0)


GAP0 = 1e-5  # m: every scene here starts the grain this far from the surface


def split_at(d, t_peak, R):
    """(approach, FE deflection, contact overlap) in m at the snapshot nearest t_peak, or None."""
    try:
        fs = np.atleast_1d(np.genfromtxt(os.path.join(d, "fem_series.csv"), delimiter=",", names=True))
        ds = np.atleast_1d(np.genfromtxt(os.path.join(d, "dem_series.csv"), delimiter=",", names=True))
    except OSError:
        return None
    if h5py is None or len(fs) < 3 or len(ds) < 3:
        return None
    with h5py.File(os.path.join(d, "dem_grains.h5"), "r") as g:
        fr = [(g[k].attrs["time"], *g[k]["position"][0]) for k in g if k.startswith("frame_")]
        fr.sort()
        v0 = g[min(k for k in g if k.startswith("frame_"))]["velocity"][0]
    if len(fr) < 3:
        return None
    fr = np.array(fr)
    tg = fr[:, 0]
    # the distance moved along the initial velocity, less the 10 um gap the
    # scenes start the grain at
    along = (fr[:, 1:] - fr[0, 1:]) @ (v0 / np.linalg.norm(v0)) - GAP0
    k = np.argmin(np.abs(tg - t_peak))
    u = fs["umax"][np.argmin(np.abs(fs["time"] - tg[k]))]
    ov = ds["max_overlap_surface"][np.argmin(np.abs(ds["time_s"] - tg[k]))] * R
    return along[k], u, ov


def local_part(d, t_peak, ring):
    """The FE's deflection at the loaded node (largest displacement) less the
    mean deflection, along the same direction, of the nodes between ring[0]
    and ring[1] (m) from it, at the snapshot nearest t_peak: the indentation
    local to the contact, without the structure's deflection (the tire's
    ring under the grain's force). Returns (local, ring mean) in m."""
    with h5py.File(os.path.join(d, "fem.h5"), "r") as f:
        x0 = f["mesh/points0"][:]
        st = f["steps"]
        k = min(st, key=lambda k: abs(st[k].attrs["time"] - t_peak))
        u = st[k]["displacement"][:]
    i = np.argmax(np.linalg.norm(u, axis=1))
    n = u[i] / np.linalg.norm(u[i])
    r = np.linalg.norm(x0 - x0[i], axis=1)
    band = (r >= ring[0]) & (r <= ring[1])
    far = float(np.mean(u[band] @ n))
    return float(u[i] @ n) - far, far


def main():
    args, ring = sys.argv[1:], None
    if args and args[0].startswith("--ring="):
        ring = [float(q) for q in args.pop(0)[7:].split(",")]
    for d in args:
        R, m, v, es = grain_and_surface(d)
        fh, th, e_in = hertz(R, m, v, es)
        print(f"Hertz (R {1e3 * R:g} mm, {v:g} m/s, E* {es:.4g} Pa): peak {fh:.2f} N, contact time {1e3 * th:.3f} ms, "
              f"input energy {e_in:.4g} J")
        try:
            t = np.atleast_1d(np.genfromtxt(os.path.join(d, "traction.csv"), delimiter=",", names=True))
            s = np.atleast_1d(np.genfromtxt(os.path.join(d, "dem_series.csv"), delimiter=",", names=True))
        except OSError as e:
            print(f"{d}: no results ({e})")
            continue
        f = np.sqrt(t["Fx"] ** 2 + t["Fy"] ** 2 + t["Fz"] ** 2)  # the grain's force on the surface
        on = f > 1e-3 * f.max()
        dt = t["t"][1] - t["t"][0]
        ended = t["t"][-1] > 1.2 * th and not on[-1]
        print(f"{d}: peak {f.max():.2f} N ({f.max() / fh - 1:+.1%}), contact time {1e3 * on.sum() * dt:.3f} ms "
              f"({on.sum() * dt / th - 1:+.1%}), up to {int(t['contacts'].max())} contacts, "
              f"rebound energy {s['ke_trans_J'][-1] / e_in:.3f} of the input{'' if ended else ' (run did not finish)'}")
        sp = split_at(d, t["t"][np.argmax(f)], R)
        if sp:
            dh = hertz_approach(f.max(), R, es)
            print(f"  at the peak: approach {1e3 * sp[0]:.4f} mm = contact overlap {1e3 * sp[2]:.4f} mm + FE block "
                  f"under the contact {1e3 * (sp[0] - sp[2]):.4f} mm (largest FE displacement {1e3 * sp[1]:.4f} mm); "
                  f"Hertz's approach for {f.max():.2f} N: {1e3 * dh:.4f} mm (approach {sp[0] / dh:.0%}, contact "
                  f"{sp[2] / dh:.0%}, FE {(sp[0] - sp[2]) / dh:.0%} of it)")
            if ring:
                loc, far = local_part(d, t["t"][np.argmax(f)], ring)
                print(f"  the FE's deflection local to the contact: {1e3 * loc:.4f} mm ({loc / dh:.0%} of Hertz's "
                      f"approach) above the mean of the nodes {1e3 * ring[0]:g}-{1e3 * ring[1]:g} mm away, "
                      f"{1e3 * far:.4f} mm")


if __name__ == "__main__":
    main()
