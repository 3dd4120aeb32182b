#!/usr/bin/env python3
"""Copies kept validation seasons so that the planted effect itself can be
offered to the diagnosis as a user hypothesis (docs/gap.md, "The planted
form offered as a hypothesis"): how often a diagnosis that is handed the
right answer among its candidates finds it, the ceiling of the hit rate
at a noise level.

Every file of each season is linked but kpis.parquet (season_copies.py), which is written
with the data-quality column `invalid_samples` (no model input, read by no
step of the diagnosis; zero in every simulated season) replaced by

    planted expected wear / (k_true(compound, axle) · E_MJ)

where the planted expected wear is truth/wear_truth.csv's
`wear_generated_pct / wear_scatter_factor` (the planted wear without the
tire's scatter, what the telemetry predicts), E_MJ the tire's friction
energy and k_true the simulator's abrasion per MJ of its compound and
axle (the median of `wear_base_pct / E_MJ`). The hypothesis of
EFFECTS_TOML, `expression = "invalid_samples"`, then sums over the energy
map to the planted expected wear divided by k_true, and the diagnosis
charges it at its own law's k like a built-in mechanism, so its term is
the planted expected wear up to the ratio of the law's k to the truth's.

`gap validate --work DST --keep --reuse --hypotheses DST/planted.toml` with
the seasons' own flags then diagnoses the copies.

usage: planted_as_hypothesis.py SRC_SEASONS DST_SEASONS
Needs pyarrow (benches/peers/requirements.txt plus pyarrow).
"""
import collections
import csv
import os
import statistics
import sys

from season_copies import copy_seasons

EFFECTS_TOML = """[[effect]]
name = "planted"
expression = "invalid_samples"
"""


def planted_per_mj(season):
    rows = list(csv.DictReader(open(os.path.join(season, "truth", "wear_truth.csv"))))
    axle = lambda w: "front" if w.startswith("F") else "rear"
    ratios = collections.defaultdict(list)
    for r in rows:
        e_mj = float(r["friction_energy_j"]) / 1e6
        if e_mj > 0:
            ratios[(r["compound"], axle(r["wheel"]))].append(float(r["wear_base_pct"]) / e_mj)
    k = {g: statistics.median(v) for g, v in ratios.items()}
    out = {}
    for r in rows:
        e_mj = float(r["friction_energy_j"]) / 1e6
        expected = float(r["wear_generated_pct"]) / float(r["wear_scatter_factor"])
        g = (r["compound"], axle(r["wheel"]))
        out[(r["run"], r["wheel"])] = expected / (k[g] * e_mj) if e_mj > 0 else 0.0
    return out


def main():
    src, dst = sys.argv[1], sys.argv[2]
    os.makedirs(dst, exist_ok=True)
    with open(os.path.join(dst, "planted.toml"), "w") as f:
        f.write(EFFECTS_TOML)

    def change(season, d):
        value = planted_per_mj(season)
        if any(x != 0.0 for x in d["invalid_samples"]):
            sys.exit(f"{season}: invalid_samples is not zero everywhere; pick another column")
        d["invalid_samples"] = [value[(run, wheel)] for run, wheel in zip(d["run"], d["wheel"])]
        return "planted wear per MJ written over invalid_samples"

    copy_seasons(src, dst, change)


if __name__ == "__main__":
    main()
