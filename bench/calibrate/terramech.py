#!/usr/bin/python3
"""Semi-empirical terramechanics for the soil calibration (issue 15): the one
place where measured curves are fitted to Bekker's and Janosi-Hanamoto's laws
and where the rigid-wheel prediction of Wong and Reece is computed.

Units: SI throughout (m, N, Pa). Bekker's moduli: k_c in N/m^(n+1), k_phi in
N/m^(n+2) (Wong's tables give kN/m^(n+1) and kN/m^(n+2): multiply by 1e3).

    p   = (k_c / b + k_phi) z^n                 pressure-sinkage, b the plate's
                                                smaller dimension (Bekker)
    tau = (c + sigma tan phi) (1 - exp(-j/K))   shear stress after a shear
                                                displacement j (Janosi-Hanamoto)

Wong, J.Y., Theory of Ground Vehicles, 4th ed., Wiley 2008, ch. 2 (soil
values, table 2.3) and ch. 4 (the rigid wheel: Wong & Reece 1967).

Only numpy (Debian's python3-numpy)."""
import math

import numpy as np

# Wong, Theory of Ground Vehicles, table 2.3: "dry sand (Land Locomotion
# Lab.)": n 1.1, k_c 0.99 kN/m^(n+1), k_phi 1528.43 kN/m^(n+2), c 1.04 kPa,
# phi 28 deg; K from Wong's fig. 2.40 range for sand (1-3 cm). A reference
# point for synthetic tests and for comparing a calibrated soil.
DRY_SAND_LLL = {"n": 1.1, "k_c": 0.99e3, "k_phi": 1528.43e3, "c": 1.04e3, "phi_deg": 28.0, "K": 0.01}


def bekker_pressure(b, z, k_c, k_phi, n):
    """p(z) under a plate of smaller dimension b (Bekker)."""
    return (k_c / b + k_phi) * np.power(np.asarray(z, float), n)


def bekker_fit(curves, refine=20):
    """Fits k_c, k_phi, n to pressure-sinkage curves of two or more plate
    widths: curves is a list of (b, z, p) with z > 0, p > 0.

    A common exponent n and one modulus k_b = k_c/b + k_phi per plate from
    ln p = ln k_b + n ln z (linear least squares), then k_c and k_phi from
    k_b = k_c (1/b) + k_phi (linear in 1/b), then Gauss-Newton on the
    pressures themselves (the log fit weights the small pressures near z = 0
    too much when the data are noisy). Returns a dict with k_c, k_phi, n and
    the relative rms residual of the pressures."""
    if len(curves) < 2 or len({float(b) for b, _, _ in curves}) < 2:
        raise ValueError("Bekker's k_c and k_phi need plates of at least two widths")
    rows, rhs = [], []
    m = len(curves)
    for i, (b, z, p) in enumerate(curves):
        z, p = np.asarray(z, float), np.asarray(p, float)
        if np.any(z <= 0) or np.any(p <= 0):
            raise ValueError("pressure-sinkage points need z > 0 and p > 0 (plate %g m)" % b)
        for zk, pk in zip(z, p):
            r = np.zeros(m + 1)
            r[0] = math.log(zk)
            r[1 + i] = 1.0
            rows.append(r)
            rhs.append(math.log(pk))
    sol = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0]
    n = sol[0]
    inv_b = np.array([1.0 / float(b) for b, _, _ in curves])
    k_b = np.exp(sol[1:])
    k_c, k_phi = np.linalg.lstsq(np.column_stack([inv_b, np.ones(m)]), k_b, rcond=None)[0]
    x = np.array([k_c, k_phi, n])
    bs = np.concatenate([np.full(len(z), float(b)) for b, z, _ in curves])
    zs = np.concatenate([np.asarray(z, float) for _, z, _ in curves])
    ps = np.concatenate([np.asarray(p, float) for _, _, p in curves])
    def ssr(y):
        return float(np.sum((ps - (y[0] / bs + y[1]) * np.power(zs, y[2])) ** 2))

    for _ in range(refine):
        zn = np.power(zs, x[2])
        model = (x[0] / bs + x[1]) * zn
        J = np.column_stack([zn / bs, zn, model * np.log(zs)])
        step = np.linalg.lstsq(J, ps - model, rcond=None)[0]
        # damped: halve the step until the residual falls (noisy measured
        # curves can send a full Gauss-Newton step far off)
        s0, t = ssr(x), 1.0
        while t > 1e-6 and not ssr(x + t * step) < s0:
            t *= 0.5
        if not t > 1e-6:
            break
        x = x + t * step
        if np.all(np.abs(t * step) <= 1e-12 * np.maximum(np.abs(x), 1.0)):
            break
    model = (x[0] / bs + x[1]) * np.power(zs, x[2])
    return {"k_c": float(x[0]), "k_phi": float(x[1]), "n": float(x[2]),
            "rms_rel": float(np.sqrt(np.mean(((ps - model) / ps) ** 2)))}


# Two-sided 95 % quantiles of Student's t for 1..30 degrees of freedom
# (standard tables); beyond 30 the normal's 1.96 is within 2 %.
_T95 = [12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145,
        2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048,
        2.045, 2.042]


