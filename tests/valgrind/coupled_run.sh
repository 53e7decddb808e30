#!/usr/bin/env bash
# A short coupled run of both servers under valgrind memcheck (leak check
# full): the tire_ckpt scene cut to 35 exchanges with a checkpoint every 10,
# run to the end, then resumed from its last checkpoint (exchange 29: the
# restore paths and 5 more exchanges), which must end in the same state.
# Fails on any memcheck error or definite/possible leak in either server.
# usage: coupled_run.sh SOURCE_DIR BUILD_DIR
set -uo pipefail
src=$1 build=$2
command -v valgrind >/dev/null || { echo "valgrind not installed: skipped"; exit 77; }
work=$(mktemp -d /tmp/demfem-valgrind-XXXXXX)
trap 'rm -rf "$work"' EXIT
sed -e 's/end_time = 0.02; progress_every = 0.0; checkpoint_every = 0.002;/end_time = 0.0007; progress_every = 0.0; checkpoint_every = 0.0002;/' \
    -e 's/coupling = { dt = 1.0e-5; exchange_every = 2; };/coupling = { dt = 1.0e-5; exchange_every = 2; stall_timeout = 30.0; };/' \
    "$src/tests/coupling/scenes/tire_ckpt.cfg" > "$work/scene.cfg"
grep -q "end_time = 0.0007" "$work/scene.cfg" || { echo "scene not cut down (tire_ckpt.cfg changed?)"; exit 1; }
# The bed is settled without valgrind (cached beside the scene).
"$build/dem_server/dem_server" --scene "$work/scene.cfg" --standalone --out "$work/bed" > "$work/bed.log" 2>&1 \
  || { cat "$work/bed.log"; exit 1; }
for side in dem fem; do
  cat > "$work/vg_$side" <<EOS
#!/bin/sh
exec valgrind -q --leak-check=full --errors-for-leak-kinds=definite,possible --error-exitcode=99 \
  --suppressions=$src/tests/valgrind/libgomp.supp --num-callers=30 --log-file=$work/$side.%p.vg \
  $build/${side}_server/${side}_server "\$@"
EOS
  chmod +x "$work/vg_$side"
done
export DEMFEM_NO_BUILD=1 DEMFEM_BUILD_DIR=$build
rc=0
"$src/run" "$work/scene.cfg" --out "$work/out" --dem "$work/vg_dem" --fem "$work/vg_fem" > "$work/run.log" 2>&1 || rc=$?
[ $rc -eq 0 ] && { "$src/run" --resume "$work/out" --dem "$work/vg_dem" --fem "$work/vg_fem" > "$work/resume.log" 2>&1 || rc=$?; }
for f in "$work"/*.vg; do
  if [ -s "$f" ]; then echo "---- $(basename "$f")"; cat "$f"; [ $rc -eq 0 ] && rc=1; fi
done
fresh=$(grep -o "_hash [0-9a-f]*" "$work/run.log" | sort | tr '\n' ' ')
resumed=$(grep -o "_hash [0-9a-f]*" "$work/resume.log" 2>/dev/null | sort | tr '\n' ' ')
if [ $rc -eq 0 ] && { [ -z "$fresh" ] || [ "$fresh" != "$resumed" ]; }; then
  echo "final states differ: fresh '$fresh', resumed '$resumed'"; rc=1
fi
if [ $rc -ne 0 ]; then cat "$work/run.log" "$work/resume.log" 2>/dev/null; echo "valgrind run failed ($rc)"; exit 1; fi
grep -h "final state\|resumed after" "$work/run.log" "$work/resume.log"
echo "valgrind memcheck: no errors, no leaks in 2 coupled runs (fresh and resumed) of both servers"
