#!/usr/bin/env bash
# The long runs behind the papers' tables, one after the other, each timed.
#
#   scripts/long_runs.sh [--out DIR] [JOB...]   # every job when none is named
#
# Each job writes into its study's folder, papers/<study>/results/ (with --out, DIR/<study>/
# instead: a scratch copy that leaves the committed results alone), and its log, the command, its
# output and its wall time, beside them as <job>.log. After each job the per-run arrays
# (run_rmse) are set aside by papers/strip_runs.py: the results files keep the summaries that
# are committed, <name>.full.json the untouched original, which git ignores.
#
# Every job is a documented command; each paper's README quotes its figures, command and wall time.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
TL="${TLTRACK:-$ROOT/.venv/bin/tltrack}"
PY="$(dirname "$TL")/python"
OUT=""
if [[ "${1:-}" == --out ]]; then OUT="$(mkdir -p "$2" && cd "$2" && pwd)"; shift 2; fi
JOBS=" $* "  # empty: every job

results() {  # results STUDY: where that study's jobs write
    if [[ -n "$OUT" ]]; then echo "$OUT/$1"; else echo "$ROOT/papers/$1/results"; fi
}
RPF="$(results rpf)"
REPRO="$(results reproduction)"
REAL="$(results realizations)"
HETERO="$(results heterogeneous)"
ROBUST="$(results robust)"
LATENCY="$(results latency)"
DASK="$(results dask)"
MANOEUVRES="$(results manoeuvres)"
CLUTTER="$(results clutter)"
LINKS="$(results links)"
STONESOUP="$(results stonesoup)"

run() {  # run DIR NAME ARGS...: the command, its log and its wall time in DIR/NAME.log
    local dir="$1" name="$2"; shift 2
    [[ "$JOBS" == "  " || "$JOBS" == *" $name "* ]] || return 0
    mkdir -p "$dir"
    local t0; t0=$(date +%s)
    local cmd=("$TL")  # or ARGS = --script FILE ARGS: a script in the same venv
    if [[ "$1" == --script ]]; then cmd=("$PY" "$ROOT/$2"); shift 2; fi
    # a job that resumes from a checkpoint adds to its log; any other starts it afresh
    if [[ " $* " != *" --checkpoint"* ]]; then : > "$dir/$name.log"; fi
    echo "\$ ${cmd[*]##*/} $*  # $(date -u +%FT%TZ)" >> "$dir/$name.log"
    MPLBACKEND=Agg "${cmd[@]}" "$@" >> "$dir/$name.log" 2>&1
    echo "wall: $(( $(date +%s) - t0 )) s, load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)" >> "$dir/$name.log"
    "$PY" "$ROOT/papers/strip_runs.py" "$dir" > /dev/null
}

# ---- papers/reproduction: the paper's figures and tables
run "$REPRO" reproduce-paper reproduce --runs 500 --out "$REPRO/paper"
run "$REPRO" reproduce-ah reproduce --runs 500 --preset arasaratnam-haykin --truth noise-free \
    --out "$REPRO/ah"
run "$REPRO" reproduce-10000 reproduce --runs 10000 --out "$REPRO/paper-10000"
run "$REPRO" losses-10000 reproduce --losses-only --runs 10000 --out "$REPRO/losses-10000"
# Table 2's particle-filter rows alone (its table2_pf.md is committed as table2_pf_10000.md).
run "$REPRO" table2-10000 reproduce --table2-pf-only --runs 10000 --out "$REPRO/table2-10000"
# Table 2's rpf rows alone, the same configs and seed as table2-10000 (`pf` is unchanged bit for
# bit), in about 40% less time.
for n in 3000 6000 9000 12000; do
    run "$REPRO" "table2-rpf-10000-n$n" experiment --scenario ct --preset paper --truth fixed \
        --filters rpf,tl-rpf --particles "$n" --runs 10000 --primary-intensity 4 --seed 0 \
        --out "$REPRO/table2-rpf-10000/n$n"
done

# ---- papers/realizations: the paper's trajectory is one draw
run "$REAL" realizations-paper study realizations --preset paper --realizations 100 --runs 10 \
    --filters pf,tl-pf,rpf,tl-rpf,ukf,tl-ukf,ckf3,tl-ckf3,ckf5,tl-ckf5 --out "$REAL/realizations-paper"
