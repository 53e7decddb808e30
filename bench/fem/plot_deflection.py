#!/usr/bin/python3
"""The tire's deflection on the rigid floor (bench_deflection's CSV) against
the number of tetrahedra, tet4 and tet10, each point labelled with the cost
of an explicit step and the stable step; the finest tet10 value is the
reference line, +-2 % shaded.

    plot_deflection.py IN.csv OUT.png
"""
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def main():
    d = np.atleast_1d(np.genfromtxt(sys.argv[1], delimiter=",", names=True, dtype=None, encoding="utf-8"))
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    ref = None
    for el, mk in (("tet10", "s"), ("tet4", "o")):
        r = np.sort(d[d["element"] == el], order="tets")
        if len(r) == 0:
            continue
        ax.plot(r["tets"], r["deflection_mm"], mk + "-", label=el)
        for row in r:
            ax.annotate(f"res {row['resolution']:g}\n{row['step_ms']:.2g} ms/step\ndt {1e6 * row['dt_limit_s']:.0f} us",
                        (row["tets"], row["deflection_mm"]), fontsize=7, xytext=(4, -22), textcoords="offset points")
        if el == "tet10":
            ref = r["deflection_mm"][-1]
    if ref is not None:
        ax.axhline(ref, color="grey", lw=0.8)
        ax.axhspan(0.98 * ref, 1.02 * ref, color="grey", alpha=0.15, label="finest tet10 +-2 %")
    ax.set_xscale("log")
    ax.set_xlabel("tetrahedra")
    ax.set_ylabel("deflection at 400 N [mm]")
    ax.set_title("tire on a rigid floor: 0.14 MPa, 400 N, no gravity (fem.floor)")
    ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(sys.argv[2], dpi=120)


if __name__ == "__main__":
    main()
