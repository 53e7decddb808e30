"""The analyses of the calibration's virtual soil tests (issue 15), one place
each, reading what the rigs and dem_server wrote:

  shear_box(rows, ...)   direct shear box (shear_rig's shear_box.csv): peak
                         and residual tau/sigma_n on the shear plane, friction
                         angles, dilation, bulk density of the sample
  heap_angle(x, r, ...)  angle of repose of a heap (a dem_grains.h5 frame)
  solid_fraction(x, r, lo, hi)  of the grains in a box (bulk density away from walls)
  sample_mass(radius, rho)

Fits across tests (Mohr-Coulomb, Janosi, Bekker) are terramech.py's."""
import math

import numpy as np

G = 9.81


def sample_mass(radius, rho):
    """Mass (kg) of spheres of the given radii (m) and solid density (kg/m^3)."""
    r = np.asarray(radius, dtype=float)
    return float(rho * 4.0 / 3.0 * math.pi * np.sum(r ** 3))


def solid_fraction(x, r, lo, hi):
    """Solid fraction of spheres (centres x, n x 3, radii r, m) in the box
    [lo, hi]: the volume of the spheres whose centres lie inside over the
    box's volume (spheres cut by the box's faces count wholly inside or not
    at all: unbiased for a random packing, exact on average)."""
    x = np.asarray(x, dtype=float)
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    inside = np.all((x >= lo) & (x < hi), axis=1)
    return float(4.0 / 3.0 * math.pi * np.sum(np.asarray(r)[inside] ** 3) / np.prod(hi - lo))


def shear_box(rows, mass, box, lower_height, residual_from=0.75):
    """Reads shear_rig's rows (dicts of floats) for a sample of `mass` kg in a
    box of inner size box = (L, W) m with the shear plane lower_height m
    above the floor.

    The normal force on the shear plane is the lid's push, plus the upper
    walls' (the grains rub on the fixed upper walls as they are pressed and
    dilate: the rig's upper_wall_fz is the force up on the walls, so the
    walls push the upper grains down by as much), plus the weight of the
    grains above the plane (the sample's mass times the share of its height
    above the plane). tau/sigma is taken against that force; against the
    lid's force alone too (`*_lid`) for comparison.

    Returns a dict: peak and residual ratio and angle (deg), the displacement
    of the peak (m), the dilation (lid rise from the start of the shear to
    the end, m) and the largest rise rate (dilatancy angle, deg), sigma_n
    (Pa, mean on the plane over the shear), bulk density (kg/m^3, sample mass
    over the box volume under the lid at the start of the shear), and the
    curves (displacement, smoothed ratio, height; without the ends the
    smoothing cannot cover) for the charts and Janosi's fit. residual: the mean
    over the last (1 - residual_from) of the travel."""
    L, W = box
    area = L * W
    sh = [r for r in rows if r["phase"] == 2]
    if len(sh) < 10:
        raise ValueError("shear_box: %d rows in the shear phase (did the servo reach sigma_n?)" % len(sh))
    d = np.array([r["displacement"] for r in sh])
    h = np.array([r["height"] for r in sh])
    up = mass * G * np.clip((h - lower_height) / h, 0.0, 1.0)
    n_lid = np.array([r["normal_force"] for r in sh])
    n_plane = n_lid + np.array([r["upper_wall_fz"] for r in sh]) + up
    t = np.array([r["shear_force"] for r in sh])
    ratio, ratio_lid = t / n_plane, t / n_lid
    # smooth over ~0.25 mm of travel: single grains rearranging make the
    # force jump from exchange to exchange
    k = max(1, int(round(2.5e-4 / max(d[1] - d[0], 1e-12))))
    kern = np.ones(k) / k
    sm = np.convolve(ratio, kern, mode="same")
    sm_lid = np.convolve(ratio_lid, kern, mode="same")
    inner = slice(k, len(sm) - k) if len(sm) > 3 * k else slice(0, len(sm))
    i_pk = int(np.argmax(sm[inner])) + inner.start
    tail = d >= residual_from * d[-1]
    res, res_lid = float(np.mean(ratio[tail])), float(np.mean(ratio_lid[tail]))
    pk, pk_lid = float(sm[i_pk]), float(np.max(sm_lid[inner]))
    dh = np.gradient(np.convolve(h, kern, mode="same"), d)
    return {
        "peak_ratio": pk,
        "peak_angle": math.degrees(math.atan(pk)),
        "peak_displacement": float(d[i_pk]),
        "residual_ratio": res,
        "residual_angle": math.degrees(math.atan(res)),
        "peak_ratio_lid": pk_lid,
        "residual_ratio_lid": res_lid,
        "sigma_n": float(np.mean(n_plane) / area),
        "sigma_n_lid": float(np.mean(n_lid) / area),
        "dilation": float(h[-1] - h[0]),
        "dilatancy_angle": math.degrees(math.atan(float(np.max(dh[inner])))),
        "bulk_density": mass / (area * h[0]),
        "travel": float(d[-1]),
        "curve_d": d[inner],
        "curve_ratio": sm[inner],
        "curve_h": h[inner],
    }


def heap_angle(x, r, floor_z=0.0, centre=None, ring=None):
    """Angle of repose (deg) of a heap of spheres: centres x (n x 3, m),
    radii r (m) on a floor at floor_z. The heap's surface is the highest
    grain top (z + r) in rings of width `ring` (default 2 r_max) around
    `centre` (default the grains' mean x, y); the slope is the least-squares
    line through the rings of the flank: from the first ring (not the
    central one) whose top is below 85 % of the heap's height (above, the
    rounded apex or the plateau a collapsed column keeps) outwards, as long
    as the tops stay at least two grain diameters above the floor (below,
    the toe of single grains is not the heap). A flat layer (fewer than two
    such rings) has angle 0.

    Returns (angle_deg, dict with the ring radii and tops used)."""
    x = np.asarray(x, dtype=float)
    r = np.asarray(r, dtype=float)
    if centre is None:
        centre = (float(np.mean(x[:, 0])), float(np.mean(x[:, 1])))
    ring = ring or 2.0 * float(np.max(r))
    rho = np.hypot(x[:, 0] - centre[0], x[:, 1] - centre[1])
    top = x[:, 2] + r - floor_z
    nb = int(np.max(rho) / ring) + 1
    rr, tt = [], []
    for b in range(nb):
        m = (rho >= b * ring) & (rho < (b + 1) * ring)
        if np.count_nonzero(m) == 0:
            continue
        rr.append((b + 0.5) * ring)
        tt.append(float(np.max(top[m])))
    rr, tt = np.array(rr), np.array(tt)
    d = 2.0 * float(np.mean(r))
    used = np.zeros(len(rr), bool)
    below = np.nonzero((tt <= 0.85 * float(np.max(tt))) & (np.arange(len(rr)) >= 1))[0]
    if len(below):  # contiguous, from there out to the toe: a stray grain further out is not the flank
        for k in range(below[0], len(rr)):
            if tt[k] < 2.0 * d:
                break
            used[k] = True
    if np.count_nonzero(used) < 2:
        return 0.0, {"ring_r": rr, "ring_top": tt, "used": used}
    slope = np.polyfit(rr[used], tt[used], 1)[0]
    return math.degrees(math.atan(max(0.0, -slope))), {"ring_r": rr, "ring_top": tt, "used": used}
