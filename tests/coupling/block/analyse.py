#!/usr/bin/python3
"""Peak force, contact time and rebound energy of the sphere-on-block runs
(measure.sh) against Hertz for steel on a rubber half-space.

    analyse.py RUNDIR ...
"""
import math
import os
import sys

import numpy as np

R, RHO, V = 0.010, 7800.0, 0.5
E1, NU1, E2, NU2 = 2.1e11, 0.3, 1.0e7, 0.45


def hertz():
    es = 1.0 / ((1 - NU1**2) / E1 + (1 - NU2**2) / E2)
    m = RHO * 4.0 / 3.0 * math.pi * R**3
    dmax = (15.0 * m * V * V / (16.0 * es * math.sqrt(R))) ** 0.4
    return 4.0 / 3.0 * es * math.sqrt(R) * dmax**1.5, 2.943 * dmax / V, 0.5 * m * V * V


def main():
    fh, th, e_in = hertz()
    print(f"Hertz: peak {fh:.2f} N, contact time {1e3 * th:.3f} ms, input energy {e_in:.4g} J")
    for d in sys.argv[1:]:
        try:
            t = np.atleast_1d(np.genfromtxt(os.path.join(d, "traction.csv"), delimiter=",", names=True))
            s = np.atleast_1d(np.genfromtxt(os.path.join(d, "dem_series.csv"), delimiter=",", names=True))
        except OSError as e:
            print(f"{d}: no results ({e})")
            continue
        f = -t["Fz"]
        on = f > 1e-3 * f.max()
        dt = t["t"][1] - t["t"][0]
        ended = t["t"][-1] > 1.2 * th and not on[-1]
        print(f"{d}: peak {f.max():.2f} N ({f.max() / fh - 1:+.1%}), contact time {1e3 * on.sum() * dt:.3f} ms "
              f"({on.sum() * dt / th - 1:+.1%}), up to {int(t['contacts'].max())} contacts, "
              f"rebound energy {s['ke_trans_J'][-1] / e_in:.3f} of the input{'' if ended else ' (run did not finish)'}")


if __name__ == "__main__":
    main()
