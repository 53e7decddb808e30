#!/usr/bin/python3
"""The tire's deflection on the rigid floor under refinement (bench_deflection's
CSV), its converged value, and each (element, resolution)'s error against
what an explicit run pays for it.

    plot_deflection.py IN.csv OUT.png [STEPS.csv ...]

Integer resolutions mesh the same tire (fem_mesh.c: uniform refinement, h ~
1/resolution); RES/N rows set fem.mesh.layers = N (cells through the wall
and the lugs). The converged value (converged() below): the thickness limit
from three or more layer counts at one resolution, plus the surface's share
from the same layer count at that resolution and twice it. The order of
the latter is not observed and is bracketed: from 1.09 (the lugs stand on
the carcass with re-entrant 90 degree edges, 270 degrees inside, where the
stress goes as r^(lambda - 1), lambda = 0.5445 (Williams, mode I): a
compliance converges as h^(2 lambda) at worst) to 3.

STEPS.csv: bench_fem's per-element step costs (quantity,value,unit with
element, resolution, explicit_cost_per_simulated_second): the cost of an
explicit run (CPU seconds per simulated second, one thread) for the
(element, resolution) they measured; the others are scaled from the nearest
measured one of the same element by nodes and stable step (marked "est.").
The step_ms of bench_deflection's CSV is not used for the cost: the machine
it ran on was shared.

Writes OUT.png (deflection against h with the converged band; error against
cost per simulated second) and prints the table as Markdown.
"""
import csv
import math
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ELEMENTS = ("tet4", "tet10")


def read_rows(path):
    with open(path, newline="") as f:
        rows = []
        for r in csv.DictReader(f):
            if r["element"] not in ELEMENTS:
                continue  # e.g. tet4_refactor: the reference floor method's cost
            res, _, layers = r["resolution"].partition("/")  # RES/LAYERS: fem.mesh.layers set
            r["resolution"], r["layers"] = float(res), int(layers) if layers else 0
            r["label"] = f"{r['resolution']:g}" + (f", {r['layers']} layers" if r["layers"] else "")
            for k in ("deflection_mm", "dt_limit_s"):
                r[k] = float(r[k])
            for k in ("nodes", "tets"):
                r[k] = int(r[k])
            rows.append(r)
    return rows


def read_steps(paths):
    cost = {}
    for p in paths:
        q = {}
        with open(p, newline="") as f:
            for r in csv.DictReader(f):
                q[r["quantity"]] = r["value"]
        if "explicit_cost_per_simulated_second" in q:
            cost[(q["element"], float(q["resolution"]))] = (float(q["explicit_cost_per_simulated_second"]),
                                                            int(q["nodes"]))
    return cost


def solve_order(h, d):
    """p and D with D(h) = D - C h^p through three points (h1 > h2 > h3)."""
    (h1, h2, h3), (d1, d2, d3) = h, d
    target = (d2 - d1) / (d3 - d2)

    def f(p):
        return (h1 ** p - h2 ** p) / (h2 ** p - h3 ** p) - target

    lo, hi = 0.05, 8.0
    if f(lo) * f(hi) > 0:
        return None, None
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if f(lo) * f(mid) <= 0:
            hi = mid
        else:
            lo = mid
    p = 0.5 * (lo + hi)
    c = (d2 - d3) / (h3 ** p - h2 ** p)
    return p, d3 + c * h3 ** p


def uniform(x):
    """On the uniform-refinement family: an integer resolution with the default layers."""
    return x["resolution"] == round(x["resolution"]) and x["layers"] in (0, round(x["resolution"]))


def layers_of(x):
    return x["layers"] or max(1, round(x["resolution"]))


