#!/usr/bin/python3
"""The calibration's fits and the rigid-wheel prediction (bench/calibrate/
terramech.py) on synthetic data with known parameters, and Wong-Reece
against closed forms.

usage: test_terramech.py CASE   (ctest runs one case per entry)"""
import math
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "bench", "calibrate"))
import terramech as tm  # noqa: E402

SAND = tm.DRY_SAND_LLL


def ensure(cond, what):
    if not cond:
        raise AssertionError(what)


def rel(a, b):
    return abs(a - b) / abs(b)


def plate_curves(noise=0.0, seed=1, widths=(0.05, 0.10)):
    rng = np.random.default_rng(seed)
    curves = []
    for b in widths:
        z = np.linspace(0.001, 0.03, 30)
        p = tm.bekker_pressure(b, z, SAND["k_c"], SAND["k_phi"], SAND["n"])
        curves.append((b, z, p * (1.0 + noise * rng.standard_normal(len(z)))))
    return curves


def bekker_exact():
    f = tm.bekker_fit(plate_curves())
    print("  k_c %.6g (%.6g), k_phi %.6g (%.6g), n %.8f (%.8f)" % (f["k_c"], SAND["k_c"], f["k_phi"], SAND["k_phi"],
                                                                    f["n"], SAND["n"]))
    ensure(rel(f["n"], SAND["n"]) < 1e-8, "n")
    ensure(rel(f["k_phi"], SAND["k_phi"]) < 1e-7, "k_phi")
    ensure(rel(f["k_c"], SAND["k_c"]) < 1e-5, "k_c")  # small beside k_phi b: the least determined
    ensure(f["rms_rel"] < 1e-9, "residual %g" % f["rms_rel"])


def bekker_noisy():
    # 2 % scatter on each pressure: n within 3 %, k_phi within 10 % (over a
    # finite range of z, n and k_phi trade against each other), and the
    # fitted law predicts a third, wider plate within 3 % (k_c alone is
    # ill-determined for sand, where k_c/b << k_phi: not tested).
    errs = []
    for seed in range(1, 21):
        f = tm.bekker_fit(plate_curves(noise=0.02, seed=seed))
        p_true = tm.bekker_pressure(0.2, 0.02, SAND["k_c"], SAND["k_phi"], SAND["n"])
        p_fit = tm.bekker_pressure(0.2, 0.02, f["k_c"], f["k_phi"], f["n"])
        errs.append((rel(f["n"], SAND["n"]), rel(f["k_phi"], SAND["k_phi"]), rel(p_fit, p_true)))
    worst = np.max(np.array(errs), axis=0)
    print("  20 noisy sets: worst relative error n %.3g, k_phi %.3g, p(0.2 m plate, 20 mm) %.3g" % tuple(worst))
    ensure(worst[0] < 0.03 and worst[1] < 0.10 and worst[2] < 0.03, "noisy fit off: %s" % worst)


def bekker_needs_two_widths():
    try:
        tm.bekker_fit(plate_curves(widths=(0.05, 0.05)))
    except ValueError as e:
        ensure("two widths" in str(e), str(e))
        return
    raise AssertionError("one plate width accepted")


def mohr_coulomb_exact():
    sigma = np.array([5e3, 10e3, 20e3])
    tau = SAND["c"] + sigma * math.tan(math.radians(SAND["phi_deg"]))
    f = tm.mohr_coulomb_fit(sigma, tau)
    print("  c %.6g Pa, phi %.8f deg" % (f["c"], f["phi_deg"]))
    ensure(abs(f["c"] - SAND["c"]) < 1e-6 * SAND["c"] and abs(f["phi_deg"] - SAND["phi_deg"]) < 1e-9, "c, phi")


