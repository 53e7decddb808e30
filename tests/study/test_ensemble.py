#!/usr/bin/python3
"""Ensembles over beds (bench/post/ensemble.py, ./run --seeds): on generated
summaries of known mean, bed-to-bed scatter and within-run scatter, the
ensemble interval covers the true mean at its stated 95 %, the dominant
scatter is named, the seeds needed for a target are right; ./run refuses
bad --seeds arguments.

usage: test_ensemble.py CASE [BUILD_DIR]   (ctest runs one case per entry)"""
import csv
import json
import math
import os
import random
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "bench", "post"))

import ensemble  # noqa: E402


def ensure(cond, what):
    if not cond:
        raise AssertionError(what)


def summary(mean, half_width):
    return {"travelled": True, "quantities": {"T_P_per_W": {"unit": "1", "mean": mean, "half_width": half_width}}}


def draw(rng, n, mu, sd_bed, se_run):
    """n runs: run mean = mu + bed effect + the run's own averaging error."""
    return [summary(mu + rng.gauss(0, sd_bed) + rng.gauss(0, se_run), 1.96 * se_run) for _ in range(n)]


def coverage_known_mean():
    rng = random.Random(4)
    mu = -0.08
    for n, sd_bed, se_run in ((3, 0.03, 0.005), (5, 0.01, 0.01), (8, 0.002, 0.02)):
        draws, covered = 4000, 0
        for _ in range(draws):
            e = ensemble.analyse(draw(rng, n, mu, sd_bed, se_run))["T_P_per_W"]
            covered += abs(e["mean"] - mu) <= e["half_width"]
        rate = covered / draws
        print("  %d seeds, bed sd %g, run se %g: covered %.3f" % (n, sd_bed, se_run, rate))
        # binomial sd at 4000 draws: 0.0034; 3 sd either side of 0.95
        ensure(0.94 <= rate <= 0.96, (n, rate))


def dominant_named():
    rng = random.Random(9)
    e = ensemble.analyse(draw(rng, 40, 0.0, 0.05, 0.002))["T_P_per_W"]
    ensure(e["dominant"] == "bed-to-bed scatter", e)
    ensure(abs(e["bed_to_bed_sd"] - 0.05) < 0.015, e)
    ensure(abs(e["within_run_se"] - 0.002) < 1e-12, e)
    e = ensemble.analyse(draw(rng, 40, 0.0, 0.001, 0.03))["T_P_per_W"]
    ensure(e["dominant"] == "within-run time scatter", e)


def seeds_for_target():
    # t_{N-1} s / sqrt(N) <= h, smallest N, against brute force
    for s, h in ((0.05, 0.02), (0.05, 0.005), (0.01, 0.02), (0.1, 0.03)):
        n = ensemble.seeds_needed(s, h)
        ok = [m for m in range(2, 10000) if ensemble.t95(m - 1) * s / math.sqrt(m) <= h]
        ensure(n == ok[0], (s, h, n, ok[:3]))
    ensure(ensemble.seeds_needed(0.05, 0.02) == 27, ensemble.seeds_needed(0.05, 0.02))
    res = ensemble.analyse(draw(random.Random(1), 4, 0.0, 0.05, 0.001), {"T_P_per_W": 0.02})
    ensure(res["T_P_per_W"]["seeds_needed"] == ensemble.seeds_needed(res["T_P_per_W"]["sd_between_runs"], 0.02),
           res)