run "$REAL" realizations-ah study realizations --preset arasaratnam-haykin --realizations 100 \
    --runs 10 --filters pf,tl-pf,rpf,tl-rpf,ukf,tl-ukf,ckf3,tl-ckf3,ckf5,tl-ckf5 \
    --out "$REAL/realizations-ah"

# ---- papers/heterogeneous: operators with different sensors
run "$HETERO" heterogeneous-rpf study heterogeneous --kind rpf --runs 200 \
    --out "$HETERO/heterogeneous-rpf"
run "$HETERO" heterogeneous-pf study heterogeneous --runs 200 --out "$HETERO/heterogeneous-pf"
# The issue's bearing-only pair (examples/bearing-only-primary.toml) on ten seeds: how far TL-PF
# is from fusion is a property of the pair, or noise of one seed?
for s in 1 2 3 4 5 6 7 8 9 10; do
    run "$HETERO" "bearing-seed-$s" experiment --config "$ROOT/examples/bearing-only-primary.toml" \
        --preset arasaratnam-haykin --truth noise-free --filters pf,tl-pf,fusion-pf,ukf,tl-ukf \
        --particles 6000 --runs 200 --seed "$s" --out "$HETERO/bearing-seeds/s$s"
done

# ---- papers/robust: faulty sources, several sources, the communication budget (pf)
for s in robust sources budget; do
    run "$ROBUST" "$s-pf" study "$s" --runs 200 --out "$ROBUST"
done

# ---- papers/manoeuvres: one model against the target class's modes on every truth
# Both keep their batches in one checkpoint folder: stopped, the same command resumes, and the
# 1000 runs reuse the 200's. Git ignores the batches but not the finished sweeps (sweep-*.json)
# nor the prefixes of unfinished ones (prefix-*.json): committed, they carry the 1000 runs (about
# 3.2 h on 2 cores at the 200's rate) across sessions.
run "$MANOEUVRES" manoeuvres study manoeuvres --runs 200 --out "$MANOEUVRES" \
    --checkpoint "$MANOEUVRES/checkpoint"
run "$MANOEUVRES" manoeuvres-1000 study manoeuvres --runs 1000 --out "$MANOEUVRES/n1000" \
    --checkpoint "$MANOEUVRES/checkpoint"
run "$MANOEUVRES" modes-step --script benchmarks/modes_step.py --runs 10 \
    --json "$MANOEUVRES/modes_step.json"

# ---- papers/clutter: the lost share against the false alarms in the gate, at N = 1000
run "$CLUTTER" clutter-20 study clutter --runs 20 --particles 1000 --out "$CLUTTER"
# ... at the study's own N = 6000 (its default), in a folder of its own
run "$CLUTTER" clutter-6000-100 study clutter --runs 100 --out "$CLUTTER/n6000"
# ... the issue's 200 and 1000 runs, sharing their batches (the 1000 about 11 h on 2 cores)
run "$CLUTTER" clutter-6000-200 study clutter --runs 200 --out "$CLUTTER/n6000-200" \
    --checkpoint "$CLUTTER/checkpoint"
run "$CLUTTER" clutter-6000-1000 study clutter --runs 1000 --out "$CLUTTER/n6000-1000" \
    --checkpoint "$CLUTTER/checkpoint"
# The headline's factor at the study's N = 6000, on a grid below the study's first point.
run "$CLUTTER" factor-200 --script papers/clutter/factor.py 200 "$CLUTTER/factor"
# ... with the paper's clean sensor at the source, and its gates against R's
run "$CLUTTER" factor-clean-200 --script papers/clutter/factor.py 200 "$CLUTTER/factor-clean" clean
run "$CLUTTER" gates-200 --script papers/clutter/gates.py 200

# ---- papers/links: a lossy, late link between vehicles (rpf, N = 6000)
run "$LINKS" links-200 study links --kind rpf --runs 200 --out "$LINKS/runs-200"
run "$LINKS" links-1000 study links --kind rpf --runs 1000 --out "$LINKS"

