#!/usr/bin/env bash
# The long Monte-Carlo runs behind the README's tables, one after the other, each timed.
#
#   scripts/long_runs.sh [OUT [JOB...]]   # default docs/results/long, every job; logs in OUT/*.log

#
# Every job is a documented command; the README quotes its figures, command and wall time.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT="${1:-$ROOT/docs/results/long}"
TL="${TLTRACK:-$ROOT/.venv/bin/tltrack}"
mkdir -p "$OUT"

shift $(( $# > 0 ? 1 : 0 ))
JOBS=" $* "  # empty: every job

run() {  # run NAME ARGS...: the command, its log and its wall time in OUT/NAME.log
    local name="$1"; shift
    [[ "$JOBS" == "  " || "$JOBS" == *" $name "* ]] || return 0
    local t0; t0=$(date +%s)
    local cmd=("$TL")  # or ARGS = --script FILE ARGS: a benchmark script in the same venv
    if [[ "$1" == --script ]]; then cmd=("$(dirname "$TL")/python" "$ROOT/$2"); shift 2; fi
    echo "\$ ${cmd[*]##*/} $*" > "$OUT/$name.log"
    MPLBACKEND=Agg "${cmd[@]}" "$@" >> "$OUT/$name.log" 2>&1
    echo "wall: $(( $(date +%s) - t0 )) s, load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)" >> "$OUT/$name.log"
}

run remedies-eval-s3 --script benchmarks/rpf_remedies.py --runs 300 --seed 3 --betas 0.3,1.0 \
    --json "$OUT/remedies-eval-s3.json"
run rpf-paper-fixed experiment --scenario ct --preset paper --truth fixed \
    --filters pf,tl-pf,rpf,tl-rpf,robust-tl-rpf,ukf,tl-ukf --particles 6000 --runs 1000 \
    --primary-intensity 4 --seed 1 --out "$OUT/rpf-paper-fixed"
run realizations-paper study realizations --preset paper --realizations 100 --runs 10 \
    --filters pf,tl-pf,rpf,tl-rpf,ukf,tl-ukf,ckf3,tl-ckf3,ckf5,tl-ckf5 --out "$OUT/realizations-paper"
run realizations-ah study realizations --preset arasaratnam-haykin --realizations 100 --runs 10 \
    --filters pf,tl-pf,rpf,tl-rpf,ukf,tl-ukf,ckf3,tl-ckf3,ckf5,tl-ckf5 --out "$OUT/realizations-ah"
run heterogeneous-rpf study heterogeneous --kind rpf --runs 200 --out "$OUT/heterogeneous-rpf"
run remedies-tuning-s11 --script benchmarks/rpf_remedies.py --runs 200 --seed 11 --truth-seed 11 \
    --betas 0.1,0.3,0.6,1.0 --json "$OUT/remedies-tuning-s11.json"
run presets study presets --kind rpf --runs 1000 --out "$OUT/presets"
run intensities study intensities --kind rpf --runs 1000 --out "$OUT/intensities"
run robust-rpf study robust --kind rpf --runs 1000 --out "$OUT/robust-rpf"
run presets-sourcepf study presets --kind rpf --source-filter pf --runs 1000 \
    --out "$OUT/presets-sourcepf"
run heterogeneous-pf study heterogeneous --runs 200 --out "$OUT/heterogeneous-pf"
run losses-10000 reproduce --losses-only --runs 10000 --out "$OUT/losses-10000"
run table2-10000 reproduce --table2-pf-only --runs 10000 --out "$OUT/table2-10000"
# Table 2's rpf rows alone, the same configs and seed as table2-10000 (whose SIR rows are already
# docs/results/table2_pf_10000.md, and `pf` is unchanged bit for bit), in about 40% less time.
for n in 3000 6000 9000 12000; do
    run "table2-rpf-10000-n$n" experiment --scenario ct --preset paper --truth fixed \
        --filters rpf,tl-rpf --particles "$n" --runs 10000 --primary-intensity 4 --seed 0 \
        --out "$OUT/table2-rpf-10000/n$n"
done
# The lost-track table's rpf rows at 10,000 runs, with the UKF they are held to in the same run:
# the configs and seed of losses-10000 (whose SIR rows are docs/results/paper-10000/report.md),
# without its SIR filters, in about a third of its time.
for p in paper arasaratnam-haykin; do
    for t in fixed random noise-free; do
        run "losses-rpf-10000-$p-$t" experiment --scenario ct --preset "$p" --truth "$t" \
            --filters rpf,tl-rpf,robust-tl-rpf,ukf,tl-ukf --particles 6000 --runs 10000 \
            --primary-intensity 4 --seed 0 --out "$OUT/losses-rpf-10000/$p-$t"
    done
done
# The same cell as losses-rpf-10000-arasaratnam-haykin-random, with the rpf's regularisation on
# (docs/rpf.md, "Regularisation").
run regularised-10000-arasaratnam-haykin-random experiment --scenario ct \
    --preset arasaratnam-haykin --truth random --filters rpf,tl-rpf,robust-tl-rpf,ukf,tl-ukf \
    --particles 6000 --runs 10000 --primary-intensity 4 --seed 0 --rpf-bandwidth 0.2 \
    --out "$OUT/regularised-10000/arasaratnam-haykin-random"
run regularised-10000-arasaratnam-haykin-random-h05 experiment --scenario ct \
    --preset arasaratnam-haykin --truth random --filters rpf,tl-rpf,robust-tl-rpf,ukf,tl-ukf \
    --particles 6000 --runs 10000 --primary-intensity 4 --seed 0 --rpf-bandwidth 0.5 \
    --out "$OUT/regularised-10000/arasaratnam-haykin-random-h05"
# The issue's bearing-only pair (examples/bearing-only-primary.toml) on ten seeds: how far TL-PF
# is from fusion is a property of the pair, or noise of one seed?
for s in 1 2 3 4 5 6 7 8 9 10; do
    run "bearing-seed-$s" experiment --config "$ROOT/examples/bearing-only-primary.toml" \
        --preset arasaratnam-haykin --truth noise-free --filters pf,tl-pf,fusion-pf,ukf,tl-ukf \
        --particles 6000 --runs 200 --seed "$s" --out "$OUT/bearing-seeds/s$s"
done
# The presets study's one cell where tl-rpf trails tl-ukf (arasaratnam-haykin, truth seed 4):
# each TL filter fed by a source of its own kind, then the source's kind crossed.
PAIRING=(--scenario ct --preset arasaratnam-haykin --truth fixed --truth-seed 4 --particles 6000
    --runs 1000 --primary-intensity 4 --seed 0)
run pairing-ah-fixed4-own experiment "${PAIRING[@]}" --filters rpf,tl-rpf,ukf,tl-ukf \
    --out "$OUT/pairing-ah-fixed4/own"
run pairing-ah-fixed4-tl-rpf-src-ukf experiment "${PAIRING[@]}" --filters tl-rpf \
    --source-filter ukf --out "$OUT/pairing-ah-fixed4/tl-rpf-src-ukf"
run pairing-ah-fixed4-tl-ukf-src-rpf experiment "${PAIRING[@]}" --filters tl-ukf \
    --source-filter rpf --out "$OUT/pairing-ah-fixed4/tl-ukf-src-rpf"
run pairing-ah-fixed4-own-h05 experiment "${PAIRING[@]}" --filters rpf,tl-rpf,ukf,tl-ukf \
    --rpf-bandwidth 0.5 --out "$OUT/pairing-ah-fixed4/own-h05"
run turn-bias-ah-fixed4 --script benchmarks/turn_bias.py --runs 100 --truth-seed 4
run turn-bias-ah-fixed4-n24000 --script benchmarks/turn_bias.py --runs 100 --truth-seed 4 \
    --particles 24000
# The divergent runs of the a-h random lost-track cell (run RMSE past 500 m), rerun at 4N.
run divergent-runs-ah-random --script benchmarks/divergent_runs.py \
    "$ROOT/docs/results/long/losses-rpf-10000/arasaratnam-haykin-random/results.json" \
    --particles 6000,24000
# The two lost TL-RPF runs of the presets study's paper fixed-1 cell, rerun at 4N.
run divergent-runs-paper-fixed1 --script benchmarks/divergent_runs.py --runs 497,760 \
    --preset paper --truth fixed --truth-seed 1 --particles 6000,24000
# How one TL-RPF divergence of that cell unfolds (run 6275), at N and at 4N.
run trace-run-6275 --script benchmarks/trace_run.py --run 6275 --every 5
run trace-run-6275-n24000 --script benchmarks/trace_run.py --run 6275 --every 5 --particles 24000
# The product's routers against stock zenohd routers (needs `make zenohd`).
run router-rtt --script benchmarks/router_rtt.py --rounds 3
# Regularisation on a seed nobody looked at (h = 0.5 was chosen on seed 0's worst runs).
for h in 0 0.5; do
    run "heldout-seed1-ah-random-h$h" experiment --scenario ct --preset arasaratnam-haykin \
        --truth random --filters rpf,tl-rpf,robust-tl-rpf,ukf,tl-ukf --particles 6000 \
        --runs 10000 --primary-intensity 4 --seed 1 --rpf-bandwidth "$h" \
        --out "$OUT/heldout-seed1/arasaratnam-haykin-random-h$h"
done
# Two more proposals for rpf (benchmarks/proposals.py), on the 13 divergent runs at N = 6000,
# and the defensive one over the held-out seed's 10,000 runs.
for p in defensive linearised; do
    run "proposals-$p-ah-random" --script benchmarks/proposals.py \
        "$ROOT/docs/results/long/losses-rpf-10000/arasaratnam-haykin-random/results.json" \
        --particles 6000 --compare "" --rerun "rpf-$p,tl-rpf-$p,robust-tl-rpf-$p"
done
run proposals-defensive-seed1 --script benchmarks/proposals.py tltrack experiment \
    --scenario ct --preset arasaratnam-haykin --truth random \
    --filters rpf-defensive,tl-rpf-defensive,robust-tl-rpf-defensive \
    --particles 6000 --runs 10000 --primary-intensity 4 --seed 1 \
    --out "$OUT/proposals/defensive-ah-random-seed1"
