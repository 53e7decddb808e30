#!/usr/bin/python3
"""Checks bench/post/steady.py against fem_server/steady.c, without a C compiler.

The series are the ones of tests/coupling/test_drive.c (a transient
100 + 60 exp(-i/100) decaying into AR(1) noise, from the same xorshift +
Box-Muller generator) and a few short ones that exercise the edge cases
(fewer than 20 samples: no truncation; fewer than 40: c/2 batches). The
expected numbers were printed by the C functions steady_start() and
steady_summary() compiled from fem_server/steady.c (gcc -O2, x86-64) on the
same series; the Python port must give the same start index and batch
count exactly and the same doubles to 1e-12 relative.

usage: bench/post/check_steady.py        (exit status 0 when all agree)
"""
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from steady import steady_start, steady_summary, t95  # noqa: E402

M64 = (1 << 64) - 1


def make_gauss(state):
    st = [state]

    def gauss():
        u = [0.0, 0.0]
        for k in range(2):
            s = st[0]
            s ^= (s << 13) & M64
            s ^= s >> 7
            s ^= (s << 17) & M64
            st[0] = s
            u[k] = (float(s >> 11) + 0.5) / 9007199254740992.0
        return math.sqrt(-2 * math.log(u[0])) * math.cos(2 * math.pi * u[1])
    return gauss


# (label, start, count, mean, min, max, half_width, batches) from steady.c
EXPECTED = [
    ("series 0", 380, 3620, 100.09492499813393, 94.027347713335871, 105.51716529060919, 0.21854704151558588, 20),
    ("series 1", 355, 3645, 100.01659792619178, 93.577353617515513, 105.40722695038703, 0.24601283990620826, 20),
    ("series 2", 320, 3680, 100.11677826981814, 94.173112638264783, 105.2679923917388, 0.2130159150577948, 20),
    ("short n=0", 0, 0, 0.0, 0.0, 0.0, 0.0, 0),
    ("short n=7", 0, 7, 1.7347264533527909, -1.1540140725496428, 6.8330100583741311, 7.7334013081415343, 3),
    ("short n=19", 0, 19, -0.3311457724553864, -4.552375840212358, 7.2006847662212747, 2.4948086927890532, 9),
    ("short n=20", 10, 10, -3.5972594571468171, -4.4576185937066377, -1.7318912491580694, 0.6591361720236123, 5),
    ("short n=23", 5, 18, -2.2015348619388599, -4.5226374954073947, -0.97483534580868003, 0.51435011650410112, 9),
    ("short n=45", 20, 25, -3.3994355901700861, -5.4324207928368438, -1.5912139814997146, 0.59464116158258151, 12),
    ("short n=137", 10, 127, -2.9056313767969697, -8.2410935285146056, 0.55395232872822664, 0.43738929255730363, 20),
]


def series():
    gauss = make_gauss(88172645463325252)
    for r in range(3):
        e = 0.0
        x = []
        for i in range(4000):
            e = 0.8 * e + gauss()
            x.append(100.0 + 60.0 * math.exp(-i / 100.0) + e)
        yield "series %d" % r, x
    for n in (0, 7, 19, 20, 23, 45, 137):
        e = 0.0
        x = []
        for i in range(n):
            e = 0.5 * e + gauss()
            x.append(-3.0 + 10.0 * math.exp(-i / 4.0) + e)
        yield "short n=%d" % n, x


def close(a, b):
    return abs(a - b) <= 1e-12 * max(1.0, abs(a), abs(b))


def main():
    bad = 0
    for (label, x), exp in zip(series(), EXPECTED):
        assert label == exp[0]
        s0 = steady_start(x)
        st = steady_summary(x, s0)
        got = (s0, st.count, st.mean, st.min, st.max, st.half_width, st.batches)
        ok = got[0] == exp[1] and got[1] == exp[2] and got[6] == exp[7] and all(
            close(g, e) for g, e in zip(got[2:6], exp[3:7]))
        bad += not ok
        print("%-4s %-12s start %5d (C %5d)  mean %.12g (C %.12g)  +-%.6g (C %.6g)  batches %d (C %d)"
              % ("ok" if ok else "FAIL", label, s0, exp[1], st.mean, exp[3], st.half_width, exp[6],
                 st.batches, exp[7]))
    for dof, want in ((19, 2.093), (45, 2.0133333333333332), (0, math.inf)):
        if t95(dof) != want:
            print("FAIL t95(%d) = %r, C gives %r" % (dof, t95(dof), want))
            bad += 1
    print("steady.py agrees with steady.c" if bad == 0 else "%d disagreements" % bad)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