def janosi_exact_and_noisy():
    j = np.linspace(0.0, 0.08, 60)
    tmax = 12e3
    tau = tmax * (1.0 - np.exp(-j / SAND["K"]))
    f = tm.janosi_fit(j, tau, tau_max=tmax)
    g = tm.janosi_fit(j, tau)
    print("  K %.8g m (given tau_max), %.8g m and tau_max %.6g Pa (both fitted); true %.8g m" %
          (f["K"], g["K"], g["tau_max"], SAND["K"]))
    ensure(rel(f["K"], SAND["K"]) < 1e-8 and rel(g["K"], SAND["K"]) < 1e-6 and rel(g["tau_max"], tmax) < 1e-6, "K")
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(20):
        noisy = tau + 0.02 * tmax * rng.standard_normal(len(j))
        worst = max(worst, rel(tm.janosi_fit(j, noisy)["K"], SAND["K"]))
    print("  noise 2 %% of tau_max, 20 sets: worst K error %.3g" % worst)
    ensure(worst < 0.08, "noisy K off by %g" % worst)


def plate_ensemble(rng, truth, m, widths=(0.05, 0.10), run_scatter=0.1, n_scatter=0.03, point_noise=0.05):
    """m synthetic plate runs per width as the DEM gives them: each run's
    modulus off by a random factor (1 + run_scatter e), its exponent by
    n_scatter e about the middle of the range, and along the curve a
    correlated (AR(1), 0.9 per bin) relative noise of point_noise: the true
    law is the ensemble's mean."""
    z = np.linspace(0.003, 0.03, 55)
    zr = 0.015
    runs = []
    for b in widths:
        for _ in range(m):
            kb = (truth["k_c"] / b + truth["k_phi"]) * (1.0 + run_scatter * rng.standard_normal())
            n = truth["n"] + n_scatter * rng.standard_normal()
            e, a = np.zeros(len(z)), 0.0
            for i in range(len(z)):
                a = 0.9 * a + math.sqrt(1.0 - 0.81) * rng.standard_normal()
                e[i] = a
            runs.append((b, z, kb * zr ** truth["n"] * (z / zr) ** n * (1.0 + point_noise * e)))
    return runs


def bekker_runs_coverage():
    # The intervals of bekker_fit_runs (jackknife over runs) hold the true
    # k_c, k_phi, n in about 95 % of synthetic ensembles of 3 runs per width
    # (asserted >= 85 % of 200: the jackknife with 4 degrees of freedom is a
    # little narrow), are not vacuous (n within +-10 %, k_phi within +-60 %
    # at the median; k_c, small beside k_phi b for sand, is not resolved by
    # 10 % run scatter and only its coverage is asserted), and shrink with
    # the scatter; one run per width is refused.
    truth = {"k_c": 5e3, "k_phi": 8e5, "n": 0.9}
    rng = np.random.default_rng(2024)
    hit = dict.fromkeys(truth, 0)
    half = {k: [] for k in truth}
    N = 200
    for _ in range(N):
        f = tm.bekker_fit_runs(plate_ensemble(rng, truth, 3))
        for k in truth:
            hit[k] += f[k + "_lo"] <= truth[k] <= f[k + "_hi"]
            half[k].append(0.5 * (f[k + "_hi"] - f[k + "_lo"]) / abs(truth[k]))
    med = {k: float(np.median(half[k])) for k in truth}
    print("  %d ensembles of 3 + 3 runs: coverage k_c %.3f, k_phi %.3f, n %.3f; median half-width k_c %.2f, "
          "k_phi %.2f, n %.3f (relative)" % (N, hit["k_c"] / N, hit["k_phi"] / N, hit["n"] / N, med["k_c"],
                                            med["k_phi"], med["n"]))
    for k in truth:
        ensure(hit[k] >= 0.85 * N, "%s covered in %d of %d ensembles" % (k, hit[k], N))
    ensure(med["n"] < 0.10 and med["k_phi"] < 0.6, "intervals too wide: %s" % med)
    f = tm.bekker_fit_runs(plate_ensemble(rng, truth, 3, run_scatter=0.01, n_scatter=0.003, point_noise=0.005))
    print("  scatter / 10: n %.4f [%.4f, %.4f], k_phi %.4g [%.4g, %.4g]" % (f["n"], f["n_lo"], f["n_hi"], f["k_phi"],
                                                                       f["k_phi_lo"], f["k_phi_hi"]))
    ensure(0.5 * (f["n_hi"] - f["n_lo"]) / truth["n"] < med["n"] / 3, "the interval of n does not shrink")
    ensure(f["n_lo"] <= truth["n"] <= f["n_hi"], "n not covered at small scatter")
    try:
        tm.bekker_fit_runs(plate_ensemble(rng, truth, 1))
    except ValueError as e:
        ensure("two or more runs" in str(e), str(e))
        return
    raise AssertionError("one run per width accepted")


