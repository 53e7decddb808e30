#!/usr/bin/python3
"""The cheapest accurate model: settings for a scene from the study results.

usage: bench/study/choose.py SCENE [--accuracy QUANTITY=TOLERANCE] [--results DIR]

The target is --accuracy (e.g. drawbar_coefficient=0.02, drawbar_pull=5% or
sinkage=0.02) or, without
it, the scene's own `run.target = { quantity = "drawbar_pull"; tolerance =
0.05; study = "tire_small"; };` (study: optional, default the scene file's
name). The results are DIR/study-<study>.csv (default bench/results, or
$DEMFEM_STUDY_RESULTS), written by bench/study/run.

Among the study's runs that finished stable and whose relative error of the
quantity is within the tolerance, the one with the shortest wall time is
chosen. In a study over several beds (bench/study/run, "seeds") a row is a
setting's mean over the beds and its error a paired difference with the
reference bed by bed: the error plus its 95 % half-width (_err_ci95) must be
within the tolerance. Traction is best asked per actual load: drawbar_coefficient (T_P/W),
gross_traction_coefficient (T_H/W), running_resistance_coefficient (T_R/W)
and sinkage_per_radius (sinkage/R) take an ABSOLUTE tolerance (0.02 means
|T_P/W - reference| <= 0.02; a percentage is refused for them): the drawbar
pull crosses zero near 10-15 % slip, where an error relative to it means
nothing. The other quantities take a relative tolerance (5% or 0.05).
Its settings (the knobs of that run, not the study's shortened
travel) go to stdout, one KEY=VALUE per line, for `./run` to pass as --set
(`terrain=dem|scm`, the study's terrain knob, `./run` turns into --terrain);
what was chosen and why goes to stderr. A run's error is measured against
the study's reference (its finest run, whose own error is taken as its 95 %
confidence interval, or the closed form): a tolerance
below the reference's own 95 % confidence interval, or below the spread of
the same settings over random beds (the `_noise` columns), cannot be
verified by the study and is refused, as is a target no run met (exit 3, with the best that
was reached); no results for the scene, or a malformed target: exit 2.
"""
import argparse
import csv
import math
import os
import re
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "bench", "post"))

import runio  # noqa: E402

QUANTITIES = ("drawbar_coefficient", "gross_traction_coefficient", "running_resistance_coefficient",
              "sinkage_per_radius", "drawbar_pull", "gross_traction", "sinkage", "deflection", "contact_time",
              "peak_force", "restitution")
# Errors in absolute terms (bench/study/run writes |value - reference| for these).
ABSOLUTE = ("drawbar_coefficient", "gross_traction_coefficient", "running_resistance_coefficient",
            "sinkage_per_radius")


def show(q, v):
    """A tolerance or error as the quantity measures it."""
    return "%.3g (absolute)" % v if q in ABSOLUTE else "%.3g %%" % (100 * v)


class Refusal(Exception):
    def __init__(self, code, msg):
        super().__init__(msg)
        self.code = code


def fnum(s):
    try:
        return float(s)
    except (TypeError, ValueError):
        return math.nan


def parse_tolerance(text):
    t = text.strip()
    try:
        v = float(t[:-1]) / 100.0 if t.endswith("%") else float(t)
    except ValueError:
        raise Refusal(2, "tolerance %r is not a number (write 5%% or 0.05)" % text)
    if not v > 0:
        raise Refusal(2, "tolerance %r must be positive" % text)
    return v


def target_of(scene_path, accuracy):
    """(quantity, tolerance, study name)."""
    study = os.path.splitext(os.path.basename(scene_path))[0]
    try:  # the scene as the servers read it (fem_server --print-config=json)
        scene = runio.resolved_scene(scene_path)
    except runio.SceneError as e:
        raise Refusal(2, str(e))
    if accuracy:
        if "=" not in accuracy:
            raise Refusal(2, "--accuracy %s: expected QUANTITY=TOLERANCE, e.g. drawbar_pull=5%%" % accuracy)
        q, tol_text = accuracy.split("=", 1)
        q, tol = q.strip(), parse_tolerance(tol_text)
        if q in ABSOLUTE and tol_text.strip().endswith("%"):
            raise Refusal(2, "%s is measured in absolute terms (per load or per radius): write e.g. %s=0.02, "
                             "not a percentage" % (q, q))
    else:
        try:
            q = str(runio.scene_get(scene, "run.target.quantity")).strip()
            tol = parse_tolerance(str(runio.scene_get(scene, "run.target.tolerance")))
        except KeyError:
            raise Refusal(2, "%s: no run.target (quantity, tolerance) and no --accuracy" % scene_path)
    try:
        study = str(runio.scene_get(scene, "run.target.study")).strip() or study
    except KeyError:
        pass
    if q not in QUANTITIES:
        raise Refusal(2, "quantity %r is not one the study measures (%s)" % (q, ", ".join(QUANTITIES)))
    return q, tol, study


