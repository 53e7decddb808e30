"""same_h5.py DIR_A DIR_B [FILE...]: every dataset of DIR_A's and DIR_B's
dem_grains.h5, wheel.h5 and fem.h5 (or the FILEs given, paths inside the
folders, e.g. checkpoint/dem.h5) has the same names, shapes and bytes (the
MPI tests: a run on several DEM ranks writes what one process writes). Exit 1
on the first difference."""
import sys

import h5py


def datasets(group, prefix=""):
    out = {}
    for k, v in group.items():
        if isinstance(v, h5py.Group):
            out.update(datasets(v, prefix + k + "/"))
        else:
            out[prefix + k] = v
    return out


for name in sys.argv[3:] or ("dem_grains.h5", "wheel.h5", "fem.h5"):
    a = h5py.File(f"{sys.argv[1]}/{name}", "r")
    b = h5py.File(f"{sys.argv[2]}/{name}", "r")
    da, db = datasets(a), datasets(b)
    assert sorted(da) == sorted(db), f"{name}: datasets {sorted(da)} vs {sorted(db)}"
    assert len(da) > 0, f"{name}: no datasets"
    for k in da:
        x, y = da[k][()], db[k][()]
        assert x.shape == y.shape and x.tobytes() == y.tobytes(), f"{name}/{k} differs"
    frames = [k for k in a if k.startswith("frame_")]
    print(f"{name}: {len(da)} datasets identical" + (f" ({len(frames)} frames)" if frames else ""))
