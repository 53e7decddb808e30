#!/usr/bin/python3
"""The plate-sinkage rig (bench/calibrate/plate_rig) with real processes
through the launcher (./run SCENE --fem plate_rig), on a small settled bed
(tests/calibrate/scenes/plate_small.cfg).

start_gap_and_stop: with fem.plate.start_gap the plate starts that far above
  the highest grain top (the first grain frame's max z + r, read from
  dem_grains.h5, not from the rig), touches nothing before it has come down
  that far, and with fem.plate.stop_sinkage the rig ends the run at that
  sinkage below its first contact (within one exchange's travel), long
  before run.end_time.
keys_checked: a negative start_gap, a misspelt plate key and a start_z
  below the bed top plus the gap are refused naming the key.

usage: test_plate_rig.py BUILD_DIR CASE"""
import csv
import os
import shutil
import subprocess
import sys
import tempfile

from rigtest import bad_keys_refused, ensure

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENE = os.path.join(ROOT, "tests", "calibrate", "scenes", "plate_small.cfg")
GAP, STOP, SPEED, DT_EXCHANGE = 0.002, 0.004, 0.1, 1e-5


def run(build, sets=()):
    out = tempfile.mkdtemp(prefix="demfem-plate-")
    env = dict(os.environ, DEMFEM_NO_BUILD="1", DEMFEM_BUILD_DIR=build)
    cmd = [os.path.join(ROOT, "run"), SCENE, "--fem", os.path.join(build, "bench", "calibrate", "plate_rig"),
           "--out", out]
    for s in sets:
        cmd += ["--set", s]
    with open(os.path.join(out, "run.log"), "w") as log:
        rc = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, timeout=900).returncode
    with open(os.path.join(out, "run.log")) as f:
        text = f.read()
    return rc, out, text


def start_gap_and_stop(build):
    import h5py
    rc, out, text = run(build)
    if rc != 0:
        sys.stdout.write(text)
    ensure(rc == 0, "the run failed (exit %d), log in %s/run.log" % (rc, out))
    with open(os.path.join(out, "plate_sinkage.csv")) as f:
        rows = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]
    with h5py.File(os.path.join(out, "dem_grains.h5"), "r") as f:
        g = f[sorted(f.keys())[0]]
        top = float(max(x[2] + r for x, r in zip(g["position"][:], g["radius"][:])))
    z0 = rows[0]["plate_z"]
    print("  plate starts at %.6f m, bed top %.6f m + gap %.3f m; %d exchanges, last sinkage %.6f m at t %.4f s" %
          (z0, top, GAP, len(rows), rows[-1]["sinkage"], rows[-1]["t"]))
    ensure(abs(z0 - (top + GAP)) < 1e-9, "the plate starts at %.9f m, not bed top + gap %.9f m" % (z0, top + GAP))
    first = next(r for r in rows if r["contacts"] > 0)
    ensure(first["plate_z"] <= top + 1e-9, "a contact at plate height %g above the bed top %g" %
           (first["plate_z"], top))
    last = rows[-1]["sinkage"]
    ensure(STOP <= last <= STOP + 2 * SPEED * DT_EXCHANGE, "stopped at sinkage %.6g m, not at %g m" % (last, STOP))
    ensure(rows[-1]["t"] < 0.5, "the run went on to %.3f s" % rows[-1]["t"])
    shutil.rmtree(out)  # kept only when the run failed


def keys_checked(build):
    rig = os.path.join(build, "bench", "calibrate", "plate_rig")
    bad_keys_refused(rig, SCENE, ((["fem.plate.start_gap=-0.01"], "start_gap"),
                                  (["fem.plate.stop_sinkage=-1"], "stop_sinkage"),
                                  (["fem.plate.stop_sinkag=0.01"], "stop_sinkag")))
    # the plate's start_z below the bed top plus the gap: refused at the first exchange
    rc, out, text = run(build, ["fem.plate.start_z=0.005"])
    print("  start_z 0.005 m: exit %d" % rc)
    ensure(rc != 0 and "start_gap" in text, "a plate starting inside the bed was accepted (exit %d)" % rc)
    shutil.rmtree(out)


CASES = {f.__name__: f for f in (start_gap_and_stop, keys_checked)}

if __name__ == "__main__":
    build = sys.argv[1]
    for name in sys.argv[2:] or list(CASES):
        CASES[name](build)
        print("ok   " + name)