def mohr_coulomb_ci_coverage():
    # Six shear tests at 10/20/40 kPa (two each) with 4 % scatter on tau:
    # the 95 % intervals of c and phi (least-squares covariance, t with 4
    # dof) cover the truth in >= 91 % of 400 sets (binomial: 95 +- 1.1 %);
    # mean_ci's interval of a mean likewise (K from several runs).
    rng = np.random.default_rng(7)
    c, phi = 1.5e3, 33.0
    sigma = np.array([1e4, 1e4, 2e4, 2e4, 4e4, 4e4])
    N, hc, hp, hm = 400, 0, 0, 0
    for _ in range(N):
        tau = c + sigma * math.tan(math.radians(phi))
        f = tm.mohr_coulomb_fit_ci(sigma, tau + 0.04 * 1.3e4 * rng.standard_normal(len(sigma)))
        hc += f["c_lo"] <= c <= f["c_hi"]
        hp += f["phi_lo_deg"] <= phi <= f["phi_hi_deg"]
        m, h = tm.mean_ci(0.5e-3 + 0.1e-3 * rng.standard_normal(5))
        hm += abs(m - 0.5e-3) <= h
    print("  coverage over %d sets: c %.3f, phi %.3f, mean of 5 %.3f" % (N, hc / N, hp / N, hm / N))
    ensure(hc >= 0.91 * N and hp >= 0.91 * N and hm >= 0.91 * N, "coverage %d %d %d of %d" % (hc, hp, hm, N))
    try:
        tm.mohr_coulomb_fit_ci(sigma[:2], sigma[:2])
    except ValueError as e:
        ensure("three or more" in str(e), str(e))
        return
    raise AssertionError("two tests accepted")


def wong_reece_compaction():
    # No shear and the stress maximum at the bottom (c1 = c2 = 0): the
    # classical Bekker wheel. Motion resistance = compaction resistance
    # b k z^(n+1)/(n+1) exactly; sinkage near Bekker's parabola formula for
    # a shallow rut.
    R, b = 0.2675, 0.17
    soil = dict(SAND, c=0.0, phi_deg=0.0)
    W = 300.0
    r = tm.wong_reece(R, b, W, 0.0, soil, c1=0.0, c2=0.0, n_quad=20000)
    k = soil["k_c"] / b + soil["k_phi"]
    rc = b * k * r["sinkage"] ** (soil["n"] + 1) / (soil["n"] + 1)
    z0 = tm.bekker_wheel_sinkage(R, b, W, soil)
    print("  z %.5f m (Bekker parabola %.5f), R_c %.5f N (b k z^(n+1)/(n+1) = %.5f), load %.6f N" %
          (r["sinkage"], z0, r["motion_resistance"], rc, r["load"]))
    ensure(rel(r["load"], W) < 1e-6, "load")
    ensure(rel(r["motion_resistance"], rc) < 1e-4, "compaction resistance")
    ensure(rel(r["sinkage"], z0) < 0.03, "sinkage vs Bekker")