# ---- papers/stonesoup: a Stone Soup particle filter with the plugin against the engine (N = 1000)
run "$STONESOUP" stonesoup-particles-500 --script papers/stonesoup/particles.py 500 \
    "$STONESOUP/particles-500.json"

# ---- papers/rpf: the particle filter that keeps the track
run "$RPF" remedies-eval-s3 --script papers/rpf/rpf_remedies.py --runs 300 --seed 3 \
    --betas 0.3,1.0 --json "$RPF/remedies-eval-s3.json"
run "$RPF" remedies-tuning-s11 --script papers/rpf/rpf_remedies.py --runs 200 --seed 11 \
    --truth-seed 11 --betas 0.1,0.3,0.6,1.0 --json "$RPF/remedies-tuning-s11.json"
run "$RPF" rpf-paper-fixed experiment --scenario ct --preset paper --truth fixed \
    --filters pf,tl-pf,rpf,tl-rpf,robust-tl-rpf,ukf,tl-ukf --particles 6000 --runs 1000 \
    --primary-intensity 4 --seed 1 --out "$RPF/rpf-paper-fixed"
run "$RPF" presets study presets --kind rpf --runs 1000 --out "$RPF/presets"
run "$RPF" intensities study intensities --kind rpf --runs 1000 --out "$RPF/intensities"
run "$RPF" robust-rpf study robust --kind rpf --runs 1000 --out "$RPF/robust-rpf"
run "$RPF" presets-sourcepf study presets --kind rpf --source-filter pf --runs 1000 \
    --out "$RPF/presets-sourcepf"
# The lost-track table's rpf rows at 10,000 runs, with the UKF they are held to in the same run:
# the configs and seed of losses-10000 (whose SIR rows are papers/reproduction/results/
# paper-10000/report.md), without its SIR filters, in about a third of its time.
for p in paper arasaratnam-haykin; do
    for t in fixed random noise-free; do
        run "$RPF" "losses-rpf-10000-$p-$t" experiment --scenario ct --preset "$p" --truth "$t" \
            --filters rpf,tl-rpf,robust-tl-rpf,ukf,tl-ukf --particles 6000 --runs 10000 \
            --primary-intensity 4 --seed 0 --out "$RPF/losses-rpf-10000/$p-$t"
    done
done
# The same cell as losses-rpf-10000-arasaratnam-haykin-random, with the rpf's regularisation on
# (papers/rpf/README.md, "Regularisation").
run "$RPF" regularised-10000-arasaratnam-haykin-random experiment --scenario ct \
    --preset arasaratnam-haykin --truth random --filters rpf,tl-rpf,robust-tl-rpf,ukf,tl-ukf \
    --particles 6000 --runs 10000 --primary-intensity 4 --seed 0 --rpf-bandwidth 0.2 \
    --out "$RPF/regularised-10000/arasaratnam-haykin-random"
run "$RPF" regularised-10000-arasaratnam-haykin-random-h05 experiment --scenario ct \
    --preset arasaratnam-haykin --truth random --filters rpf,tl-rpf,robust-tl-rpf,ukf,tl-ukf \
    --particles 6000 --runs 10000 --primary-intensity 4 --seed 0 --rpf-bandwidth 0.5 \
    --out "$RPF/regularised-10000/arasaratnam-haykin-random-h05"
# The presets study's one cell where tl-rpf trails tl-ukf (arasaratnam-haykin, truth seed 4):
# each TL filter fed by a source of its own kind, then the source's kind crossed.
PAIRING=(--scenario ct --preset arasaratnam-haykin --truth fixed --truth-seed 4 --particles 6000
    --runs 1000 --primary-intensity 4 --seed 0)
run "$RPF" pairing-ah-fixed4-own experiment "${PAIRING[@]}" --filters rpf,tl-rpf,ukf,tl-ukf \
    --out "$RPF/pairing-ah-fixed4/own"
run "$RPF" pairing-ah-fixed4-tl-rpf-src-ukf experiment "${PAIRING[@]}" --filters tl-rpf \
    --source-filter ukf --out "$RPF/pairing-ah-fixed4/tl-rpf-src-ukf"