def converged(rows):
    """The converged deflection and its error estimate (mm), with the steps that made them.

    D(res, layers) = D - a t^p - b h^q, t ~ 1 / layers, h ~ 1 / res (the two directions' errors add).
    The thickness limit D - b h^q at one resolution: from three or more layer counts (observed p).
    The surface's share: the pair (res 1, L layers) and (res 2, L layers) differ in h alone, so
    D(2, L) - D(1, L) = b (1 - 2^-q) whatever the thickness error; q is not observed (two points) and is
    taken as 2 (the thickness' observed order for tet10), bracketed by 1.09 (the lugs' re-entrant
    edges, the slowest a compliance can go) and 3. The error estimate adds the spread over q and the
    thickness extrapolate's own correction."""
    notes, out = [], []
    for el in ("tet10", "tet4"):
        mine = [x for x in rows if x["element"] == el and x["resolution"] == round(x["resolution"])]
        for res in sorted({x["resolution"] for x in mine}):
            ser = sorted((x for x in mine if x["resolution"] == res), key=layers_of)
            if len(ser) < 3:
                continue
            s3 = ser[-3:]
            p, lim = solve_order([1.0 / layers_of(x) for x in s3], [x["deflection_mm"] for x in s3])
            if p is None:
                notes.append(f"{el} resolution {res:g}: layers {[layers_of(x) for x in s3]} fit no power law")
                continue
            corr = lim - s3[-1]["deflection_mm"]
            ls = ", ".join(str(layers_of(x)) for x in ser)
            ds = ", ".join(f"{x['deflection_mm']:.4f}" for x in ser)
            notes.append(f"{el} resolution {res:g}: layers {ls} give {ds} mm: observed order {p:.2f} in the "
                         f"thickness, limit {lim:.4f} mm ({corr:+.4f} from the finest)")
            pair = None
            for L in sorted({layers_of(x) for x in ser}, reverse=True):
                a = next((x for x in ser if layers_of(x) == L), None)
                b = next((x for x in mine if x["resolution"] == 2 * res and layers_of(x) == L), None)
                if a and b:
                    pair = (L, a, b)
                    break
            if pair is None:
                notes.append(f"{el}: no resolution {2 * res:g} at the same layers: the surface's error is not "
                             "measured, the value below is the thickness limit at this resolution only")
                out.append((el, lim, abs(corr), False))
                continue
            L, a, b = pair
            delta = b["deflection_mm"] - a["deflection_mm"]
            vals = {q: lim + delta / (1.0 - 2.0 ** -q) for q in (1.089, 2.0, 3.0)}
            err = max(abs(vals[1.089] - vals[2.0]), abs(vals[3.0] - vals[2.0])) + abs(corr)
            notes.append(f"{el}: resolution {res:g} -> {2 * res:g} at {L} layers: {delta:+.4f} mm, so the "
                         f"surface adds {vals[2.0] - lim:+.4f} mm (q = 2; {vals[1.089] - lim:+.4f} at q = 1.09, "
                         f"{vals[3.0] - lim:+.4f} at q = 3)")
            out.append((el, vals[2.0], err, True))
    if not out:
        return None, None, notes
    # tet10 first (it does not lock); tet4 converges from below, slowly, its extrapolate is a lower bound
    el, val, err, full = out[0]
    if not full:
        lower = max(o[1] for o in out)
        notes.append(f"not converged: at least {lower:.3f} mm (both elements converge from below)")
        return lower, err, notes + [f"at least {lower:.2f} mm (thickness limit, {el} at resolution 1)"]
    notes.append(f"converged deflection {val:.3f} +- {err:.3f} mm (from {el})")
    return val, err, notes + [f"converged {val:.2f} +- {err:.2f} mm"]


