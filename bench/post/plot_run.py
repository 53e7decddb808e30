#!/usr/bin/python3
"""Pictures of one scene run, from its outputs alone (no ParaView).

usage: bench/post/plot_run.py OUTDIR [--png-dir DIR] [--time T ...]
                              [--wheel-y Y] [--rim-frame] [--no-views]

OUTDIR is a run's output folder (./run SCENE --out OUTDIR; default
out/<scene name>). Writes into OUTDIR (or --png-dir):

  run_series.png    vertical load, T_H, T_R, T_P and sinkage against time,
                    phases shaded, the steady part fem_server averaged
                    (summary.json: every quantity past its transient, whole
                    lug periods) marked and its means drawn
  run_traction.png  bar chart of T_H, T_R, T_P over the steady part: mean,
                    min and max, and the 95 % confidence interval of the mean
                    (as fig. 15 of Michael et al.), with the mean vertical
                    load they were measured under and T/W
  run_side_<t>.png  side view (from -y) of the deformed tire coloured by
                    eps33, the vertical strain; grains behind the wheel's
                    mid-plane as discs coloured by their x velocity
                    (figs. 16-17)
  run_back_<t>.png  back view (from behind, looking along +x), same colours;
                    grains ahead of the axle plane
  run_bottom_<t>.png bottom view of the tread: strain in the travel direction
                    (the paper's eps22) and eps33 (fig. 19)

<t> is the snapshot time in ms; by default the last tire snapshot (and the
grain frame nearest to it). Strains are turned into the world frame
(x travel, y axle, z up) with the wheel's angle at that time: fem.h5 stores
them in the rim frame, which turns with the wheel (--rim-frame shows the
stored components instead; there eps22 is the axle direction).
The tire is placed with the wheel centre of traction.csv; its y comes from a
scene file in OUTDIR (the slip sweep copies it there), --wheel-y, or else the
middle of the grain bed.
"""
import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import numpy as np  # noqa: E402

import runio  # noqa: E402

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.collections import EllipseCollection, PolyCollection  # noqa: E402

PHASE_COLOURS = {0: "#d9e8f5", 1: "#dff0d8", 2: "#eeeeee", 3: "#f5e6d9"}


def log(msg):
    print("[plot_run] " + msg, flush=True)


# ---- time series ----------------------------------------------------------------

def phase_spans(t, phase):
    """[(phase, t0, t1)] of the contiguous phases."""
    spans = []
    if len(t) == 0:
        return spans
    p = np.round(phase).astype(int)
    cut = np.flatnonzero(np.diff(p)) + 1
    starts = np.concatenate([[0], cut])
    ends = np.concatenate([cut, [len(t)]])
    for a, b in zip(starts, ends):
        t0 = t[a - 1] if a > 0 else 0.0
        spans.append((int(p[a]), t0, t[b - 1]))
    return spans


def moving_average(x, w):
    if w <= 1 or len(x) < w:
        return x
    c = np.cumsum(np.concatenate([[0.0], x]))
    m = (c[w:] - c[:-w]) / w
    pad = w // 2
    return np.concatenate([np.full(pad, np.nan), m, np.full(len(x) - len(m) - pad, np.nan)])


def travel_summary(outdir, d):
    """(steady start time, steady end time, travel indices, stats) from the
    run's summary.json (fem_server computes them; nothing is recomputed
    here), or None when the run has none or never travelled."""
    s = runio.read_summary(outdir)
    if s is None or not s.get("travelled"):
        return None
    idx = runio.travel_rows(d)
    return s["steady"]["start_time"], s["steady"]["end_time"], idx, s["stats"]


