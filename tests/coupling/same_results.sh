#!/usr/bin/env bash
# Two coupled runs' result files the same: traction.csv, summary.json,
# fem_series.csv, dem_series.csv and the run records byte for byte, every
# dataset of dem_grains.h5, wheel.h5 and fem.h5 (same_h5.py). Timings are
# left out: the profiles, and the run records' keys in seconds of wall time
# (named *_s, e.g. dem_run.json's bed_s). Exit 0 when all are the same; else
# names the first that differs.
# Usage: same_results.sh DIR_A DIR_B
set -uo pipefail
a=$1 b=$2
for f in traction.csv summary.json fem_series.csv dem_series.csv; do
  cmp "$a/$f" "$b/$f" || { echo "$b: $f differs"; exit 1; }
done
timings='^ *"[A-Za-z0-9_]+_s": '
for f in dem_run.json fem_run.json; do
  [ -f "$a/$f" ] && [ -f "$b/$f" ] || { echo "$b: $f missing"; exit 1; }
  cmp <(grep -Ev "$timings" "$a/$f") <(grep -Ev "$timings" "$b/$f") \
    || { echo "$b: $f differs (timings left out)"; exit 1; }
done
"${DEMFEM_PYTHON:-/usr/bin/python3}" "$(dirname "$0")/same_h5.py" "$a" "$b" || { echo "$b: HDF5 results differ"; exit 1; }