def reads_summaries_from_runs():
    # run folders with summary.json as fem_server writes them: the command line works on them
    tmp = tempfile.mkdtemp()
    dirs = []
    for k, m in enumerate((1.0, 2.0, 3.0)):
        d = os.path.join(tmp, "seed%d" % (k + 1))
        os.makedirs(d)
        with open(os.path.join(d, "summary.json"), "w") as f:  # with the set-down, as fem_server writes it
            json.dump(dict(summary(m, 0.1), set_down={"time_s": 0.6, "sinkage_m": 0.028 + 0.002 * m}), f)
        dirs.append(d)
    out = os.path.join(tmp, "ens.json")
    p = subprocess.run([sys.executable, os.path.join(ROOT, "bench", "post", "ensemble.py")] + dirs +
                       ["--json", out, "--target", "T_P_per_W=0.5"], capture_output=True, text=True)
    ensure(p.returncode == 0, p.stderr)
    r = json.load(open(out))["quantities"]["T_P_per_W"]
    ensure(abs(r["mean"] - 2.0) < 1e-12 and abs(r["half_width"] - 4.303 * 1.0 / math.sqrt(3)) < 1e-9, r)
    # the static sinkage (summary.json's set_down): one value per run, its interval the beds'
    r = json.load(open(out))["quantities"]["static_sinkage"]
    ensure(abs(r["mean"] - 0.032) < 1e-12 and abs(r["half_width"] - 4.303 * 0.002 / math.sqrt(3)) < 1e-9
           and r["unit"] == "m" and r["within_run_se"] == 0.0, r)
    ensure("seeds" in p.stdout and "dominates" in p.stdout, p.stdout)
    # a run without its summary is named
    os.remove(os.path.join(dirs[1], "summary.json"))
    p = subprocess.run([sys.executable, os.path.join(ROOT, "bench", "post", "ensemble.py")] + dirs,
                       capture_output=True, text=True)
    ensure(p.returncode != 0 and dirs[1] in p.stderr, p.stderr)