def plot_series(d, summary, path, title):
    t = d["t"]
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    w = max(1, int(round(0.005 / dt)))
    panels = [("Fz", "vertical load $F_z$ [N]", 1.0), ("T_H", "$T_H$ gross traction [N]", 1.0),
              ("T_R", "$T_R$ running resistance [N]", 1.0), ("T_P", "$T_P$ drawbar pull [N]", 1.0),
              ("sinkage", "sinkage [mm]", 1e3)]
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(10, 12))
    spans = phase_spans(t, d["phase"])
    for ax, (col, label, scale) in zip(axes, panels):
        for p, t0, t1 in spans:
            ax.axvspan(t0, t1, color=PHASE_COLOURS.get(p, "#ffffff"), lw=0, zorder=0)
        y = d[col] * scale
        ax.plot(t, y, color="0.55", lw=0.4, zorder=1, label="every exchange")
        if w > 1 and col != "sinkage":
            ax.plot(t, moving_average(y, w), color="C0", lw=1.2, zorder=2,
                    label="%.0f ms moving average" % (w * dt * 1e3))
        if summary is not None:
            ts, t_end, idx, stats = summary
            ax.axvline(ts, color="C3", ls="--", lw=1.2, zorder=3,
                       label="steady part from t = %.3f s" % ts)
            if col in stats:
                st = stats[col]
                ax.hlines(st.mean * scale, ts, t_end, color="C3", lw=1.8, zorder=4,
                          label="steady mean %.4g ± %.2g" % (st.mean * scale, st.half_width * scale))
                # keep the axis on the interesting range: the raw signal has
                # single-exchange spikes of many times the mean
        lo, hi = np.nanpercentile(y, [0.5, 99.5]) if len(y) else (0, 1)
        pad = 0.15 * (hi - lo) if hi > lo else 1.0
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_ylabel(label)
        ax.grid(True, lw=0.3)
        ax.legend(loc="upper left", fontsize=7, ncol=2, framealpha=0.8)
    # phase legend on the top panel
    from matplotlib.patches import Patch
    seen = sorted({p for p, _, _ in spans})
    handles = [Patch(color=PHASE_COLOURS.get(p, "#fff"), label=runio.PHASE_NAMES.get(p, str(p)) + " phase")
               for p in seen]
    if handles:
        axes[0].add_artist(axes[0].legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.8))
        axes[0].legend(loc="upper left", fontsize=7, ncol=2, framealpha=0.8)
    axes[-1].set_xlabel("time t [s]")
    axes[0].set_title(title + "\n(y ranges clipped to the 0.5–99.5 % percentiles of each signal)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    log("wrote " + path)


def plot_traction_bars(summary, slip, path, title):
    ts, te, idx, stats = summary
    names = ["T_H", "T_R", "T_P"]
    labels = ["$T_H$\ngross traction", "$T_R$\nrunning resistance", "$T_P$\ndrawbar pull"]
    means = np.array([stats[k].mean for k in names])
    mins = np.array([stats[k].min for k in names])
    maxs = np.array([stats[k].max for k in names])
    ci = np.array([stats[k].half_width for k in names])
    fig, ax = plt.subplots(figsize=(7, 5.5))
    x = np.arange(3)
    ax.bar(x, means, color=["C2", "C1", "C0"], width=0.55, alpha=0.8, label="steady mean")
    ax.errorbar(x, means, yerr=[means - mins, maxs - means], fmt="none", ecolor="0.3", elinewidth=1,
                capsize=10, label="min / max (single exchanges)")
    ax.errorbar(x + 0.12, means, yerr=ci, fmt="none", ecolor="C3", elinewidth=2.5, capsize=5,
                label="95 % CI of the mean (batch means)")
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xticks(x)
    ax.set_xticklabels(["%s\n%.1f ± %.1f N\n[%.0f, %.0f]\n%s/W = %.3f ± %.3f" % (
                        lab, m, c, lo, hi, k, stats[k + "_per_W"].mean, stats[k + "_per_W"].half_width)
                        for k, lab, m, c, lo, hi in zip(names, labels, means, ci, mins, maxs)])
    ax.set_ylabel("force [N]")
    ax.set_xlabel("steady mean ± 95 % CI [min, max]", fontsize=8)
    n = stats["T_P"].count
    W = stats["load"]
    ax.set_title("%s\nslip %.1f %%, load W = %.1f ± %.1f N, steady part t = %.3f to %.3f s (%d exchanges)"
                 % (title, 100 * slip, W.mean, W.half_width, ts, te, n), fontsize=10)
    ax.legend(fontsize=8, loc="best")
    ax.grid(True, axis="y", lw=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    log("wrote " + path)


# ---- tire and grain pictures ------------------------------------------------------

class Scene3D:
    """The deformed tire surface in world coordinates with per-face strains,
    and a grain frame, at one time."""

    def __init__(self, outdir, d, t_snap, wheel_y, rim_frame):
        fem = os.path.join(outdir, "fem.h5")
        tets, _ = runio.read_fem_mesh(fem)
        snaps = runio.fem_snapshots(fem)
        self.time, name = min(snaps, key=lambda s: abs(s[0] - t_snap))
        s = runio.read_fem_snapshot(fem, name)
        faces, owner = runio.boundary_faces(tets)
        pos = s["position"]
        # orient the faces outwards (node order of the tetrahedra may be either)
        cen_tet = pos[tets].mean(axis=1)
        n = np.cross(pos[faces[:, 1]] - pos[faces[:, 0]], pos[faces[:, 2]] - pos[faces[:, 0]])
        inward = np.einsum("ij,ij->i", n, pos[faces].mean(axis=1) - cen_tet[owner]) < 0
        faces[inward] = faces[inward][:, ::-1]
        # wheel pose at the snapshot time
        t = d["t"]
        tt = self.time
        self.angle = float(np.interp(tt, t, d["angle"])) if len(t) else 0.0
        xc = float(np.interp(tt, t, d["x"])) if len(t) else 0.0
        zc = float(np.interp(tt, t, d["z"])) if len(t) else 0.0
        self.phase = int(round(float(np.interp(tt, t, d["phase"])))) if len(t) else 0
        self.center = np.array([xc, wheel_y if wheel_y is not None else 0.0, zc])
        R = runio.rotation_y(self.angle)
        self.R = R
        self.faces = faces
        self.owner = owner
        eps = runio.tensor6_to_matrix(s["strain"])
        # fem_server writes snapshots in the world frame (positions c + R(X+u),
        # strain R e R^T); older files were in the rim frame.
        self.world_frame = runio.fem_world_frame(fem)
        if self.world_frame:
            if wheel_y is None:
                self.center[1] = float(pos[:, 1].mean())
                wheel_y = self.center[1]
            self.pos_rim = (pos - self.center) @ R
            self.world = pos
            eps = np.einsum("ba,nbc,cd->nad", R, eps, R)  # back to the rim frame: R^T e R
        else:
            self.pos_rim = pos
        if rim_frame:
            self.eps_travel = s["eps22"] if "eps22" in s else eps[:, 1, 1]
            self.eps_vert = s["eps33"] if "eps33" in s else eps[:, 2, 2]
            self.travel_label = r"$\varepsilon_{22}$ as stored (rim frame yy: axle direction)"
            self.vert_label = r"$\varepsilon_{33}$ as stored (rim frame zz)"
        else:
            ew = np.einsum("ab,nbc,dc->nad", R, eps, R)
            self.eps_travel = ew[:, 0, 0]
            self.eps_vert = ew[:, 2, 2]
            self.travel_label = r"strain in the travel direction $\varepsilon_{xx}$ (paper's $\varepsilon_{22}$)"
            self.vert_label = r"vertical strain $\varepsilon_{zz}$ (paper's $\varepsilon_{33}$, sinkage direction)"
        self.grains = None
        self.grain_time = None
        gpath = os.path.join(outdir, "dem_grains.h5")
        if os.path.exists(gpath):
            try:
                frames = runio.grain_frames(gpath)
                if frames:
                    gt, gname = min(frames, key=lambda f: abs(f[0] - tt))
                    self.grains = runio.read_grain_frame(gpath, gname)
                    self.grain_time = gt
            except (OSError, KeyError) as e:
                log("cannot read %s (%s): tire without grains" % (gpath, e))
        if wheel_y is None:
            if self.grains is not None:
                gy = self.grains["position"][:, 1]
                self.center[1] = 0.5 * (gy.min() + gy.max())
                log("wheel centre y not known: taking the middle of the grain bed, y = %.4f m "
                    "(give --wheel-y or put the scene file in the run folder)" % self.center[1])
            else:
                log("wheel centre y not known and no grains: y = 0")
        if not self.world_frame:
            self.world = self.center + pos @ R.T

    def faces_for_view(self, view_axis, sign):
        """Visible faces for a viewer looking along sign * axis, far to near."""
        X = self.world
        P = X[self.faces]
        n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
        # the viewer looks along +axis (sign = +1) from the negative side: a
        # face is visible when its outward normal points back at the viewer
        vis = sign * n[:, view_axis] < 0
        depth = sign * P[:, :, view_axis].mean(axis=1)
        order = np.argsort(-depth[vis])  # far first
        return np.flatnonzero(vis)[order]


def sym_limits(values, pct=99.0):
    v = np.abs(values[np.isfinite(values)])
    a = np.percentile(v, pct) if len(v) else 1.0
    return -(a if a > 0 else 1e-9), (a if a > 0 else 1e-9)


def draw_tire(ax, sc, fidx, values, axes2d, vlim, cmap="RdBu_r"):
    P = sc.world[sc.faces[fidx]][:, :, axes2d]
    vals = values[sc.owner[fidx]]
    pc = PolyCollection(P, array=vals, cmap=cmap, clim=vlim, edgecolors="face", linewidths=0.15, zorder=3)
    ax.add_collection(pc)
    return pc


def draw_grains(ax, g, sel, axes2d, depth_axis, depth_sign, vlim, cmap="PuOr_r", zorder=2):
    pos = g["position"][sel]
    order = np.argsort(-depth_sign * pos[:, depth_axis])
    pos = pos[order]
    r = g["radius"][sel][order]
    v = g["velocity"][sel][order][:, 0]
    ec = EllipseCollection(2 * r, 2 * r, np.zeros_like(r), units="xy", offsets=pos[:, axes2d],
                           offset_transform=ax.transData, array=v, cmap=cmap, clim=vlim,
                           edgecolors="0.25", linewidths=0.1, zorder=zorder)
    ax.add_collection(ec)
    return ec


def view_title(sc, what):
    ph = runio.PHASE_NAMES.get(sc.phase, str(sc.phase))
    s = "%s\ntire at t = %.3f s (%s phase), wheel centre x = %.3f m, z = %.3f m" % (
        what, sc.time, ph, sc.center[0], sc.center[2])
    if sc.grain_time is not None:
        s += "\ngrain frame t = %.3f s" % sc.grain_time
        if abs(sc.grain_time - sc.time) > 1e-6:
            s += " (nearest to the tire snapshot: %+.0f ms)" % (1e3 * (sc.grain_time - sc.time))
    else:
        s += "\n(no grain frames)"
    return s


def finish_view(fig, ax, pcs, labels, path):
    ax.set_aspect("equal")
    for k, (pc, lab) in enumerate(zip(pcs, labels)):
        if pc is not None:
            cb = fig.colorbar(pc, ax=ax, orientation="horizontal", fraction=0.05, pad=0.01, aspect=40)
            cb.set_label(lab, fontsize=9)
            cb.ax.tick_params(labelsize=8)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    log("wrote " + path)


def grain_vlim(g, sel):
    """Symmetric limits of v_x: the 99th percentile of |v_x|, at least
    0.02 m/s (a bed at rest is then white, not coloured by its noise)."""
    if g is None or not np.any(sel):
        return (-1, 1)
    lo, hi = sym_limits(g["velocity"][sel][:, 0], 99.0)
    a = max(hi, 0.02)
    return (-a, a)


def plot_side(sc, path, title):
    c = sc.center
    rad = np.max(np.linalg.norm(sc.pos_rim[:, [0, 2]], axis=1))
    fidx = sc.faces_for_view(1, +1)
    fig, ax = plt.subplots(figsize=(10, 8), layout="constrained")
    gpc = None
    zlo = c[2] - rad - 0.02
    if sc.grains is not None:
        p = sc.grains["position"]
        zlo = min(zlo, p[:, 2].min() - 0.01)
        sel = (p[:, 1] >= c[1]) & (np.abs(p[:, 0] - c[0]) < 2.2 * rad)
        gpc = draw_grains(ax, sc.grains, sel, [0, 2], 1, +1, grain_vlim(sc.grains, sel))
    tpc = draw_tire(ax, sc, fidx, sc.eps_vert, [0, 2], sym_limits(sc.eps_vert[sc.owner[fidx]]))
    xlo, xhi = c[0] - rad - 0.02, c[0] + rad + 0.02
    if gpc is not None and np.any(sel):
        xs = p[sel, 0]
        xlo, xhi = min(xlo, xs.min() - 0.01), max(xhi, xs.max() + 0.01)
    ax.set_xlim(xlo, xhi)
    ax.set_ylim(zlo, c[2] + rad + 0.02)
    ax.set_xlabel("x [m] (travel →)")
    ax.set_ylabel("z [m]")
    fig.suptitle(title + "\n" + view_title(sc, "side view from -y, grains behind the wheel's mid-plane"),
                 fontsize=9)
    finish_view(fig, ax, [gpc, tpc], ["grains: velocity $v_x$ [m/s]", "tire: " + sc.vert_label], path)


def plot_back(sc, path, title):
    c = sc.center
    rad = np.max(np.linalg.norm(sc.pos_rim[:, [0, 2]], axis=1))
    fidx = sc.faces_for_view(0, +1)
    fig, ax = plt.subplots(figsize=(7, 10.5), layout="constrained")
    gpc = None
    zlo = c[2] - rad - 0.02
    ylo, yhi = c[1] - 0.15, c[1] + 0.15
    if sc.grains is not None:
        p = sc.grains["position"]
        zlo = min(zlo, p[:, 2].min() - 0.01)
        ylo, yhi = min(ylo, p[:, 1].min() - 0.01), max(yhi, p[:, 1].max() + 0.01)
        sel = (p[:, 0] >= c[0]) & (p[:, 0] < c[0] + 0.6 * rad)
        gpc = draw_grains(ax, sc.grains, sel, [1, 2], 0, +1, grain_vlim(sc.grains, sel))
    tpc = draw_tire(ax, sc, fidx, sc.eps_vert, [1, 2], sym_limits(sc.eps_vert[sc.owner[fidx]]))
    ax.set_xlim(yhi, ylo)  # seen from behind (looking along +x), +y is on the left
    ax.set_ylim(zlo, c[2] + rad + 0.02)
    ax.set_xlabel("y [m] (axle direction; seen from behind, +y to the left)")
    ax.set_ylabel("z [m]")
    fig.suptitle(title + "\n" + view_title(sc, "back view looking along +x,\ngrains ahead of the axle plane"),
                 fontsize=9)
    finish_view(fig, ax, [gpc, tpc], ["grains: velocity $v_x$ [m/s]", "tire: " + sc.vert_label], path)


def plot_bottom(sc, path, title):
    c = sc.center
    fidx = sc.faces_for_view(2, +1)  # viewer below, looking up along +z
    # keep the lower half: the upper half is hidden behind it anyway
    low = sc.world[sc.faces[fidx]][:, :, 2].mean(axis=1) < c[2]
    fidx = fidx[low]
    fig, axs = plt.subplots(1, 2, figsize=(12, 4.8), layout="constrained")
    for ax, vals, lab in ((axs[0], sc.eps_travel, sc.travel_label), (axs[1], sc.eps_vert, sc.vert_label)):
        pc = draw_tire(ax, sc, fidx, vals, [0, 1], sym_limits(vals[sc.owner[fidx]]))
        ax.set_xlim(c[0] - 0.2, c[0] + 0.2)
        ax.set_ylim(c[1] + 0.11, c[1] - 0.11)  # seen from below, +y points down
        ax.set_aspect("equal")
        ax.set_xlabel("x [m] (travel →)")
        ax.set_ylabel("y [m] (seen from below)")
        cb = fig.colorbar(pc, ax=ax, orientation="horizontal", pad=0.12, shrink=0.9)
        cb.set_label(lab, fontsize=9)
        ax.annotate("", xy=(c[0] + 0.17, c[1] - 0.095), xytext=(c[0] + 0.09, c[1] - 0.095),
                    arrowprops=dict(arrowstyle="->", lw=1.5))
        ax.text(c[0] + 0.13, c[1] - 0.1, "travel", ha="center", va="bottom", fontsize=8)
    fig.suptitle(title + "\n" + "\n".join(view_title(sc, "bottom view of the tread").split("\n")[:2]), fontsize=9)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    log("wrote " + path)


# ---- main --------------------------------------------------------------------------

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("outdir", help="a run's output folder (traction.csv, fem.h5, dem_grains.h5)")
    ap.add_argument("--png-dir", help="where the PNGs go (default: OUTDIR)")
    ap.add_argument("--time", type=float, action="append",
                    help="time [s] of the tire pictures (nearest snapshot; repeatable; default: the last)")
    ap.add_argument("--wheel-y", type=float, help="wheel centre y [m] (default: from a scene file in OUTDIR)")
    ap.add_argument("--rim-frame", action="store_true", help="colour by the strains as stored (rim frame)")
    ap.add_argument("--no-views", action="store_true", help="only the time series and the bar chart")
    ap.add_argument("--title", help="title prefix (default: the folder name)")
    a = ap.parse_args(argv)

    outdir = a.outdir
    png = a.png_dir or outdir
    os.makedirs(png, exist_ok=True)
    title = a.title or "run %s" % os.path.basename(os.path.abspath(outdir))
    made = 0

    tpath = os.path.join(outdir, "traction.csv")
    d = None
    if os.path.exists(tpath):
        d = runio.read_traction(tpath)
        if len(d["t"]) == 0:
            log("traction.csv has no rows: no time series")
            d = None
    else:
        log("no traction.csv in %s: no time series" % outdir)
    summary = None
    if d is not None:
        summary = travel_summary(outdir, d)
        if summary is None:
            log("no summary.json of a travelled run: no steady statistics")
        else:
            ts, te, idx, stats = summary
            log("steady part of the travel (fem_server's summary.json): t = %.4f to %.4f s" % (ts, te))
            for k in ("T_H", "T_R", "T_P", "load"):
                st = stats[k]
                log("  %-4s mean %9.2f N  (95%% CI +-%7.2f N, %d batches)  min %9.2f  max %9.2f"
                    % (k, st.mean, st.half_width, st.batches, st.min, st.max))
            log("  sinkage mean %.1f mm (95%% CI +-%.1f mm)" % (1e3 * stats["sinkage"].mean,
                                                              1e3 * stats["sinkage"].half_width))
        plot_series(d, summary, os.path.join(png, "run_series.png"), title)
        made += 1
        if summary is not None:
            slip = float(np.median(d["slip"][summary[2]]))
            plot_traction_bars(summary, slip, os.path.join(png, "run_traction.png"), title)
            made += 1

    fem = os.path.join(outdir, "fem.h5")
    if a.no_views:
        pass
    elif not os.path.exists(fem):
        log("no fem.h5: no tire pictures")
    elif d is None:
        log("no traction.csv: cannot place the tire, no tire pictures")
    else:
        try:
            snaps = runio.fem_snapshots(fem)
        except (OSError, KeyError) as e:
            log("cannot read %s (%s): no tire pictures" % (fem, e))
            snaps = []
        if not snaps:
            log("fem.h5 holds no tire snapshot yet: no tire pictures")
        else:
            wheel_y = a.wheel_y if a.wheel_y is not None else runio.read_scene_wheel_y(outdir)
            times = a.time or [snaps[-1][0]]
            for tq in times:
                sc = Scene3D(outdir, d, tq, wheel_y, a.rim_frame)
                tag = "%06.0fms" % (1e3 * sc.time)
                plot_side(sc, os.path.join(png, "run_side_%s.png" % tag), title)
                plot_back(sc, os.path.join(png, "run_back_%s.png" % tag), title)
                plot_bottom(sc, os.path.join(png, "run_bottom_%s.png" % tag), title)
                made += 3
    log("%d pictures in %s" % (made, png))
    return 0 if made else 1


if __name__ == "__main__":
    sys.exit(main())