run "$RPF" pairing-ah-fixed4-tl-ukf-src-rpf experiment "${PAIRING[@]}" --filters tl-ukf \
    --source-filter rpf --out "$RPF/pairing-ah-fixed4/tl-ukf-src-rpf"
run "$RPF" pairing-ah-fixed4-own-h05 experiment "${PAIRING[@]}" --filters rpf,tl-rpf,ukf,tl-ukf \
    --rpf-bandwidth 0.5 --out "$RPF/pairing-ah-fixed4/own-h05"
run "$RPF" turn-bias-ah-fixed4 --script papers/rpf/turn_bias.py --runs 100 --truth-seed 4
run "$RPF" turn-bias-ah-fixed4-n24000 --script papers/rpf/turn_bias.py --runs 100 --truth-seed 4 \
    --particles 24000
# The divergent runs of the a-h random lost-track cell (run RMSE past 500 m), rerun at 4N: the
# 13 runs that papers/rpf/divergent_runs.py finds in that cell's per-run arrays
# (losses-rpf-10000/arasaratnam-haykin-random/results.full.json, when that job ran here).
DIVERGENT=1273,1896,3978,4539,4907,5523,6275,7322,7505,8110,8504,9279,9607
run "$RPF" divergent-runs-ah-random --script papers/rpf/divergent_runs.py --runs "$DIVERGENT" \
    --preset arasaratnam-haykin --truth random --particles 6000,24000
# The two lost TL-RPF runs of the presets study's paper fixed-1 cell, rerun at 4N.
run "$RPF" divergent-runs-paper-fixed1 --script papers/rpf/divergent_runs.py --runs 497,760 \
    --preset paper --truth fixed --truth-seed 1 --particles 6000,24000
# How one TL-RPF divergence of that cell unfolds (run 6275), at N and at 4N.
run "$RPF" trace-run-6275 --script papers/rpf/trace_run.py --run 6275 --every 5
run "$RPF" trace-run-6275-n24000 --script papers/rpf/trace_run.py --run 6275 --every 5 \
    --particles 24000
# Regularisation on a seed nobody looked at (h = 0.5 was chosen on seed 0's worst runs).
for h in 0 0.5; do
    run "$RPF" "heldout-seed1-ah-random-h$h" experiment --scenario ct \
        --preset arasaratnam-haykin --truth random --filters rpf,tl-rpf,robust-tl-rpf,ukf,tl-ukf \
        --particles 6000 --runs 10000 --primary-intensity 4 --seed 1 --rpf-bandwidth "$h" \
        --out "$RPF/heldout-seed1/arasaratnam-haykin-random-h$h"
done
# Two more proposals for rpf (papers/rpf/proposals.py), on the 13 divergent runs at N = 6000,
# and the defensive one over the held-out seed's 10,000 runs.
for p in defensive linearised; do
    run "$RPF" "proposals-$p-ah-random" --script papers/rpf/proposals.py --runs "$DIVERGENT" \
        --preset arasaratnam-haykin --truth random --particles 6000 --compare "" \
        --rerun "rpf-$p,tl-rpf-$p,robust-tl-rpf-$p"
done
run "$RPF" proposals-defensive-seed1 --script papers/rpf/proposals.py tltrack experiment \
    --scenario ct --preset arasaratnam-haykin --truth random \
    --filters rpf-defensive,tl-rpf-defensive,robust-tl-rpf-defensive \
    --particles 6000 --runs 10000 --primary-intensity 4 --seed 1 \
    --out "$RPF/proposals/defensive-ah-random-seed1"

# ---- papers/latency: step times and the live tracker's latency (want a quiet machine)
run "$LATENCY" bench bench --json "$LATENCY/bench.json"
run "$LATENCY" bench-live bench-live --particles 6000 --pace 50 --json "$LATENCY/bench-live.json"
# The product's routers against stock zenohd routers (needs `make zenohd`).
run "$LATENCY" router-rtt --script benchmarks/router_rtt.py --rounds 3

# ---- papers/dask: a Dask cluster against the local process pool (52 min)
run "$DASK" dask-vs-pool --script benchmarks/dask_vs_pool.py --runs 1000 --repeats 3 \
    --json "$DASK/dask_vs_pool-1000.json"
