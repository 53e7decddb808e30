"""Steady part of a noisy series and its mean with a 95 % confidence interval.

An exact Python port of fem_server/steady.c (the traction summary that
fem_server prints at the end of a run), so that studies computed from
traction.csv agree with the server's own numbers:

* steady_start(x): MSER-5 (White 1997; Franklin & White 2008). Average the
  series in batches of 5 and drop the leading d batches (d <= half of them)
  that minimise the squared standard error of the remaining mean; among
  equal values the earliest start wins. Returns a sample index (a multiple
  of 5), 0 when the series has fewer than 20 samples.
* steady_summary(x, start): mean, min and max of x[start:], and the 95 %
  half-width of the mean from up to 20 non-overlapping batch means with
  Student's t (c >= 40 samples: 20 batches of c // 20, the remainder is not
  used for the interval; shorter: c // 2 batches; < 2 batches: 0).

The loops run in the same order as the C code, so the results are the same
doubles (checked by bench/post/check_steady.py).
"""
import math
from collections import namedtuple

_T95 = (0, 12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
        2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
        2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042)

SteadyStats = namedtuple("SteadyStats", "start count mean min max half_width batches")


def t95(dof):
    """Two-sided 95 % Student t quantile (steady_t95)."""
    if dof < 1:
        return math.inf
    if dof <= 30:
        return _T95[dof]
    return 1.960 + 2.4 / dof


def steady_start(x):
    """Index where the steady part of x begins (MSER-5), as steady_start()."""
    B = 5
    x = [float(v) for v in x]
    n = len(x)
    m = n // B
    if m < 4:
        return 0
    best = math.inf
    best_d = 0
    s1 = 0.0
    s2 = 0.0
    for j in range(m - 1, -1, -1):
        z = 0.0
        for k in range(B):
            z += x[j * B + k]
        z /= B
        s1 += z
        s2 += z * z
        d = j
        length = m - j
        if d > m // 2 or length < 2:
            continue
        mean = s1 / length
        ss = s2 - length * mean * mean
        if ss < 0:
            ss = 0.0
        mser = ss / (float(length) * float(length))
        if mser <= best:  # <=: prefer the earliest start among equals
            best = mser
            best_d = d
    return best_d * B


def steady_summary(x, start):
    """Mean, min, max and 95 % batch-means half-width of x[start:], as steady_summary()."""
    x = [float(v) for v in x]
    n = len(x)
    start = start if start < n else n
    c = n - start
    if c == 0:
        return SteadyStats(start, 0, 0.0, 0.0, 0.0, 0.0, 0)
    y = x[start:]
    s = 0.0
    mn = y[0]
    mx = y[0]
    for v in y:
        s += v
        mn = v if v < mn else mn
        mx = v if v > mx else mx
    mean = s / c
    b = 20 if c >= 40 else c // 2
    if b < 2:
        return SteadyStats(start, c, mean, mn, mx, 0.0, 0)
    length = c // b
    bs = 0.0
    bss = 0.0
    for k in range(b):
        z = 0.0
        for i in range(length):
            z += y[k * length + i]
        z /= length
        bs += z
        bss += z * z
    bm = bs / b
    var = (bss - b * bm * bm) / (b - 1)
    hw = t95(b - 1) * math.sqrt(var / b if var > 0 else 0.0)
    return SteadyStats(start, c, mean, mn, mx, hw, b)


def travel_statistics(rows, columns=("T_H", "T_R", "T_P", "sinkage")):
    """What fem_server prints at the end of a run, from traction.csv columns.

    rows: a dict of numpy arrays or lists keyed by column name, holding at
    least 'phase' and the columns asked for. The travel phase (phase == 1)
    is taken, the steady start is detected on its drawbar pull T_P and the
    same start is used for every column. Returns (start, n_travel, {col: SteadyStats})
    or (None, 0, {}) when the run never reached the travel phase."""
    phase = list(rows["phase"])
    idx = [i for i, p in enumerate(phase) if int(round(p)) == 1]
    if not idx:
        return None, 0, {}
    def pick(col):
        v = rows[col]
        return [float(v[i]) for i in idx]
    tp = pick("T_P")
    start = steady_start(tp)
    stats = {col: steady_summary(pick(col), start) for col in columns}
    return start, len(idx), stats
