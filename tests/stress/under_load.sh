#!/usr/bin/env bash
# The process tests under artificial CPU load: one busy loop per core while
# the peer-loss, start-order and corruption cases of test_ipc run REPEAT
# times, then the coupled launcher case whose FEM side is killed. A slow,
# crowded schedule exposes tests that synchronise by sleeping or by polling
# for a short-lived state (issue 12); ctest runs this case alone (RUN_SERIAL).
#   under_load.sh BUILD_DIR [REPEAT]
set -u
build=$1 repeat=${2:-3}
busy=()
stop_busy() { local p; for p in "${busy[@]}"; do kill "$p" 2>/dev/null; done; for p in "${busy[@]}"; do wait "$p" 2>/dev/null; done; }
trap stop_busy EXIT
for _ in $(seq "$(nproc)"); do
  ( while :; do :; done ) &
  busy+=($!)
done
echo "busy loops (pids ${busy[*]}) on $(nproc) cores"
cases=(dem_starts_first fem_killed dem_killed fem_stopped dem_stopped fem_sigterm dem_sigint
       stale_segment_refused corrupted_header_refused out_of_order_frame_refused)
fail=0
for r in $(seq "$repeat"); do
  if ! "$build/tests/ipc/test_ipc" "${cases[@]}"; then
    echo "under load: test_ipc failed in repetition $r of $repeat"
    fail=1
    break
  fi
done
if [ $fail -eq 0 ] && ! "$build/tests/coupling/test_coupled" plate_peer_killed; then
  echo "under load: test_coupled plate_peer_killed failed"
  fail=1
fi
[ $fail -eq 0 ] && echo "under load: ${#cases[@]} test_ipc cases x $repeat and plate_peer_killed passed"
exit $fail
