#!/usr/bin/python3
"""The cheapest accurate model (bench/study/choose.py and ./run --accuracy)
on small committed study tables (tests/study/results/): the right run is
chosen, and a target the study cannot meet or cannot verify is refused.

usage: test_choose.py CASE [BUILD_DIR]   (ctest runs one case per entry)"""
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
RESULTS = os.path.join(HERE, "results")
CHOOSE = os.path.join(ROOT, "bench", "study", "choose.py")
TIRE = os.path.join(ROOT, "tests", "coupling", "scenes", "tire_small.cfg")
PLATE = os.path.join(ROOT, "tests", "coupling", "scenes", "impact_plate.cfg")
BUILD = sys.argv[2] if len(sys.argv) > 2 else os.path.join(ROOT, "build")


def choose(scene, *args):
    # choose.py reads the scene through fem_server --print-config=json of this build
    p = subprocess.run([sys.executable, CHOOSE, scene, "--results", RESULTS] + list(args), capture_output=True,
                       text=True, env=dict(os.environ, DEMFEM_BUILD_DIR=BUILD))
    return p.returncode, p.stdout.split("\n")[:-1], p.stderr


def ensure(cond, what):
    if not cond:
        raise AssertionError(what)


def with_target(base, target):
    """A copy of scene `base` (beside it, so relative paths hold) with run.target added."""
    text = open(base).read().replace("run = {", "run = { target = { %s };" % target, 1)
    fd, path = tempfile.mkstemp(suffix=".cfg", dir="/tmp")
    os.write(fd, text.encode())
    os.close(fd)
    return path


def picks_fastest_within_tolerance():
    # 5 %: base (3 %, 10 s) and fast (4 %, 5 s) meet it; rigid (20 %) does not;
    # the unstable run (0.1 %, 1 s) and the failed one are never candidates.
    rc, out, err = choose(TIRE, "--accuracy", "drawbar_pull=5%", "--results", RESULTS)
    ensure(rc == 0, err)
    ensure(out == ["coupling.dt=2e-05", "fem.mesh.resolution=0.25"], out)
    ensure("chose run 'fast'" in err and "error 4 %" in err and "fastest of the 3" in err, err)
    # 3.5 % (as a fraction): only base and the reference meet it; base is faster.
    rc, out, err = choose(TIRE, "--accuracy", "drawbar_pull=0.035", "--results", RESULTS)
    ensure(rc == 0 and out == ["coupling.dt=1e-05", "fem.mesh.resolution=0.25"], (rc, out, err))
    # 2.5 %: only the reference, whose own error is its 2 % confidence interval.
    rc, out, err = choose(TIRE, "--accuracy", "drawbar_pull=2.5%", "--results", RESULTS)
    ensure(rc == 0 and "chose run 'reference'" in err, err)
    ensure(out == ["coupling.dt=5e-06", "fem.mesh.resolution=0.35"], out)
    # Another quantity, another choice: sinkage within 5 % is the rigid tire.
    rc, out, err = choose(TIRE, "--accuracy", "sinkage=5%", "--results", RESULTS)
    ensure(rc == 0 and out == ["coupling.dt=1e-05", 'fem.integrator="rigid"'], (out, err))


def refuses_below_noise_floor():
    rc, out, err = choose(TIRE, "--accuracy", "drawbar_pull=1%", "--results", RESULTS)
    ensure(rc == 3 and out == [], (rc, out))
    ensure("refused" in err and "cannot tell drawbar_pull to 1 %" in err and "+-2 %" in err, err)


def refuses_below_seed_spread():
    # The same settings on another random bed moved the sinkage by 3 %.
    rc, out, err = choose(TIRE, "--accuracy", "sinkage=2.5%", "--results", RESULTS)
    ensure(rc == 3 and out == [], (rc, out))
    ensure("another random bed differ by 3 %" in err and "sinkage_noise" in err, err)


def refuses_when_none_meets():
    # Closed-form study: peak force to 1e-6 is better than any run did.
    rc, out, err = choose(PLATE, "--accuracy", "peak_force=0.0001%", "--results", RESULTS)
    ensure(rc == 3 and out == [], (rc, out))
    ensure("no setting in" in err and "the best was 0.0003 %" in err and "run 'base'" in err, err)


def bad_targets_refused():
    rc, _, err = choose(TIRE, "--accuracy", "speed=5%")
    ensure(rc == 2 and "not one the study measures" in err, err)
    rc, _, err = choose(TIRE, "--accuracy", "drawbar_pull=fast")
    ensure(rc == 2 and "not a number" in err, err)
    rc, _, err = choose(TIRE)  # no target in the scene, none given
    ensure(rc == 2 and "no run.target" in err, err)
    # A study that was never run.
    scene = with_target(TIRE, 'quantity = "sinkage"; tolerance = 0.05; study = "never_run";')
    try:
        rc, _, err = choose(scene)
        ensure(rc == 2 and "no study results" in err and "./run bench study" in err, err)
    finally:
        os.unlink(scene)


