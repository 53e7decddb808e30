#!/usr/bin/python3
"""The calibration's test analyses (bench/calibrate/soiltests.py) on
synthetic data with known answers, and the frictionless heap through
dem_server (closed form: it spreads flat).

heap_angle_cone: grains filling a cone of 30 deg (and of 15 deg) on a
  floor, a grain-layer toe around it: the angle comes back within 2 deg.
heap_angle_flat: a single layer of grains: 0.
shear_box_synthetic: rows of a made-up shear test, tau/sigma rising to 0.8
  at 2 mm and falling to 0.6, 10 N on the upper walls, a known sample mass:
  peak (smoothed over 0.25 mm of travel) and residual against the plane's
  normal force (lid + walls + the upper grains' weight) come back to 2 % and
  1 %, the bulk density exactly.
frictionless_heap: scenes/calibrate/repose.cfg with friction and rolling
  resistance 0 settles through dem_server into a layer: angle < 3 deg
  (the calibration soil's heap stands at ~20 deg).

usage: test_soiltests.py BUILD_DIR CASE"""
import math
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "bench", "calibrate"))
import soiltests  # noqa: E402


def ensure(cond, what):
    if not cond:
        raise AssertionError(what)


def cone(angle_deg, r=0.0025, R=0.07, seed=1):
    """Grain centres in columns on a grid filling a cone of the angle over a
    one-grain toe out to 1.6 R, each column's top grain touching the cone's
    surface."""
    rng = np.random.default_rng(seed)
    d = 2 * r
    H = R * math.tan(math.radians(angle_deg))
    pts = []
    for x in np.arange(-1.6 * R, 1.6 * R, d):
        for y in np.arange(-1.6 * R, 1.6 * R, d):
            rho = math.hypot(x, y)
            top = max(H * (1 - rho / R), 0.0) + d  # the toe layer everywhere
            for z in np.arange(top - r, r - 1e-12, -d):  # a grain's top on the surface
                pts.append((x + 0.1 * r * rng.standard_normal(), y + 0.1 * r * rng.standard_normal(), z))
    x = np.array(pts)
    return x, np.full(len(x), r)


def heap_angle_cone():
    for ang in (30.0, 15.0):
        x, r = cone(ang)
        got, _ = soiltests.heap_angle(x, r, 0.0, centre=(0.0, 0.0))
        print("  cone %.0f deg: %.2f deg" % (ang, got))
        ensure(abs(got - ang) < 2.0, "cone of %g deg read as %g" % (ang, got))


def heap_angle_flat():
    x, r = cone(0.0)
    got, _ = soiltests.heap_angle(x, r, 0.0)
    ensure(got == 0.0, "a flat layer read as %g deg" % got)


def shear_box_synthetic():
    L = W = 0.05
    area = L * W
    mass, h0, lower = 0.2, 0.06, 0.025
    rows = []
    for k in range(2000):
        d = 3e-6 * k
        ratio = 0.8 * min(d / 0.002, 1.0) if d <= 0.002 else 0.8 - 0.2 * min((d - 0.002) / 0.002, 1.0)
        h = h0 + 0.2 * d
        n_lid = 1e4 * area
        wall = 10.0
        plane = n_lid + wall + mass * 9.81 * (h - lower) / h
        rows.append({"phase": 2, "displacement": d, "height": h, "normal_force": n_lid, "upper_wall_fz": wall,
                     "shear_force": ratio * plane})
    res = soiltests.shear_box(rows, mass, (L, W), lower)
    print("  peak %.4f at %.2f mm, residual %.4f, bulk density %.1f" %
          (res["peak_ratio"], 1e3 * res["peak_displacement"], res["residual_ratio"], res["bulk_density"]))
    ensure(abs(res["peak_ratio"] - 0.8) < 0.016, "peak %g, not 0.8" % res["peak_ratio"])
    ensure(abs(res["residual_ratio"] - 0.6) < 0.006, "residual %g, not 0.6" % res["residual_ratio"])
    ensure(abs(res["peak_displacement"] - 0.002) < 2.5e-4, "peak at %g m, not 2 mm" % res["peak_displacement"])
    ensure(abs(res["bulk_density"] - mass / (area * h0)) < 1e-9, "bulk density %g" % res["bulk_density"])
    ensure(abs(math.degrees(math.atan(0.2)) - res["dilatancy_angle"]) < 0.5, "dilatancy angle %g" %
           res["dilatancy_angle"])


def frictionless_heap(build):
    out = tempfile.mkdtemp(prefix="demfem-heap-")
    env = dict(os.environ, DEMFEM_NO_BUILD="1", DEMFEM_BUILD_DIR=build)
    scene = os.path.join(ROOT, "scenes", "calibrate", "repose.cfg")
    cmd = [os.path.join(ROOT, "run"), scene, "--dem-only", "--out", out,
           "--set", "dem.materials.[0].friction=0.0", "--set", "dem.materials.[0].rolling_friction=0.0",
           # frictionless grains keep sliding for seconds: stop once they are slow
           # (KE 3e-8 J/grain, ~2 cm/s), the layer is flat long before
           "--set", "dem.bed.settle_ke=3e-8",
           # 900 of the scene's 1800 grains (a column ~5 diameters high): half the time
           "--set", "dem.bed.layers.[0].count=900"]
    with open(os.path.join(out, "run.log"), "w") as log:
        rc = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, timeout=1200).returncode
    ensure(rc == 0, "the heap run failed (exit %d), log in %s/run.log" % (rc, out))
    import h5py
    with h5py.File(os.path.join(out, "dem_grains.h5"), "r") as f:
        g = f[sorted(f.keys())[0]]
        x, r = np.array(g["position"]), np.array(g["radius"])
    shutil.rmtree(out)  # kept only when the run failed
    got, prof = soiltests.heap_angle(x, r, 0.0)
    print("  frictionless heap: %.2f deg, highest ring top %.1f mm" % (got, 1e3 * np.max(prof["ring_top"])))
    ensure(got < 3.0, "a frictionless heap stands at %g deg" % got)


CASES = {f.__name__: f for f in (heap_angle_cone, heap_angle_flat, shear_box_synthetic)}

if __name__ == "__main__":
    build = sys.argv[1]
    for name in sys.argv[2:]:
        if name == "frictionless_heap":
            frictionless_heap(build)
        else:
            CASES[name]()
        print("ok   " + name)
