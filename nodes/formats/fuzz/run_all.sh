#!/bin/sh
# Runs every fuzz target for SECONDS (default 600) one after another at the lowest CPU priority,
# logging to logs/<target>.log; prints each target's executions and whether it crashed.
#   cd nodes/formats/fuzz && ./run_all.sh [SECONDS] [TARGET...]
set -u
cd "$(dirname "$0")"
seconds=${1:-600}
[ $# -gt 0 ] && shift
targets=${*:-"evt3 evt2 es text aedat4 camera_file decode_any"}
mkdir -p logs
for t in $targets; do
    start=$(date +%s)
    nice -n 19 cargo +nightly fuzz run -O "$t" -- -max_total_time="$seconds" -timeout=10 \
        -print_final_stats=1 > "logs/$t.log" 2>&1
    rc=$?
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "logs/$t.log" | grep -o '[0-9]*$')
    echo "$t: exit $rc, $(( $(date +%s) - start )) s, ${execs:-?} executions"
done