def paired_difference():
    # a choice that shifts T_P/W by delta on every bed, beds scattering 10x
    # more than the runs' own averaging: the paired interval covers delta at
    # its stated 95 % and is far narrower than the unpaired one
    rng = random.Random(12)
    delta, n, sd_bed, se_run = 0.015, 4, 0.04, 0.004
    draws, covered, resolved, ratio = 3000, 0, 0, []
    for _ in range(draws):
        beds = [rng.gauss(0, sd_bed) for _ in range(n)]
        base = [summary(-0.1 + b + rng.gauss(0, se_run), 1.96 * se_run) for b in beds]
        var = [summary(-0.1 + delta + b + rng.gauss(0, se_run), 1.96 * se_run) for b in beds]
        e = ensemble.paired(var, base)["T_P_per_W"]
        covered += abs(e["difference"] - delta) <= e["half_width"]
        resolved += e["resolved"]
        ratio.append(e["half_width"] / e["unpaired_half_width"])
    rate = covered / draws
    print("  paired: covered %.3f, resolved %.3f, paired/unpaired half-width %.2f"
          % (rate, resolved / draws, sorted(ratio)[draws // 2]))
    ensure(0.935 <= rate <= 0.965, rate)   # binomial sd at 3000 draws: 0.004
    ensure(sorted(ratio)[draws // 2] < 0.2, "pairing did not cancel the beds")
    # no effect: "resolved" only at the false-alarm rate
    false = sum(ensemble.paired(*[[summary(b + rng.gauss(0, se_run), 0.01) for b in beds] for _ in range(2)])
                ["T_P_per_W"]["resolved"] for beds in ([rng.gauss(0, sd_bed) for _ in range(n)]
                                                      for _ in range(draws)))
    ensure(0.035 <= false / draws <= 0.065, false / draws)
    # the command line pairs folders by name and refuses a mismatch
    tmp = tempfile.mkdtemp()
    for side, shift in (("base", 0.0), ("var", 0.5)):
        for k, m in enumerate((1.0, 2.0, 4.0)):
            d = os.path.join(tmp, side, "seed%d" % (k + 1))
            os.makedirs(d)
            with open(os.path.join(d, "summary.json"), "w") as f:
                json.dump(summary(m + shift + 0.01 * k, 0.1), f)
    runs = [os.path.join(tmp, "var", "seed%d" % k) for k in (1, 2, 3)]
    base = [os.path.join(tmp, "base", "seed%d" % k) for k in (1, 2, 3)]
    out = os.path.join(tmp, "d.json")
    script = os.path.join(ROOT, "bench", "post", "ensemble.py")
    p = subprocess.run([sys.executable, script] + runs + ["--against"] + base + ["--json", out],
                       capture_output=True, text=True)
    ensure(p.returncode == 0, p.stderr)
    d = json.load(open(out))["difference"]["T_P_per_W"]
    ensure(abs(d["difference"] - 0.5) < 1e-12 and d["resolved"] and d["half_width"] < 1e-9, d)
    ensure("resolved" in p.stdout, p.stdout)
    p = subprocess.run([sys.executable, script] + runs + ["--against"] + base[::-1], capture_output=True, text=True)
    ensure(p.returncode == 2 and "not the same bed" in p.stderr, p.stderr)


def reads_sweep_rows():
    # slip_sweep's result rows stand for runs (written with slip_sweep's own
    # column list, so a renamed column fails here): a known shift of 3 N in
    # T_P on three beds, two slips and two tires per file
    import importlib.machinery
    import importlib.util
    loader = importlib.machinery.SourceFileLoader("slip_sweep", os.path.join(ROOT, "bench", "slip_sweep", "run"))
    sweep = importlib.util.module_from_spec(importlib.util.spec_from_loader("slip_sweep", loader))
    loader.exec_module(sweep)
    tmp = tempfile.mkdtemp()

    def write(name, tp, sink, status="ok"):
        path = os.path.join(tmp, name)
        with open(path, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=sweep.COLUMNS, restval="")
            w.writeheader()
            for slip, tire, off in ((5, "elastic", 0.0), (5, "rigid", 100.0), (20, "elastic", 50.0)):
                row = {c: "0" for c in sweep.COLUMNS if c.endswith(("_N", "_m", "_W", "_ci95"))}
                row.update(slip_percent=slip, tire=tire, status=status if off == 0.0 else "ok",
                           T_P_mean_N=tp + off, T_P_ci95_N=0.5, sinkage_mean_m=sink, sinkage_ci95_m=1e-4)
                w.writerow(row)
        return path + "@5"

    base = [write("base%d.csv" % k, tp, 0.04 + 0.001 * k) for k, tp in enumerate((-30.0, -45.0, -20.0))]
    var = [write("var%d.csv" % k, tp + 3.0, 0.04 + 0.001 * k) for k, tp in enumerate((-30.0, -45.0, -20.0))]
    s = ensemble.load_summaries(base)
    ensure([r["quantities"]["T_P"]["mean"] for r in s] == [-30.0, -45.0, -20.0], s)
    ensure(ensemble.load_summaries([base[0][:-2] + "@5,rigid"])[0]["quantities"]["T_P"]["mean"] == 70.0, "tire")
    out = os.path.join(tmp, "d.json")
    script = os.path.join(ROOT, "bench", "post", "ensemble.py")
    p = subprocess.run([sys.executable, script] + var + ["--against"] + base + ["--json", out],
                       capture_output=True, text=True)
    ensure(p.returncode == 0, p.stderr)
    with open(out) as f:
        d = json.load(f)["difference"]
    ensure(abs(d["T_P"]["difference"] - 3.0) < 1e-12 and d["T_P"]["resolved"], d["T_P"])
    ensure(abs(d["sinkage"]["difference"]) < 1e-15 and not d["sinkage"]["resolved"], d["sinkage"])
    # a file of several rows without a slip, a slip not in it: refused, named
    for arg in (base[0][:-2], base[0][:-2] + "@30"):
        p = subprocess.run([sys.executable, script, arg], capture_output=True, text=True)
        ensure(p.returncode != 0 and "rows match" in p.stderr, p.stderr)
    # a failed run's row counts as not travelled
    ensure(not ensemble.load_summaries([write("bad.csv", 0.0, 0.0, "failed (exit 1)")])[0]["travelled"], "status")


def launcher_refuses_bad_seeds():
    env = dict(os.environ, DEMFEM_NO_BUILD="1")
    scene = os.path.join(ROOT, "tests", "coupling", "scenes", "tire_small.cfg")
    for args, what in ((["--seeds", "0"], "--seeds needs a number"), (["--seeds", "x"], "--seeds needs a number"),
                       (["--seeds", "2", "--resume", "/tmp"], "cannot be combined")):
        p = subprocess.run([os.path.join(ROOT, "run"), scene] + args, capture_output=True, text=True, env=env)
        ensure(p.returncode == 2 and what in p.stderr, (args, p.returncode, p.stderr))


CASES = {f.__name__: f for f in (coverage_known_mean, dominant_named, seeds_for_target, reads_summaries_from_runs,
                                 paired_difference, reads_sweep_rows, launcher_refuses_bad_seeds)}

if __name__ == "__main__":
    CASES[sys.argv[1]]()
    print("ok   %s" % sys.argv[1])
