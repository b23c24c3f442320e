#!/bin/bash
# CPU (user+sys) and peak RSS of warm `nlp-calib compare SCENARIO --data LOG` in fresh processes
# against the floor every run pays (`python3 -c "import numpy, casadi"`) and against importing what
# the compare holds at its end, as the command imports it (benchmarks/import_modules.py), from one or
# more checkouts interleaved, REPS rounds. Warm: each checkout's bytecode cache (PYTHONPYCACHEPREFIX)
# and the compile cache filled by one compare first. Appends "what checkout user sys maxrss_kB"
# lines and the load average at each round's start to OUT, then prints the medians in floors.
# WHAT (environment; default "floor compare imports") times only the ones it names, e.g. WHAT="floor
# imports" for more rounds of the imports at the cost of one compare per checkout.
#   benchmarks/compare_cpu.sh OUT REPS SCENARIO LOG CHECKOUT...
set -u
out=$1; reps=$2; scen=$3; data=$(realpath "$4"); shift 4
work=$(mktemp -d)
here=$(dirname "$(realpath "$0")")
unset PYTHONDONTWRITEBYTECODE
for checkout in "$@"; do
  n=$(basename "$checkout")
  cd "$checkout" || exit 1
  export PYTHONPATH="$checkout" PYTHONPYCACHEPREFIX="$work/pyc_$n"
  python3 -m nlp_calib compare "$scen" --data "$data" --out "$work/out_$n" --force > /dev/null 2>&1
  python3 "$here/import_modules.py" held "$work/imports_$n.py" compare "$scen" --data "$data" \
    --out "$work/out_$n" --force 2>&1 > /dev/null | grep '^modules' | sed "s/^modules [^ ]*/modules $n/" >> "$out"
  python3 "$work/imports_$n.py"  # the methods file such a command keeps, written
done
for _ in $(seq "$reps"); do
  echo "load $(cut -d' ' -f1-3 /proc/loadavg)" >> "$out"
  for checkout in "$@"; do
    n=$(basename "$checkout")
    cd "$checkout" || exit 1
    export PYTHONPATH="$checkout" PYTHONPYCACHEPREFIX="$work/pyc_$n"
    for what in ${WHAT:-floor compare imports}; do
      case $what in
        floor) cmd=(python3 -c "import numpy, casadi") ;;
        compare) cmd=(python3 -m nlp_calib compare "$scen" --data "$data" --out "$work/out_$n" --force) ;;
        imports) cmd=(python3 "$work/imports_$n.py") ;;
      esac
      /usr/bin/time -o "$work/time" -f "%U %S %M" "${cmd[@]}" > /dev/null 2>&1
      echo "$what $n $(cat "$work/time")" >> "$out"
    done
  done
done
echo "load $(cut -d' ' -f1-3 /proc/loadavg)" >> "$out"
rm -rf "$work"
python3 - "$out" <<'PY'
import statistics, sys
cpu, rss = {}, {}
for line in open(sys.argv[1]):
    f = line.split()
    if len(f) == 5 and f[0] in ("floor", "compare", "imports"):
        cpu.setdefault((f[0], f[1]), []).append(float(f[2]) + float(f[3]))
        rss.setdefault((f[0], f[1]), []).append(int(f[4]) / 1024)
for checkout in dict.fromkeys(c for _, c in cpu):
    floor = statistics.median(cpu[("floor", checkout)])
    for what in ("floor", "compare", "imports"):
        if (what, checkout) not in cpu:
            continue
        v = cpu[(what, checkout)]
        m = statistics.median(v)
        peak = statistics.median(rss[(what, checkout)])
        print(f"{checkout:12s} {what:8s} n={len(v)} median {m:.2f} s = {m / floor:.2f} floors "
              f"(range {min(v):.2f}-{max(v):.2f} s), peak {peak:.0f} MB")
PY
