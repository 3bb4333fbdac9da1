#!/usr/bin/env bash
# Run every blurtrap benchmark and study in one command.
#
#   benchmarks/run_all.sh            # quick mode (~1 h on an idle 2-core CPU, 2-4x when shared)
#   benchmarks/run_all.sh --full     # the sizes recorded in benchmarks/RESULTS*.md (hours)
#   benchmarks/run_all.sh --out DIR  # where logs and results go (default benchmarks/out/<mode>)
#   benchmarks/run_all.sh --dry-run  # print the commands only
#
# Environment: PYTHON (default: python) must have blurtrap installed with its test extras and
# matplotlib; BLURTRAP_PEER_PYTHON names the interpreter of a separate venv holding the peers
# (lumicks.pylake, tweezepy, emcee, numba, setuptools); without it the peer rows are skipped
# with the reason. Each script's stdout/stderr goes to DIR/<script>.log; scripts that write
# RESULTS_*.md and figures write them into DIR, so a quick run never overwrites the recorded
# results in benchmarks/ (copy the ones you want to record). A failing script is reported
# and the others still run; the exit status is non-zero if any failed.
set -u
cd "$(dirname "$0")/.."

MODE=quick
OUT=""
DRY=no
while [ $# -gt 0 ]; do
    case "$1" in
        --full) MODE=full ;;
        --quick) MODE=quick ;;
        --out) shift; OUT="$1" ;;
        --dry-run) DRY=yes ;;
        -h|--help) sed -n '2,15p' "$0"; exit 0 ;;
        *) echo "run_all.sh: unknown argument '$1' (expected --full, --quick, --out DIR, --dry-run)" >&2; exit 2 ;;
    esac
    shift
done
PY="${PYTHON:-python}"
OUT="${OUT:-benchmarks/out/$MODE}"
if [ $DRY = yes ]; then
    echo "# $MODE mode; would run from $(pwd), writing to $OUT:"
fi
export BLURTRAP_PEER_PYTHON="${BLURTRAP_PEER_PYTHON:-/work/peervenv/bin/python}"

if [ "$MODE" = quick ]; then
    RUNS=(
        "bench_simulate.py --quick"
        "bench_calibration.py --quick"
        "bench_scaling.py --out $OUT"
        "bench_peers.py --seeds 20 --photodiode-exact-seeds 5 --out $OUT --raw $OUT/peers_raw.json --data $OUT/peer_data"
        "bench_efficiency.py --seeds 50 --frames 32768 --out $OUT --raw $OUT/efficiency_raw.json"
        "study_calibration.py --quick --fig $OUT/calibration_study.png"
        "study_posterior.py --datasets 20 --steps 400 --out $OUT"
        "study_diagnose.py --quick --out $OUT"
        "study_robustness.py --out $OUT/robustness.json"
        "study_whittle_leakage.py"
    )
else
    RUNS=(
        "bench_simulate.py"
        "bench_calibration.py"
        "bench_scaling.py --full --out $OUT"
        "bench_peers.py --seeds 100 --out $OUT --raw $OUT/peers_raw.json --data $OUT/peer_data"
        "bench_efficiency.py --seeds 200 --frames 65536 --out $OUT --raw $OUT/efficiency_raw.json"
        "study_calibration.py --fig $OUT/calibration_study.png"
        "study_posterior.py --datasets 200 --steps 800 --out $OUT"
        "study_diagnose.py --out $OUT"
        "study_robustness.py --seeds 3 --out $OUT/robustness.json"
        "study_whittle_leakage.py"
    )
fi

# every benchmarks/bench_*.py and study_*.py must be listed above
for f in benchmarks/bench_*.py benchmarks/study_*.py; do
    base="$(basename "$f")"
    listed=no
    for r in "${RUNS[@]}"; do [ "${r%% *}" = "$base" ] && listed=yes; done
    [ $listed = no ] && echo "run_all.sh: NOTE $base is not in the run list; add it to run_all.sh" >&2
done

if [ $DRY = yes ]; then
    for r in "${RUNS[@]}"; do echo "nice $PY benchmarks/$r > $OUT/${r%%.py*}.log"; done
    exit 0
fi
mkdir -p "$OUT"
{
    echo "# run_all.sh ($MODE) $(date -Iseconds)"
    echo "machine: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $(nproc) cores; load $(cut -d' ' -f1-3 /proc/loadavg)"
    echo "python: $("$PY" -c 'import sys, jax, numpy, blurtrap; print(sys.version.split()[0], "jax", jax.__version__, "numpy", numpy.__version__, "blurtrap", blurtrap.__version__)' 2>&1)"
    echo "git: $(git rev-parse --short HEAD 2>/dev/null) $(git status --porcelain 2>/dev/null | wc -l) changed files"
    echo "peers: $BLURTRAP_PEER_PYTHON"
} | tee "$OUT/run_all.txt"

FAILED=()
for r in "${RUNS[@]}"; do
    script="${r%% *}"
    log="$OUT/${script%.py}.log"
    echo "== $r  ($(date +%H:%M:%S), load $(cut -d' ' -f1 /proc/loadavg)) -> $log" | tee -a "$OUT/run_all.txt"
    t0=$(date +%s)
    # shellcheck disable=SC2086
    if nice "$PY" benchmarks/$r > "$log" 2>&1; then status=ok; else status="FAILED (rc $?)"; FAILED+=("$script"); fi
    echo "   $status in $(( $(date +%s) - t0 )) s" | tee -a "$OUT/run_all.txt"
done

echo "results: $OUT (RESULTS_*.md, *.png, *.log)" | tee -a "$OUT/run_all.txt"
if [ ${#FAILED[@]} -gt 0 ]; then
    echo "failed: ${FAILED[*]}" | tee -a "$OUT/run_all.txt"
    exit 1
fi