def choose(rows, quantity, tol, source):
    """(row, explanation) of the fastest run within tol, or raise Refusal."""
    if not rows or quantity not in rows[0]:
        raise Refusal(2, "%s has no column %s (a study of another kind of scene?)" % (source, quantity))
    ref = [r for r in rows if r["run"] == "reference" and r["status"] == "ok"]
    noise = 0.0
    absolute = quantity in ABSOLUTE
    if ref and math.isfinite(fnum(ref[0].get(quantity + "_ci95"))) and (absolute or fnum(ref[0][quantity])):
        noise = abs(fnum(ref[0][quantity + "_ci95"]) / (1.0 if absolute else fnum(ref[0][quantity])))
    if tol < noise:
        raise Refusal(3, "the study cannot tell %s to %s: its reference run's own 95 %% confidence interval "
                         "is +-%s (%s); ask for at least that, or rerun the study with a longer travel"
                      % (quantity, show(quantity, tol), show(quantity, noise), source))
    spread = fnum(rows[0].get(quantity + "_noise"))
    if math.isfinite(spread) and tol < spread:
        raise Refusal(3, "the study cannot tell %s to %s: the same settings with another random bed differ "
                         "by %s (%s, column %s_noise); ask for at least that"
                      % (quantity, show(quantity, tol), show(quantity, spread), source, quantity))
    scored = []
    for r in rows:
        if r["status"] != "ok" or r.get("stable") != "yes" or r["knob"] == "dem.bed.seed":
            continue  # (the seed runs measure the noise, they are not settings)
        e = noise if r["run"] == "reference" else fnum(r.get(quantity + "_err"))
        if r["run"] != "reference" and r.get(quantity + "_err_ci95"):
            # a study over several beds: the error is a paired mean over the beds; the
            # setting must meet the tolerance with its 95 % interval, not only on average
            e += fnum(r[quantity + "_err_ci95"])
        w = fnum(r.get("wall_s"))
        if math.isfinite(e) and math.isfinite(w):
            scored.append((w, e, r))
    if not scored:
        raise Refusal(3, "%s holds no finished stable run with an error of %s" % (source, quantity))
    met = sorted([s for s in scored if s[1] <= tol], key=lambda s: (s[0], s[1]))
    if not met:
        best = min(scored, key=lambda s: s[1])
        raise Refusal(3, "no setting in %s met %s within %s: the best was %s (run '%s', %.1f s: %s)"
                      % (source, quantity, show(quantity, tol), show(quantity, best[1]), best[2]["run"], best[0],
                         best[2]["settings"] or "the study's base"))
    w, e, r = met[0]
    slowest = max(s[0] for s in met)
    why = ("%s within %s: chose run '%s' of %s: error %s in %.1f s of wall time, the fastest of the %d "
           "stable runs that met it (they took %.1f to %.1f s; %d did not meet it)%s"
           % (quantity, show(quantity, tol), r["run"], source, show(quantity, e), w, len(met), w, slowest,
              len(scored) - len(met), "; the reference's own 95 %% CI is +-%s" % show(quantity, noise) if noise else ""))
    return r, why


def settings_of(row):
    return runio.split_settings(row["settings"])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0], epilog=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--accuracy")
    ap.add_argument("--results", default=os.environ.get("DEMFEM_STUDY_RESULTS",
                                                       os.path.join(ROOT, "bench", "results")))
    a = ap.parse_args(argv)
    try:
        q, tol, study = target_of(a.scene, a.accuracy)
        path = os.path.join(a.results, "study-%s.csv" % study)
        if not os.path.exists(path):
            raise Refusal(2, "no study results for scenes like %s (%s): run ./run bench study "
                             "bench/study/studies/%s.json, or name another study in run.target.study"
                          % (os.path.basename(a.scene), path, study))
        rows = list(csv.DictReader(open(path)))
        row, why = choose(rows, q, tol, os.path.relpath(path, ROOT) if path.startswith(ROOT) else path)
    except Refusal as r:
        print("[accuracy] refused: %s" % r, file=sys.stderr)
        return r.code
    sets = settings_of(row)
    print("[accuracy] %s" % why, file=sys.stderr)
    print("[accuracy] settings: %s" % ("; ".join(sets) or "the scene as it is"), file=sys.stderr)
    for s in sets:
        if not re.match(r"^[A-Za-z][-A-Za-z0-9_.\[\]]*=", s):
            print("[accuracy] refused: malformed setting %r in %s" % (s, path), file=sys.stderr)
            return 2
        print(s)
    return 0


if __name__ == "__main__":
    sys.exit(main())
