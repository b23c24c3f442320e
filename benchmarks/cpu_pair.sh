#!/bin/bash
# CPU (user+sys) and peak RSS of `nlp-calib run SCENARIO --data LOG` in fresh processes, from two
# checkouts one after the other (interleaved: a before and an after per call), with the load average
# at the start and end of each run. Appends a line per run to OUT (tab-separated).
#   benchmarks/cpu_pair.sh OUT TAG SCENARIO LOG CHECKOUT_BEFORE CHECKOUT_AFTER
# Logs: nlp-calib simulate --records N --seed 11 --out LOG (the demo's), or
#       nlp-calib simulate --config scenarios/data/camera_demo.sim.yaml --duration N/50 --out LOG.tum
set -u
out=$1; tag=$2; scen=$3; data=$4; shift 4
work=$(mktemp -d)
for checkout in "$@"; do
  l0=$(cut -d' ' -f1-3 /proc/loadavg)
  (cd "$checkout" && /usr/bin/time -v -o "$work/time" nice -n 10 python3 -m nlp_calib run "$scen" \
      --data "$data" --out "$work/out" --force > "$work/log" 2>&1)
  rc=$?
  l1=$(cut -d' ' -f1-3 /proc/loadavg)
  u=$(awk '/User time/ {print $NF}' "$work/time"); s=$(awk '/System time/ {print $NF}' "$work/time")
  m=$(awk '/Maximum resident/ {print $NF}' "$work/time"); w=$(awk '/Elapsed/ {print $NF}' "$work/time")
  printf '%s\t%s\trc=%s\tcpu=%s\tuser=%s\tsys=%s\tpeak_MB=%s\twall=%s\tload=%s -> %s\n' "$tag" \
    "$(git -C "$checkout" rev-parse --short HEAD)" "$rc" "$(echo "$u + $s" | bc)" "$u" "$s" \
    "$((m / 1024))" "$w" "$l0" "$l1" >> "$out"
done
rm -rf "$work"
