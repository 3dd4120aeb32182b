#!/usr/bin/env bash
# Regenerates the MCAP fixtures and their goldens. Run from the repository root.
#   tiny-*.mcap   written by tirewear (first run of the tiny preset at 5 Hz),
#                 then read by Python (read_our_mcap.py) into tests/golden/.
#   python-*.mcap written by Python mcap-protobuf-support (write_python_mcap.py).
set -euo pipefail
cargo build --release --quiet
tmp=$(mktemp -d)
for enc in sample block; do
  ./target/release/tirewear --quiet simulate --preset tiny --seed 3 --rate 5 --encoding "$enc" --out "$tmp/$enc"
  first=$(ls "$tmp/$enc/telemetry" | sort | head -n 1)
  cp "$tmp/$enc/telemetry/$first" "tests/fixtures/tiny-$enc.mcap"
done
rm -rf "$tmp"
python3 tests/oracles/read_our_mcap.py
python3 tests/oracles/write_python_mcap.py
# Logger files for `tirewear import` and their goldens (plain Python).
python3 tests/oracles/write_motec_csv.py
python3 tests/oracles/write_motec_ld.py
