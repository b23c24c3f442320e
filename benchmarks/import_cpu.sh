#!/bin/bash
# CPU (user+sys) of fresh processes: what starting a command costs against the floor every run pays
# (`python3 -c "import numpy, casadi"`), from one or more checkouts interleaved, REPS rounds, each
# without a bytecode cache (every module compiled from source, as with PYTHONDONTWRITEBYTECODE=1 and
# no __pycache__) and with one (PYTHONPYCACHEPREFIX, filled before the first round). Per checkout:
#   help    nlp-calib --help
#   runimp  importing, in a fresh process, every nlp_calib module a `run` of SCENARIO ends up holding,
#           as the command imports them (import_modules.py)
#   run     nlp-calib run SCENARIO --data LOG           check  nlp-calib check CALIBRATION LOG
# Appends to OUT how many modules each command holds (all, the package's), the CPU importing what a
# run holds took and the share of it spent making dataclasses, then "mode what checkout user sys"
# lines and the load average at each round's start.
#   benchmarks/import_cpu.sh OUT REPS SCENARIO LOG CALIBRATION CHECKOUT...
set -u
out=$1; reps=$2; scen=$3; data=$(realpath "$4"); calib=$(realpath "$5"); shift 5
work=$(mktemp -d)
timed() {  # label, then the command
  local label=$1; shift
  /usr/bin/time -o "$work/time" -f "%U %S" "$@" > /dev/null 2>&1
  echo "$label $(cat "$work/time")" >> "$out"
}
here=$(dirname "$(realpath "$0")")
for checkout in "$@"; do  # the modules each command holds at its end, and a filled bytecode cache
  n=$(basename "$checkout")
  cd "$checkout" || exit 1
  export PYTHONPATH="$checkout" PYTHONPYCACHEPREFIX="$work/pyc_$n" PYTHONDONTWRITEBYTECODE=
  for c in help run check; do
    case $c in
      help) args=(--help) ;;
      run) args=(run "$scen" --data "$data" --out "$work/out_$n" --force) ;;
      check) args=(check "$calib" "$data" --out "$work/check_$n" --force) ;;
    esac
    python3 "$here/import_modules.py" held "$work/imports_${c}_$n.py" "${args[@]}" 2>&1 >/dev/null \
      | grep '^modules' | sed "s/^modules [^ ]*/modules $c $n/" >> "$out"
  done
  python3 "$here/import_modules.py" dataclasses "$work/imports_run_$n.py" | sed "s/^/$n /" >> "$out"
done
for _ in $(seq "$reps"); do
  echo "load $(cut -d' ' -f1-3 /proc/loadavg)" >> "$out"
  for mode in uncached cached; do
    for checkout in "$@"; do
      n=$(basename "$checkout")
      if [ $mode = cached ]; then
        export PYTHONPYCACHEPREFIX="$work/pyc_$n" PYTHONDONTWRITEBYTECODE=
      else
        unset PYTHONPYCACHEPREFIX; export PYTHONDONTWRITEBYTECODE=1
      fi
      cd "$checkout" || exit 1
      export PYTHONPATH="$checkout"
      timed "$mode floor $n" python3 -c "import numpy, casadi"
      timed "$mode help $n" python3 -m nlp_calib --help
      timed "$mode runimp $n" python3 "$work/imports_run_$n.py"
      timed "$mode run $n" python3 -m nlp_calib run "$scen" --data "$data" --out "$work/out_$n" --force
      timed "$mode check $n" python3 -m nlp_calib check "$calib" "$data" --out "$work/check_$n" --force
    done
  done
done
echo "load $(cut -d' ' -f1-3 /proc/loadavg)" >> "$out"
rm -rf "$work"
# The median of each over OUT's rounds, in CPU seconds and in floors (the median of every checkout's
# floor in that mode: the same two imports, timed beside each).
python3 - "$out" <<'PY'
import statistics, sys
cpu = {}
for line in open(sys.argv[1]):
    f = line.split()
    if len(f) == 5 and f[0] in ("uncached", "cached"):
        cpu.setdefault(tuple(f[:3]), []).append(float(f[3]) + float(f[4]))
for (mode, what, checkout), v in cpu.items():
    floor = statistics.median([c for (mo, w, _), v2 in cpu.items() if (mo, w) == (mode, "floor") for c in v2])
    m = statistics.median(v)
    print(f"{mode:8s} {what:6s} {checkout:12s} n={len(v)} median {m:.2f} s = {m / floor:.2f} floors")
PY
