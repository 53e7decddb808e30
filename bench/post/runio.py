"""Readers for the outputs of one scene run (./run SCENE --out DIR).

Layouts, from the C sources:

* traction.csv (fem_server/fem_main.c, also wheel.h5:/series): one row per
  exchange, columns t, phase (0 sinkage, 1 travel, 2 done, 3 fixed), x, z
  (wheel centre, m), angle (rad, about +y), omega (rad/s), v (m/s), slip,
  Fx Fy Fz (N, grains on tire), My (N m, axle torque), T_H T_R T_P (N),
  contacts, sinkage (m), E_elastic E_kinetic (J, tire), W_dem W_fem (J).
* fem.h5 (fem_server/fem_output.c via common/h5io.c): /mesh/connectivity
  (n_tets x 4 int), /mesh/points0 (n_nodes x 3, undeformed, rim frame),
  /steps/NNNNNN (attributes time, step) with position (X + u, rim frame),
  displacement, strain and stress (n_tets x 6, XDMF Tensor6 order xx xy xz
  yy yz zz, tensor shear components, rim frame), eps22 and eps33 (the rim-
  frame yy and zz components). The rim frame is centred on the axle and
  turns with the wheel: world = centre + R_y(angle) (X + u).
* dem_grains.h5 (dem_server/dem_output.c): /frame_NNNNNN (attribute time)
  with position, velocity, angular_velocity (n x 3), radius, contacts (n).

HDF5 files are opened without file locking so that a run still writing them
can be read (the writers flush after every snapshot).
"""
import os

os.environ.setdefault("HDF5_USE_FILE_LOCKING", "FALSE")

import numpy as np  # noqa: E402

PHASE_NAMES = {0: "sinkage", 1: "travel", 2: "done", 3: "fixed"}


def read_traction(path):
    """traction.csv as a dict of numpy arrays keyed by column name.
    A last line cut short by a run still writing is dropped."""
    with open(path) as f:
        header = f.readline().strip().split(",")
        lines = f.read().splitlines()
    ncol = len(header)
    if lines and len(lines[-1].split(",")) != ncol:
        lines = lines[:-1]
    if not lines:
        return {h: np.zeros(0) for h in header}
    data = np.loadtxt(lines, delimiter=",", ndmin=2)
    return {h: data[:, k] for k, h in enumerate(header)}


def travel_rows(traction):
    """The row indices of traction.csv's travel phase, in order (the phase
    column holds fem_server's drive phases: 0 sinking, 1 travelling, 2
    done)."""
    return np.flatnonzero(np.rint(traction["phase"]) == 1)


def set_down(summary, traction=None):
    """(time s, sinkage m) of the wheel when its travel began: the sinkage
    under the load before it rolls (the static sinkage of a load-controlled
    set-down, wheel.motion = "load_travel"; the depth at which the load was
    reached under position control), as fem_server's summary.json reports
    it (`set_down`). A summary.json from before fem_server reported it has
    no such key: then the first travel row of the run's traction.csv, the
    row fem_server takes (`traction`, from read_traction). None when the
    run never travelled (or neither says)."""
    sd = summary.get("set_down") if summary else None
    if sd is not None:
        if sd.get("time_s") is None or sd.get("sinkage_m") is None:
            return None
        return float(sd["time_s"]), float(sd["sinkage_m"])
    if traction is None:
        return None
    idx = travel_rows(traction)
    if idx.size == 0:
        return None
    i = int(idx[0])
    return float(traction["t"][i]), float(traction["sinkage"][i])


def _h5():
    import h5py
    return h5py


def fem_snapshots(path):
    """[(time, group name)] of the tire snapshots in fem.h5, by time."""
    h5py = _h5()
    out = []
    with h5py.File(path, "r") as f:
        if "steps" not in f:
            return out
        for name, g in f["steps"].items():
            if "time" in g.attrs and "position" in g and "strain" in g:
                out.append((float(g.attrs["time"]), name))
    out.sort()
    return out


def fem_world_frame(path):
    """Whether fem.h5 holds world-frame snapshots (fem_server since the
    contact_force field; the root attribute "units" says so)."""
    h5py = _h5()
    with h5py.File(path, "r") as f:
        units = f.attrs.get("units", b"")
        if isinstance(units, bytes):
            units = units.decode("utf-8", "replace")
        return "world frame" in str(units)


def read_fem_mesh(path):
    h5py = _h5()
    with h5py.File(path, "r") as f:
        return np.asarray(f["/mesh/connectivity"]), np.asarray(f["/mesh/points0"])


def read_fem_snapshot(path, name):
    """Snapshot `name` (a key of /steps): dict of position, displacement, strain, ..."""
    h5py = _h5()
    with h5py.File(path, "r") as f:
        g = f["steps"][name]
        d = {k: np.asarray(g[k]) for k in g.keys()}
        d["time"] = float(g.attrs["time"])
    return d


def grain_frames(path):
    """[(time, group name)] of the grain frames of the run in dem_grains.h5.

    Frames are taken in the order written (frame number). When dem_server
    settles a new bed in the same run it writes frames of the settling first
    and then sets the clock back to zero: only the frames after the last
    time the clock went back are kept. (Settling frames that are followed by
    run frames with later times cannot be told apart from the file alone.)"""
    h5py = _h5()
    out = []
    with h5py.File(path, "r") as f:
        for name, g in f.items():
            if name.startswith("frame_") and "time" in g.attrs and "position" in g and "velocity" in g:
                try:
                    num = int(name[len("frame_"):])
                except ValueError:
                    continue
                out.append((num, float(g.attrs["time"]), name))
    out.sort()
    first = 0
    for k in range(1, len(out)):
        if out[k][1] < out[k - 1][1]:
            first = k
    return [(t, name) for _num, t, name in out[first:]]