def scene_target_read():
    scene = with_target(TIRE, 'quantity = "drawbar_pull"; tolerance = 0.05; study = "tire_small";')
    try:
        rc, out, err = choose(scene)
        ensure(rc == 0 and out == ["coupling.dt=2e-05", "fem.mesh.resolution=0.25"], (out, err))
    finally:
        os.unlink(scene)


def launcher(scene, *args):
    env = dict(os.environ, DEMFEM_NO_BUILD="1", DEMFEM_BUILD_DIR=BUILD, DEMFEM_STUDY_RESULTS=RESULTS)
    out = tempfile.mkdtemp(prefix="demfem-choose-")
    p = subprocess.run([os.path.join(ROOT, "run"), scene, "--out", out, "--fem",
                        os.path.join(BUILD, "tests", "coupling", "plate_peer")] + list(args),
                       capture_output=True, text=True, env=env, timeout=120)
    return p.returncode, p.stdout + p.stderr


def launcher_runs_chosen_settings():
    # The scene asks for the peak force within 0.01 %: the study's fastest
    # run that met it used a DEM step of 4e-6 s; both servers run with it.
    scene = with_target(PLATE, 'quantity = "peak_force"; tolerance = 1e-4; study = "impact_plate";')
    try:
        rc, log = launcher(scene)
    finally:
        os.unlink(scene)
    ensure(rc == 0, log)
    ensure("[accuracy] peak_force within 0.01 %: chose run 'dt=4e-06'" in log, log)
    ensure("--set coupling.dt=4e-06" in log and "[dem] 1 grains; dt = 4e-06 s" in log, log)
    # The user's own --set comes after the chosen ones and wins.
    rc, log = launcher(PLATE, "--accuracy", "peak_force=0.01%", "--set", "coupling.dt=2e-06")
    ensure(rc == 0 and "[dem] 1 grains; dt = 2e-06 s" in log, log)


def launcher_refuses():
    rc, log = launcher(PLATE, "--accuracy", "peak_force=0.0001%")
    ensure(rc == 3, log)
    ensure("[accuracy] refused: no setting in" in log and "[dem]" not in log and "[fem]" not in log, log)


def terrain_chosen():
    # A study whose terrain knob put SCM on the front: within 5 % of the peak
    # force SCM (2 %, 0.3 s) is cheaper than the DEM (0.3 %, 0.8 s), and the
    # choice is a terrain=scm line; within 1 % only the DEM is.
    scene = with_target(PLATE, 'quantity = "peak_force"; tolerance = 0.05; study = "terrain_plate";')
    try:
        rc, out, err = choose(scene)
        ensure(rc == 0 and out == ["terrain=scm", "coupling.dt=1e-06"], (rc, out, err))
        rc, out, err = choose(scene, "--accuracy", "peak_force=1%")
        ensure(rc == 0 and out == ["terrain=dem", "coupling.dt=1e-06"], (rc, out, err))
    finally:
        os.unlink(scene)


def launcher_runs_chosen_terrain():
    # ./run turns the chosen terrain=scm into scm_server on the terrain side
    # (the plate scene with a soil 1 mm below the plate: scm_server attaches,
    # exchanges with the plate peer to the end and reports its work), unless
    # the user names the terrain program themselves.
    text = open(PLATE).read().replace("run = {", "run = { target = { quantity = \"peak_force\"; tolerance = 0.05; "
                                      "study = \"terrain_plate\"; };", 1)
    text += "\nscm = { surface_height = -0.001; grid = { min = [-0.05, -0.05]; max = [0.05, 0.05]; }; };\n"
    fd, scene = tempfile.mkstemp(suffix=".cfg", dir="/tmp")
    os.write(fd, text.encode())
    os.close(fd)
    try:
        rc, log = launcher(scene)
        ensure(rc == 0, log)
        ensure("[accuracy] terrain: scm" in log and "scm_server" in log and "[scm] coupled run finished" in log, log)
        ensure("[dem]" not in log, log)
        rc, log = launcher(scene, "--terrain", "dem")
        ensure(rc == 0 and "[accuracy] terrain" not in log and "[dem]" in log and "[scm]" not in log, log)
    finally:
        os.unlink(scene)


CASES = {f.__name__: f for f in (picks_fastest_within_tolerance, refuses_below_noise_floor, refuses_below_seed_spread,
                                 refuses_when_none_meets,
                                 bad_targets_refused, scene_target_read, launcher_runs_chosen_settings,
                                 launcher_refuses, terrain_chosen, launcher_runs_chosen_terrain)}

if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] not in CASES:
        print("usage: test_choose.py CASE [BUILD_DIR]; cases: " + " ".join(CASES))
        sys.exit(2)
    try:
        CASES[sys.argv[1]]()
    except AssertionError as e:
        print("FAIL %s: %s" % (sys.argv[1], e))
        sys.exit(1)
    print("ok   %s" % sys.argv[1])