def wong_reece_slip_shape():
    # Wong's shape on sand: drawbar pull rises with slip, steeply at first;
    # sinkage grows with slip (the stress maximum moves forward). (On this
    # soil under 980 N the growing sinkage makes the Wong-Reece drawbar pull
    # peak near 30 % slip and fall beyond: not asserted either way.)
    R, b, W = 0.2675, 0.17, 980.0
    s = [0.0, 0.05, 0.1, 0.2, 0.5]
    rs = [tm.wong_reece(R, b, W, si, SAND) for si in s]
    dp = [r["drawbar_pull"] / W for r in rs]
    z = [r["sinkage"] for r in rs]
    print("  slip " + " ".join("%.2f" % x for x in s))
    print("  DP/W " + " ".join("%.3f" % x for x in dp))
    print("  z mm " + " ".join("%.1f" % (1e3 * x) for x in z))
    ensure(all(b_ > a_ for a_, b_ in zip(dp[:4], dp[1:4])), "drawbar pull not rising with slip up to 20 %")
    slope = [(dp[i + 1] - dp[i]) / (s[i + 1] - s[i]) for i in range(3)]
    ensure(slope[0] > slope[1] > slope[2], "not steepest at low slip: %s" % slope)
    ensure(all(b_ >= a_ for a_, b_ in zip(z, z[1:])), "sinkage not growing with slip")


def slip_sweep_wong():
    # bench/slip_sweep/run --wong: the rigid wheel beside a sweep, with the
    # base scene's wheel (shinone.cfg: R 0.2675 m, b 0.17 m, 980 N) on the
    # soil scene's scm.soil, one curve per K; nothing run (--no-run).
    import csv
    import subprocess
    import tempfile
    build = os.environ.get("DEMFEM_BUILD_DIR", os.path.join(ROOT, "build"))
    out = tempfile.mkdtemp(prefix="demfem-wong-")
    p = subprocess.run([sys.executable, os.path.join(ROOT, "bench", "slip_sweep", "run"), build, out,
                        "--scene", os.path.join(ROOT, "scenes", "shinone.cfg"), "--slips", "10", "40",
                        "--work", os.path.join(out, "w"), "--tag", "t", "--no-run",
                        "--wong", os.path.join(ROOT, "scenes", "shinone_scm.cfg"), "--wong-K", "0.0004", "0.1"],
                       capture_output=True, text=True)
    ensure(p.returncode != 2, p.stderr)  # (1: the sweep's runs were not run)
    rows = list(csv.DictReader(open(os.path.join(out, "slip_sweep-t-wong.csv"))))
    ensure(len(rows) == 80 and abs(float(rows[-1]["slip_percent"]) - 40.0) < 1e-9, len(rows))
    for r in rows:  # the load carried is the scene's
        ensure(abs(float(r["load_N"]) - 980.0) < 0.5, r)
    soil = {"k_c": -5733.0, "k_phi": 4.125e5, "n": 0.703, "c": 557.0, "phi_deg": 37.4}
    ref = tm.wong_reece(0.2675, 0.17, 980.0, 0.4, dict(soil, K=0.1))
    last = [r for r in rows if r["K_m"] == "0.1"][-1]
    ensure(rel(float(last["drawbar_pull_N"]), ref["drawbar_pull"]) < 1e-5, (last, ref))
    # a stiffer shear response (smaller K) mobilises more thrust at every slip
    small = {r["slip_percent"]: float(r["thrust_N"]) for r in rows if r["K_m"] == "0.0004"}
    large = {r["slip_percent"]: float(r["thrust_N"]) for r in rows if r["K_m"] == "0.1"}
    ensure(all(small[k] > large[k] for k in small), "K made no difference")
    ensure(os.path.exists(os.path.join(out, "slip_sweep-t-drawbar.png")), "chart")


CASES = {f.__name__: f for f in (bekker_exact, bekker_noisy, bekker_needs_two_widths, mohr_coulomb_exact,
                                 janosi_exact_and_noisy, bekker_runs_coverage, mohr_coulomb_ci_coverage,
                                 wong_reece_compaction, wong_reece_slip_shape, slip_sweep_wong)}

if __name__ == "__main__":
    names = sys.argv[1:] or list(CASES)
    for name in names:
        CASES[name]()
        print("ok   " + name)
