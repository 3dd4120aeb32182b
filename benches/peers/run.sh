#!/usr/bin/env bash
# Whole-season extraction against its two references, measured in one run:
#   - zstd alone decompressing the same chunks (the physical limit), and
#   - the Python peer (benches/peers/python_peer.py: the official mcap +
#     mcap-protobuf-support readers and numpy), on one core and on all.
#
#   benches/peers/run.sh [SEASON] [OUT]
#
# SEASON: a season archive; default: the demo season simulated (seed 1) into
# target/peer-season. OUT: where bench.json and peer.json go (default
# target/peer-results). Needs Python 3.11+ with benches/peers/requirements.txt
# installed (`python3 -m venv v && v/bin/pip install -r benches/peers/requirements.txt`;
# PYTHON=v/bin/python). Not needed by CI or the tests.
set -euo pipefail
cd "$(dirname "$0")/../.."
SEASON=${1:-target/peer-season}
OUT=${2:-target/peer-results}
PYTHON=${PYTHON:-python3}
cargo build --release --quiet
TW=target/release/tirewear
mkdir -p "$OUT"
if [ ! -f "$SEASON/season.toml" ]; then
  "$TW" simulate --preset demo --seed 1 --quiet --out "$SEASON"
fi
# The page cache holds the files for every contender alike.
cat "$SEASON"/telemetry/*.mcap > /dev/null
"$TW" bench --engine cpu --only decode --season "$SEASON" --quiet --out "$OUT/bench.json"
CORES=$(nproc)
peer() {
  "$PYTHON" benches/peers/python_peer.py "$SEASON" --jobs "$1" --out "$OUT/peer-$1.json" \
    | sed -n 's/^seconds: //p'
}
P1=$(peer 1)
PN=$(peer "$CORES")
"$PYTHON" - "$OUT/bench.json" "$P1" "$PN" "$CORES" <<'PY'
import json, sys
bench, p1, pn, cores = json.load(open(sys.argv[1])), float(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
t = {l["engine"]: l["seconds"] for l in bench["lines"] if l["kernel"] == "decode, season"}
z1, e1, d1 = t["zstd only, 1 thread"], t["extract, 1 thread"], t["tirewear, 1 thread"]
zn = next(v for k, v in t.items() if k.startswith("zstd only,") and "1 thread" not in k)
en = next(v for k, v in t.items() if k.startswith("extract,") and "1 thread" not in k)
dn = next(v for k, v in t.items() if k.startswith("tirewear,") and "1 thread" not in k)
print(f"{'':26}{'1 core':>10}{cores + ' cores':>10}")
for name, a, b in [("zstd only (s)", z1, zn), ("tirewear decode (s)", d1, dn),
                   ("tirewear extract (s)", e1, en), ("Python peer (s)", p1, pn)]:
    print(f"{name:26}{a:10.3f}{b:10.3f}")
print(f"{'extract vs Python peer':26}{p1 / e1:9.1f}x{pn / en:9.1f}x   (target >= 20x on one core)")
print(f"{'extract vs zstd alone':26}{z1 / e1:10.2f}{zn / en:10.2f}   (target >= 0.5)")
print(f"{'decode vs zstd alone':26}{z1 / d1:10.2f}{zn / dn:10.2f}")
PY