def read_grain_frame(path, name):
    h5py = _h5()
    with h5py.File(path, "r") as f:
        g = f[name]
        d = {k: np.asarray(g[k]) for k in g.keys()}
        d["time"] = float(g.attrs["time"])
    return d


def rotation_y(angle):
    """The rim-to-world rotation of fem_server (rotation_about_y)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def tensor6_to_matrix(t6):
    """(n, 6) XDMF Tensor6 (xx xy xz yy yz zz) -> (n, 3, 3) symmetric."""
    xx, xy, xz, yy, yz, zz = (t6[:, k] for k in range(6))
    return np.stack([np.stack([xx, xy, xz], -1), np.stack([xy, yy, yz], -1), np.stack([xz, yz, zz], -1)], -2)


def boundary_faces(tets):
    """Faces of a tetrahedral mesh that belong to one tetrahedron only:
    (faces (m, 3) node indices, owning tetrahedron (m,))."""
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    faces = tets[:, local].reshape(-1, 3)
    owner = np.repeat(np.arange(len(tets)), 4)
    key = np.sort(faces, axis=1)
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    once = counts[inv.ravel()] == 1
    return faces[once], owner[once]


def fem_server_path():
    """fem_server of the build the scripts use: DEMFEM_BUILD_DIR (as ./run
    sets it), else build/ beside bench/."""
    build = os.environ.get("DEMFEM_BUILD_DIR") or os.path.join(
        os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "build")
    return os.path.join(build, "fem_server", "fem_server")


class SceneError(Exception):
    pass


def resolved_scene(scene_path, sets=()):
    """The scene as the servers resolve it (the file with every KEY=VALUE of
    sets applied, in order), as nested dicts and lists: fem_server
    --print-config=json (common/scene.c) prints it, so that no script parses
    libconfig. Raises SceneError with the server's message."""
    import json
    import subprocess
    cmd = [fem_server_path(), "--scene", scene_path]
    for kv in sets:
        cmd += ["--set", kv if isinstance(kv, str) else "%s=%s" % tuple(kv)]
    cmd.append("--print-config=json")
    try:
        p = subprocess.run(cmd, capture_output=True, text=True)
    except OSError as e:
        raise SceneError("%s: %s (build fem_server first: ./run build)" % (cmd[0], e))
    if p.returncode != 0:
        raise SceneError(p.stderr.strip() or "%s exited %d" % (cmd[0], p.returncode))
    return json.loads(p.stdout)


def scene_get(scene, key):
    """scene["a"]["b"]["c"] for key "a.b.c" (a list index may be a part:
    "dem.bed.layers.0.count"); KeyError when missing."""
    v = scene
    for part in key.split("."):
        if isinstance(v, list):
            try:
                v = v[int(part)]
            except (ValueError, IndexError):
                raise KeyError(key)
        elif isinstance(v, dict) and part in v:
            v = v[part]
        else:
            raise KeyError(key)
    return v


def split_settings(text):
    """The KEY=VALUE items of a study's settings column ("k=v; k=v", as
    bench/study/run writes it): split at "; " only where a key follows, since
    a value (a list of groups, e.g. dem.bed.layers) has "; " of its own."""
    import re
    return [s.strip() for s in re.split(r";\s*(?=[A-Za-z][-A-Za-z0-9_.\[\]]*=)", text or "") if s.strip()]


def libconfig_value(v):
    """A Python value (as resolved_scene gives) as libconfig value text, for
    --set: floats always with a point, groups as { k = v; }, lists of groups
    as ( ... ), lists of scalars as [ ... ]."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        t = repr(v)
        return t if any(c in t for c in ".eEn") else t + ".0"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, dict):
        return "{ " + " ".join("%s = %s;" % (k, libconfig_value(x)) for k, x in v.items()) + " }"
    if isinstance(v, list):
        inner = ", ".join(libconfig_value(x) for x in v)
        return ("( %s )" if any(isinstance(x, (dict, list)) for x in v) else "[%s]") % inner
    raise TypeError(v)


def run_scene(outdir):
    """The resolved scene of a run folder written by ./run (the scene file in
    OUT/scene.path and its --set list in OUT/scene.sets), or None."""
    try:
        path = open(os.path.join(outdir, "scene.path")).read().strip()
        sets_path = os.path.join(outdir, "scene.sets")
        sets = [ln for ln in open(sets_path).read().splitlines() if ln] if os.path.exists(sets_path) else []
        return resolved_scene(path, sets)
    except (OSError, SceneError):
        return None


def read_scene_wheel_y(outdir):
    """wheel.center[1] of the scene a run folder was run with, or None."""
    scene = run_scene(outdir)
    try:
        return float(scene_get(scene, "wheel.center")[1]) if scene else None
    except (KeyError, IndexError, TypeError):
        return None


class Stat:
    """One quantity of a run's summary (fem_server/fem_summary.c): mean,
    half_width (95 %), sd (time scatter), min, max, tau_s (correlation
    time), samples, batches, short_series."""

    def __init__(self, d):
        self.__dict__.update(d)
        self.count = d.get("samples", 0)


def read_summary(run_dir):
    """The run's summary.json (written by fem_server at the end of a run) as
    a dict, with "stats" mapping quantity names to Stat objects (and "Fz" as
    an alias of "load", the traction.csv column name); None when the run
    wrote none (failed, or still running)."""
    import json
    path = os.path.join(run_dir, "summary.json")
    if not os.path.exists(path):
        return None
    with open(path) as f:
        s = json.load(f)
    s["stats"] = {k: Stat(v) for k, v in s.get("quantities", {}).items()}
    if "load" in s["stats"]:
        s["stats"]["Fz"] = s["stats"]["load"]
    return s
