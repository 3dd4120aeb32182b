#!/usr/bin/env bash
# Season-scale extraction on both engines, the way docs/performance.md
# measured it: simulate a `season` archive, read it once so the page cache
# holds it, then extract it with the CPU and the GPU engine, twice each.
#
#   benches/season_engines.sh [TIREWEAR_BINARY] [SCALE] [WORKDIR]
#   JOBS=1 benches/season_engines.sh ...   # one decoding thread (--jobs 1)
#
# Prints each extraction's summary (rate, decode share, GPU time split) and
# wall time and peak memory from /usr/bin/time when it exists.
set -euo pipefail
bin=${1:-target/release/tirewear}
scale=${2:-1}
work=${3:-$(mktemp -d)}
jobs=()
[ -n "${JOBS:-}" ] && jobs=(--jobs "$JOBS")
season="$work/season"
"$bin" --quiet simulate --preset season --scale "$scale" --out "$season" | tail -1
find "$season" -name '*.mcap' -exec cat {} + >/dev/null
timed() {
    if [ -x /usr/bin/time ]; then /usr/bin/time -f "$1: %e s wall, %M KB peak" "${@:2}"; else shift; "$@"; fi
}
for rep in 1 2; do
    for engine in cpu gpu; do
        echo "== extract --engine $engine (repeat $rep)"
        timed "extract $engine" "$bin" --quiet extract "$season" --engine "$engine" "${jobs[@]}" \
            --out "$work/kpis-$engine.parquet" 2>&1 | grep -v INFO
    done
done