def t95(dof):
    """The two-sided 95 % quantile of Student's t with dof degrees of freedom."""
    if dof < 1:
        raise ValueError("an interval needs at least one degree of freedom (got %d)" % dof)
    return _T95[dof - 1] if dof <= 30 else 1.96


def bekker_fit_runs(runs):
    """Bekker's k_c, k_phi, n from an ensemble of plate runs, with 95 %
    intervals from the scatter between runs: runs is a list of (b, z, p), one
    per run (bed, position), two or more widths with two or more runs each.

    The estimate is bekker_fit over all runs together. Its interval is the
    stratified delete-one-run jackknife (the strata are the widths): each run
    left out in turn, the fit repeated,
        var = sum_h (m_h - 1)/m_h sum_i (theta_(h,i) - mean_h theta_(h,.))^2,
    and half-width t95(N - H) sqrt(var), N runs in H widths. A run is the
    unit of independent scatter (the points of one curve are strongly
    correlated: the same grains give way under the plate), so the fit's own
    least-squares covariance over points would be far too narrow. Returns the
    bekker_fit dict plus '<name>_lo', '<name>_hi', '<name>_se' for k_c, k_phi
    and n, 'runs' and 'dof'."""
    widths = sorted({float(b) for b, _, _ in runs})
    groups = {b: [i for i, r in enumerate(runs) if float(r[0]) == b] for b in widths}
    if len(widths) < 2 or min(len(g) for g in groups.values()) < 2:
        raise ValueError("intervals need two or more runs at each of two or more plate widths")
    fit = bekker_fit(runs)
    keys = ("k_c", "k_phi", "n")
    var = dict.fromkeys(keys, 0.0)
    for b, idx in groups.items():
        m = len(idx)
        loo = [bekker_fit([r for k, r in enumerate(runs) if k != i]) for i in idx]
        for q in keys:
            v = np.array([f[q] for f in loo])
            var[q] += (m - 1.0) / m * float(np.sum((v - v.mean()) ** 2))
    dof = len(runs) - len(widths)
    t = t95(dof)
    for q in keys:
        se = math.sqrt(var[q])
        fit[q + "_se"] = se
        fit[q + "_lo"] = fit[q] - t * se
        fit[q + "_hi"] = fit[q] + t * se
    fit["runs"] = len(runs)
    fit["dof"] = dof
    return fit


def mohr_coulomb_fit(sigma, tau):
    """Cohesion c (Pa) and friction angle phi (deg) from the shear strength
    tau at normal stresses sigma: tau = c + sigma tan phi (linear least
    squares; two or more normal stresses)."""
    sigma, tau = np.asarray(sigma, float), np.asarray(tau, float)
    if len(np.unique(sigma)) < 2:
        raise ValueError("the friction angle needs shear tests at two or more normal stresses")
    tan_phi, c = np.linalg.lstsq(np.column_stack([sigma, np.ones(len(sigma))]), tau, rcond=None)[0]
    return {"c": float(c), "phi_deg": math.degrees(math.atan(tan_phi))}


def mohr_coulomb_fit_ci(sigma, tau):
    """mohr_coulomb_fit with 95 % intervals from the least-squares covariance
    (each (sigma, tau) an independent test: a sample of its own), t95 with
    N - 2 degrees of freedom; three or more tests. Adds c_lo, c_hi, phi_lo_deg,
    phi_hi_deg (through tan phi's interval) and dof."""
    sigma, tau = np.asarray(sigma, float), np.asarray(tau, float)
    if len(sigma) < 3 or len(np.unique(sigma)) < 2:
        raise ValueError("an interval for c and phi needs three or more tests at two or more normal stresses")
    A = np.column_stack([sigma, np.ones(len(sigma))])
    (tan_phi, c), res = np.linalg.lstsq(A, tau, rcond=None)[:2]
    dof = len(sigma) - 2
    s2 = float(np.sum((tau - A @ np.array([tan_phi, c])) ** 2)) / dof
    cov = s2 * np.linalg.inv(A.T @ A)
    t = t95(dof)
    dt, dc = t * math.sqrt(cov[0, 0]), t * math.sqrt(cov[1, 1])
    return {"c": float(c), "phi_deg": math.degrees(math.atan(tan_phi)), "c_lo": float(c - dc), "c_hi": float(c + dc),
            "phi_lo_deg": math.degrees(math.atan(tan_phi - dt)), "phi_hi_deg": math.degrees(math.atan(tan_phi + dt)),
            "dof": dof}


def mean_ci(x):
    """Mean and 95 % half-width t95(N - 1) s / sqrt(N) of independent samples x."""
    x = np.asarray(x, float)
    if len(x) < 2:
        raise ValueError("an interval needs two or more samples")
    return float(np.mean(x)), t95(len(x) - 1) * float(np.std(x, ddof=1)) / math.sqrt(len(x))


