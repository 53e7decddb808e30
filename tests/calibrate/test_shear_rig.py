#!/usr/bin/python3
"""The direct shear rig (bench/calibrate/shear_rig) against closed forms, with
real processes through the launcher (./run SCENE --fem shear_rig).

frozen_block_friction: the rig's lid, servo-controlled to sigma_n and slid
  along x over a bed whose every grain is frozen (tests/calibrate/scenes/
  shear_frozen.cfg): every contact slides at its Coulomb limit on a
  horizontal plate, so tau / sigma_n is the pair's friction coefficient,
  (0.5 + 0.3) / 2 = 0.4, in every exchange once the springs have saturated
  (after 0.5 mm of the 3 mm slide); asserted to 1e-9.
servo_holds_stress: in the same run the servo holds sigma_n = 5 kPa within
  0.5 % over the whole slide, and the shear phase is reached and covers the
  requested 3 mm (the rig ends the run itself).
keys_checked: a misspelt fem.shear key, a lid wider than the box and a lid
  that starts below the shear plane are refused before any segment exists,
  with a message naming the key.

usage: test_shear_rig.py BUILD_DIR CASE"""
import csv
import os
import shutil
import subprocess
import sys
import tempfile

from rigtest import bad_keys_refused, ensure

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENE = os.path.join(ROOT, "tests", "calibrate", "scenes", "shear_frozen.cfg")
MU_PAIR = 0.4
SIGMA = 5.0e3


def run_frozen(build):
    """Runs the frozen-bed scene to its end (the launcher returns when both
    processes have exited) and returns the rig's rows."""
    out = tempfile.mkdtemp(prefix="demfem-shear-")
    env = dict(os.environ, DEMFEM_NO_BUILD="1", DEMFEM_BUILD_DIR=build)
    rig = os.path.join(build, "bench", "calibrate", "shear_rig")
    with open(os.path.join(out, "run.log"), "w") as log:
        rc = subprocess.run([os.path.join(ROOT, "run"), SCENE, "--fem", rig, "--out", out], stdout=log,
                            stderr=subprocess.STDOUT, env=env, timeout=900).returncode
    if rc != 0:
        sys.stdout.write(open(os.path.join(out, "run.log")).read())
    ensure(rc == 0, "the run failed (exit %d), log in %s/run.log" % (rc, out))
    with open(os.path.join(out, "shear_box.csv")) as f:
        rows = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]
    shutil.rmtree(out)  # kept only when the run failed
    return rows


def frozen_block_friction(build):
    rows = [r for r in run_frozen(build) if r["phase"] == 2 and r["displacement"] > 0.0005]
    ensure(len(rows) > 100, "only %d rows past 0.5 mm of sliding" % len(rows))
    worst = max(abs(r["shear_force"] / r["normal_force"] - MU_PAIR) for r in rows)
    print("  %d exchanges sliding, max |tau/sigma - mu| = %.3g" % (len(rows), worst))
    ensure(worst < 1e-9, "tau/sigma_n off mu = %g by %g" % (MU_PAIR, worst))
    ensure(all(r["contacts"] >= 1 for r in rows), "the lid lost the grains")


def servo_holds_stress(build):
    rows = run_frozen(build)
    shear = [r for r in rows if r["phase"] == 2]
    ensure(shear, "the shear phase was never reached")
    travel = shear[-1]["displacement"]
    ensure(abs(travel - 0.003) < 1e-4, "sheared %g m, not the 3 mm asked" % travel)
    worst = max(abs(r["normal_stress"] - SIGMA) / SIGMA for r in shear)
    print("  %d exchanges shearing, max |sigma - sigma_n| / sigma_n = %.3g" % (len(shear), worst))
    ensure(worst < 5e-3, "the servo let sigma_n stray by %.3g %%" % (100 * worst))
    # the phases follow each other and never go back
    phases = [r["phase"] for r in rows]
    ensure(phases == sorted(phases) and phases[0] == 0, "phases out of order")


def keys_checked(build):
    rig = os.path.join(build, "bench", "calibrate", "shear_rig")
    bad_keys_refused(rig, SCENE, ((["fem.shear.normal_stres=1e4"], "normal_stres"),
                                  (["fem.shear.lid_clearance=0.03"], "lid_clearance"),
                                  (["fem.shear.walls=true", "fem.shear.lid_start_z=0.005"], "lid_start_z")))


CASES = {f.__name__: f for f in (frozen_block_friction, servo_holds_stress, keys_checked)}

if __name__ == "__main__":
    build = sys.argv[1]
    for name in sys.argv[2:] or list(CASES):
        CASES[name](build)
        print("ok   " + name)
