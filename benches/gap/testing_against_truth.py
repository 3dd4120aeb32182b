#!/usr/bin/env python3
"""The testing events' gap measured against the simulator's true wear of every
testing tire (docs/gap.md, "The worn-through testing tires, measured against
the truth").

`tirewear gap` measures the testing events on the tires it can measure: a
tire whose tread wore through is left out, since its reading is only a lower
bound. That measure favours a law biased low. For a simulated season the
truth is known (truth/wear_truth.csv, `wear_total_pct`, uncapped), so this
script writes a copy of a kept season (`gap validate --keep`) whose testing
events' worn-through tires carry their true wear and are no longer flagged,
runs `tirewear gap` on it with each `--worn-through` setting, and prints the
testing RMSE of the final model (%) against that truth. Training rows are
untouched, so the terms chosen are the same as on the season itself.

usage: testing_against_truth.py TIREWEAR SEASON_DIR... [--settings leave-out,tobit]
Needs pyarrow (benches/peers/requirements.txt plus pyarrow).
"""
import csv
import json
import os
import subprocess
import sys
import tempfile

import pyarrow as pa
import pyarrow.parquet as pq


def uncapped_copy(season, dst, testing_events):
    """Links every file of `season` but kpis.parquet into `dst` (the side
    tables and compounds/ must come along: the law reads the WLF constants
    there), and writes kpis.parquet with the testing events' worn-through
    tires at their true wear. Returns how many tires changed."""
    os.makedirs(dst, exist_ok=True)
    for f in os.listdir(season):
        if f != "kpis.parquet":
            os.symlink(os.path.join(season, f), os.path.join(dst, f))
    truth = {
        (r["run"], r["wheel"]): float(r["wear_total_pct"])
        for r in csv.DictReader(open(os.path.join(season, "truth", "wear_truth.csv")))
    }
    table = pq.read_table(os.path.join(season, "kpis.parquet"))
    d = table.to_pydict()
    changed = 0
    for i, (event, run, wheel, worn) in enumerate(
        zip(d["event"], d["run"], d["wheel"], d["worn_through_readings"])
    ):
        if event in testing_events and worn > 0:
            d["wear_mean_pct"][i] = truth[(run, wheel)]
            d["worn_through_readings"][i] = 0.0
            changed += 1
    out = pa.Table.from_pydict(d, schema=table.schema)
    pq.write_table(out.replace_schema_metadata(table.schema.metadata), os.path.join(dst, "kpis.parquet"))
    return changed


def gap(tirewear, kpis, out, setting, extra=()):
    subprocess.run(
        [tirewear, "gap", kpis, "--worn-through", setting, "--out", out, "--quiet", *extra],
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    return json.load(open(os.path.join(out, "gap.json")))


def main():
    args = sys.argv[1:]
    settings = ["leave-out", "tobit"]
    if "--settings" in args:
        i = args.index("--settings")
        settings = args[i + 1].split(",")
        del args[i : i + 2]
    tirewear, seasons = args[0], args[1:]
    with tempfile.TemporaryDirectory() as work:
        for season in seasons:
            name = os.path.basename(os.path.normpath(season))
            # The testing events as the diagnosis picks them on the season
            # itself (the split alone: no terms needed for it).
            first = gap(
                tirewear,
                os.path.join(season, "kpis.parquet"),
                os.path.join(work, name, "as-is"),
                settings[0],
                ("--max-terms", "0"),
            )
            copy = os.path.join(work, name, "uncapped")
            n = uncapped_copy(season, copy, set(first["testing_events"]))
            line = f"{name}: {n} worn-through testing tires at their true wear"
            for s in settings:
                d = gap(tirewear, os.path.join(copy, "kpis.parquet"), os.path.join(work, name, s), s)
                base, last = d["steps"][0]["testing"], d["steps"][-1]["testing"]
                line += f" | {s}: RMSE {base['rmse_pct']:.2f} -> {last['rmse_pct']:.2f} % (bias {last['bias_pct']:+.2f})"
            print(line, flush=True)


if __name__ == "__main__":
    main()