def janosi_fit(j, tau, tau_max=None, refine=30):
    """Shear deformation modulus K (m) of tau = tau_max (1 - exp(-j/K)) from a
    shear stress-displacement curve (j >= 0). With tau_max given only K is
    fitted, else both. Start: -ln(1 - tau/tau_max) = j/K through the points
    below 90 % of tau_max; then Gauss-Newton on tau."""
    j, tau = np.asarray(j, float), np.asarray(tau, float)
    fixed = tau_max is not None
    tm = float(tau_max) if fixed else float(np.max(tau)) * 1.02
    use = (tau < 0.9 * tm) & (j > 0) & (tau > 0)
    if np.count_nonzero(use) < 2:
        raise ValueError("too few points below 90 % of the shear strength to fit K")
    y = -np.log(1.0 - tau[use] / tm)
    K = float(np.sum(j[use] ** 2) / np.sum(j[use] * y))
    for _ in range(refine):
        e = np.exp(-j / K)
        model = tm * (1.0 - e)
        dK = -tm * e * j / K ** 2
        if fixed:
            J = dK[:, None]
        else:
            J = np.column_stack([dK, 1.0 - e])
        step = np.linalg.lstsq(J, tau - model, rcond=None)[0]
        K += step[0]
        if not fixed:
            tm += step[1]
        if abs(step[0]) <= 1e-12 * abs(K):
            break
    return {"K": float(K), "tau_max": float(tm)}


def wong_reece(R, b, W, slip, soil, c1=0.43, c2=0.32, n_quad=2000):
    """Steady rigid wheel on soft soil (Wong & Reece 1967; Wong, ch. 4): the
    entry angle theta_1 that carries the vertical load W, and with it the
    sinkage z, the drawbar pull DP = H - R_c (the integral of the horizontal
    stresses), the driving torque T and the gross thrust H.

    Normal stress over the arc (theta from the bottom-dead-centre, positive
    towards the front), maximum at theta_m = (c1 + c2 s) theta_1:
      front, theta_m..theta_1: sigma = k R^n (cos th - cos th_1)^n
      rear,  0..theta_m:       sigma = k R^n (cos(th_1 - th/th_m (th_1 - th_m)) - cos th_1)^n
    k = k_c/b + k_phi; shear tau = (c + sigma tan phi)(1 - exp(-j/K)) with
    j(th) = R [(th_1 - th) - (1 - s)(sin th_1 - sin th)] (driving, s >= 0).
      W  = R b int (sigma cos th + tau sin th) dth
      DP = R b int (tau cos th - sigma sin th) dth
      T  = R^2 b int tau dth
    The exit angle is taken as 0 (no rebound). Returns a dict."""
    k = soil["k_c"] / b + soil["k_phi"]
    n, c, tphi, K = soil["n"], soil.get("c", 0.0), math.tan(math.radians(soil.get("phi_deg", 0.0))), soil.get("K", 1.0)

    def integrals(th1):
        th = np.linspace(0.0, th1, n_quad + 1)
        thm = (c1 + c2 * slip) * th1
        front = th >= thm
        base = np.where(front, np.cos(th),
                        np.cos(th1 - np.where(thm > 0, th / max(thm, 1e-300), 0.0) * (th1 - thm)))
        sigma = k * R ** n * np.power(np.maximum(base - math.cos(th1), 0.0), n)
        j = R * ((th1 - th) - (1.0 - slip) * (math.sin(th1) - np.sin(th)))
        tau = (c + sigma * tphi) * (1.0 - np.exp(-np.maximum(j, 0.0) / K))
        w = np.full(n_quad + 1, th1 / n_quad)
        w[0] = w[-1] = 0.5 * th1 / n_quad  # trapezoid
        Wz = R * b * np.sum(w * (sigma * np.cos(th) + tau * np.sin(th)))
        DP = R * b * np.sum(w * (tau * np.cos(th) - sigma * np.sin(th)))
        H = R * b * np.sum(w * tau * np.cos(th))
        T = R * R * b * np.sum(w * tau)
        return Wz, DP, H, T

    lo, hi = 1e-6, 0.5 * math.pi
    if integrals(hi)[0] < W:
        raise ValueError("the soil cannot carry %g N under this wheel even at 90 degrees of contact" % W)
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if integrals(mid)[0] < W:
            lo = mid
        else:
            hi = mid
    th1 = 0.5 * (lo + hi)
    Wz, DP, H, T = integrals(th1)
    return {"theta1": th1, "sinkage": R * (1.0 - math.cos(th1)), "drawbar_pull": DP, "thrust": H,
            "motion_resistance": H - DP, "torque": T, "load": Wz}


def bekker_wheel_sinkage(R, b, W, soil):
    """Bekker's closed-form sinkage of a rigid wheel (circle replaced by a
    parabola, small sinkage; Wong eq. 4.13):
      z0 = [3 W / ((3 - n)(k_c + b k_phi) sqrt(2R))]^(2/(2n+1))"""
    n = soil["n"]
    return (3.0 * W / ((3.0 - n) * (soil["k_c"] + b * soil["k_phi"]) * math.sqrt(2.0 * R))) ** (2.0 / (2.0 * n + 1.0))
