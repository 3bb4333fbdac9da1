#!/usr/bin/env bash
# Run every blurtrap benchmark and study in one command.
#
#   benchmarks/run_all.sh            # quick mode (~1 h on an idle 2-core CPU, 2-4x when shared)
#   benchmarks/run_all.sh --smoke    # every script at its smallest sizes, all code paths (~45 min
#                                    # at load 15 on 2 shared cores, mostly compilation)
#   benchmarks/run_all.sh --full     # the sizes recorded in benchmarks/RESULTS*.md (hours)
#   benchmarks/run_all.sh --out DIR  # where logs and results go (default benchmarks/out/<mode>)
#   benchmarks/run_all.sh --dry-run  # print the commands only
#
# Environment: PYTHON (default: python) must have blurtrap installed with its test extras and
# matplotlib; BLURTRAP_PEER_PYTHON names the interpreter of a separate venv holding the peers
# (lumicks.pylake, tweezepy, emcee, numba, setuptools); without it the peer rows are skipped
# with the reason. Each run's stdout/stderr goes to DIR/<script>.log (<script>_<first option>.log
# for a script listed twice); scripts that write
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
        --smoke) MODE=smoke ;;
        --out) shift; OUT="$1" ;;
        --dry-run) DRY=yes ;;
        -h|--help) sed -n '2,18p' "$0"; exit 0 ;;
        *) echo "run_all.sh: unknown argument '$1' (expected --smoke, --quick, --full, --out DIR, --dry-run)" >&2; exit 2 ;;
    esac
    shift
done
PY="${PYTHON:-python}"
OUT="${OUT:-benchmarks/out/$MODE}"
if [ $DRY = yes ]; then
    echo "# $MODE mode; would run from $(pwd), writing to $OUT:"
fi
export BLURTRAP_PEER_PYTHON="${BLURTRAP_PEER_PYTHON:-/work/peervenv/bin/python}"

if [ "$MODE" = smoke ]; then
    # smallest sizes that still run every code path of every script (numbers meaningless)
    RUNS=(
        "bench_simulate.py --quick --sizes 1 64 --repeat 1 --substeps 10 --memory-substeps 1e6 --json $OUT/simulate.json"
        "bench_numba_reference.py --sizes 1 64 --substeps 10 --budget 2e5 --repeat 1"
        "bench_calibration.py --quick"
        "bench_scaling.py --smoke --repeat 1 --out $OUT"
        "bench_scaling.py --gpu --gpu-scale 0.001 --out $OUT"
        "bench_peers.py --seeds 2 --photodiode-exact-seeds 1 --mcmc-steps 50 --max-frames 16384 --out $OUT --raw $OUT/peers_raw.json --data $OUT/peer_data"
        "bench_peers.py --replot $OUT/peers_raw.json --out $OUT/peers_replot"
        "bench_efficiency.py --seeds 3 --exact-seeds 2 --frames 4096 --out $OUT --raw $OUT/efficiency_raw.json"
        "bench_efficiency.py --recheck 0.5:1 2:series --recheck-seeds 3 --frames 4096 --out $OUT"
        "bench_efficiency.py --replot $OUT/efficiency_raw.json --out $OUT/efficiency_replot"
        "study_calibration.py --smoke --fig $OUT/calibration_study.png"
        "study_posterior.py --datasets 3 --steps 100 --timing-steps 100 --out $OUT"
        "study_diagnose.py --seeds 1 --effect-seeds 1 --weak-seeds 1 --power-seeds 1 --out $OUT"
        "study_robustness.py --smoke --out $OUT/robustness.json"
        "study_whittle_leakage.py --seeds 2 --ratios 30 1000 --frames 8192"
        "study_instruments.py --seeds 3 --chunk 3 --out $OUT --data $OUT/instruments_data --raw $OUT/instruments_raw.json"
    )
elif [ "$MODE" = quick ]; then
    RUNS=(
        "bench_simulate.py --quick"
        "bench_numba_reference.py --budget 2e6"
        "bench_calibration.py --quick"
        "bench_scaling.py --out $OUT"
        "bench_peers.py --seeds 20 --photodiode-exact-seeds 5 --out $OUT --raw $OUT/peers_raw.json --data $OUT/peer_data"
        "bench_efficiency.py --seeds 50 --frames 32768 --out $OUT --raw $OUT/efficiency_raw.json"
        "study_calibration.py --quick --fig $OUT/calibration_study.png"
        "study_posterior.py --datasets 20 --steps 400 --out $OUT"
        "study_diagnose.py --quick --out $OUT"
        "study_robustness.py --out $OUT/robustness.json"
        "study_whittle_leakage.py"
        "study_instruments.py --seeds 30 --out $OUT --data $OUT/instruments_data --raw $OUT/instruments_raw.json"
    )
else
    RUNS=(
        "bench_simulate.py"
        "bench_numba_reference.py"
        "bench_calibration.py"
        "bench_scaling.py --full --out $OUT"
        "bench_peers.py --seeds 100 --out $OUT --raw $OUT/peers_raw.json --data $OUT/peer_data"
        "bench_efficiency.py --seeds 200 --frames 65536 --out $OUT --raw $OUT/efficiency_raw.json"
        "study_calibration.py --fig $OUT/calibration_study.png"
        "study_posterior.py --datasets 200 --steps 800 --out $OUT"
        "study_diagnose.py --out $OUT"
        "study_robustness.py --seeds 3 --out $OUT/robustness.json"
        "study_whittle_leakage.py"
        "study_instruments.py --seeds 200 --out $OUT --data $OUT/instruments_data --raw $OUT/instruments_raw.json"
    )
fi

# every benchmarks/bench_*.py and study_*.py must be listed above
for f in benchmarks/bench_*.py benchmarks/study_*.py; do
    base="$(basename "$f")"
    listed=no
    for r in "${RUNS[@]}"; do [ "${r%% *}" = "$base" ] && listed=yes; done
    [ $listed = no ] && echo "run_all.sh: NOTE $base is not in the run list; add it to run_all.sh" >&2
done

# log file per run: the script name, plus the first option for a script listed twice
logname() {
    local r="$1" base="${1%%.py*}" n=0 x
    for x in "${RUNS[@]}"; do [ "${x%%.py*}" = "$base" ] && n=$((n + 1)); done
    if [ $n -gt 1 ]; then
        local opt="${r#* }"; opt="${opt%% *}"; opt="${opt#--}"
        [ "$opt" = "$r" ] || [ -z "$opt" ] || base="${base}_${opt}"
    fi
    echo "$base"
}

if [ $DRY = yes ]; then
    for r in "${RUNS[@]}"; do echo "nice $PY benchmarks/$r > $OUT/$(logname "$r").log"; done
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
    log="$OUT/$(logname "$r").log"
    echo "== $r  ($(date +%H:%M:%S), load $(cut -d' ' -f1 /proc/loadavg)) -> $log" | tee -a "$OUT/run_all.txt"
    t0=$(date +%s)
    # shellcheck disable=SC2086
    if nice "$PY" benchmarks/$r > "$log" 2>&1; then status=ok; else status="FAILED (rc $?)"; FAILED+=("$(logname "$r")"); fi
    echo "   $status in $(( $(date +%s) - t0 )) s" | tee -a "$OUT/run_all.txt"
done

echo "results: $OUT (RESULTS_*.md, *.png, *.log)" | tee -a "$OUT/run_all.txt"
if [ ${#FAILED[@]} -gt 0 ]; then
    echo "failed: ${FAILED[*]}" | tee -a "$OUT/run_all.txt"
    exit 1
fi