def main():
    rows = read_rows(sys.argv[1])
    steps = read_steps(sys.argv[3:])
    conv, err, notes = converged(rows)
    band = notes.pop() if conv is not None else ""
    print("\n".join(notes) + "\n")
    if conv is None:
        sys.exit("plot_deflection: no element has three layer counts at one resolution: nothing to extrapolate")

    # a uniform refinement by k divides the stable step by k (tet4 at 1 -> 2: 25.6 -> 12.6 us): the runs
    # without explicit steps (nostep) get theirs from the coarsest uniform row of the element that has one
    for r in rows:
        if not r["dt_limit_s"] > 0 and uniform(r):
            ref = [x for x in rows if x["element"] == r["element"] and uniform(x) and x["dt_limit_s"] > 0]
            if ref:
                x = min(ref, key=lambda x: x["resolution"])
                r["dt_limit_s"] = x["dt_limit_s"] * x["resolution"] / r["resolution"]
                r["dt_est"] = True

    def cost_of(r):
        key = (r["element"], r["resolution"])
        if key in steps and not r["layers"]:
            return steps[key][0], ""
        same = [(k, v) for k, v in steps.items() if k[0] == r["element"]]
        if not same or not r["dt_limit_s"] > 0:
            return float("nan"), ""
        (k, (c, n)) = min(same, key=lambda kv: abs(math.log(kv[0][1] / r["resolution"])))
        ref = next((x for x in rows if x["element"] == k[0] and x["resolution"] == k[1] and x["dt_limit_s"] > 0),
                   None)
        if ref is None:
            return float("nan"), ""
        return c * r["nodes"] / n * ref["dt_limit_s"] / r["dt_limit_s"], " est."

    print("| element | resolution | tets | nodes | deflection mm | error % | stable step us | "
          "CPU s per simulated s |")
    print("|---|---|---|---|---|---|---|---|")
    table = []
    for r in sorted(rows, key=lambda x: (x["element"] != "tet4", x["resolution"])):
        e = 100.0 * (r["deflection_mm"] / conv - 1.0)
        c, mark = cost_of(r)
        same = r["resolution"] == round(r["resolution"])
        table.append((r, e, c, same))
        dt = f"{1e6 * r['dt_limit_s']:.1f}{' est.' if r.get('dt_est') else ''}" if r["dt_limit_s"] > 0 else "-"
        cs = f"{c:.0f}{mark}" if c == c else "-"
        print(f"| {r['element']} | {r['label']}{'' if same else ' (other groove)'} | {r['tets']} | "
              f"{r['nodes']} | {r['deflection_mm']:.3f} | {e:+.1f} | {dt} | {cs} |")

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5.2))
    for el, mk in (("tet4", "o"), ("tet10", "s")):
        r = sorted((x for x in rows if x["element"] == el), key=lambda x: x["resolution"])
        ri = [x for x in r if uniform(x)]
        ro = [x for x in r if x["resolution"] != round(x["resolution"])]
        rl = [x for x in r if x["layers"] and not uniform(x)]
        if ri:
            ax.plot([x["tets"] for x in ri], [x["deflection_mm"] for x in ri], mk + "-",
                    label=f"{el}, resolution 1, 2, ... (the same tire)")
        if ro:
            ax.plot([x["tets"] for x in ro], [x["deflection_mm"] for x in ro], mk, mfc="none",
                    color=ax.lines[-1].get_color() if ri else None, label=f"{el}, other resolutions (groove rounded)")
        if rl:
            ax.plot([x["tets"] for x in rl], [x["deflection_mm"] for x in rl], "x",
                    color=ax.lines[-1].get_color() if ri or ro else None,
                    label=f"{el}, more cells through the wall (fem.mesh.layers)")
        for x in r:
            ax.annotate(x["label"], (x["tets"], x["deflection_mm"]), fontsize=7,
                        xytext=(4, 2), textcoords="offset points")
    ax.axhline(conv, color="grey", lw=0.8)
    ax.axhspan(conv - err, conv + err, color="grey", alpha=0.3, label=band)
    ax.axhspan(0.98 * conv, 1.02 * conv, color="grey", alpha=0.12, label="+-2 %")
    ax.set_xscale("log")
    ax.set_xlabel("tetrahedra (labels: resolution, layers through the wall)")
    ax.set_ylabel("deflection at 400 N [mm]")
    ax.set_title("tire on a rigid floor: 0.14 MPa, 400 N, no gravity")
    ax.legend(fontsize=6, loc="lower right")
    for el, mk in (("tet4", "o"), ("tet10", "s")):
        pts = [(c, abs(e), r) for r, e, c, same in table if r["element"] == el and same and c == c]
        if pts:
            bx.plot([p[0] for p in pts], [p[1] for p in pts], mk, label=el)
            for c, e, r in pts:
                bx.annotate(r["label"], (c, e), fontsize=7, xytext=(4, 2), textcoords="offset points")
    bx.axhline(2.0, color="grey", lw=0.8, ls="--")
    bx.axhline(10.0, color="grey", lw=0.8, ls=":")
    bx.set_xscale("log")
    bx.set_yscale("log")
    bx.set_xlabel("explicit run: CPU s per simulated s (one thread)")
    bx.set_ylabel("|deflection error| against the grey line, left [%]")
    bx.set_title("speed against accuracy (2 % and 10 % dashed)")
    bx.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(sys.argv[2], dpi=120)


if __name__ == "__main__":
    main()
