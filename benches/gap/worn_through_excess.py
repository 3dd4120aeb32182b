#!/usr/bin/env python3
"""How far a worn-through tire's measured mean wear lies below its true mean
wear, by the share of its depth readings at the worn-through depth
(docs/gap.md, "The testing gap against the true wear, in the validation").

A tire is flagged worn through (`worn_through_readings` > 0 in kpis.parquet)
when any reading is at or below 5 % of the new depth; its mean wear is then
a lower bound. This script reads, for each kept season (`gap validate
--keep`), the readings (wear/readings.csv), the KPI table and the truth
(truth/wear_truth.csv, `wear_total_pct`), and prints, per fifth of capped
readings, how many worn-through tires there are and their true minus
measured mean wear (%).

usage: worn_through_excess.py SEASON_DIR...
Needs pyarrow (benches/peers/requirements.txt plus pyarrow).
"""
import collections
import csv
import os
import statistics
import sys

import pyarrow.parquet as pq

WORN_THROUGH_FRACTION = 0.05  # src/kpi/wear.rs


def main():
    bins = collections.defaultdict(list)
    for season in sys.argv[1:]:
        truth = {
            (r["run"], r["wheel"]): float(r["wear_total_pct"])
            for r in csv.DictReader(open(os.path.join(season, "truth", "wear_truth.csv")))
        }
        readings, capped = collections.Counter(), collections.Counter()
        for r in csv.DictReader(open(os.path.join(season, "wear", "readings.csv"))):
            tire = (r["run"], r["wheel"])
            readings[tire] += 1
            capped[tire] += float(r["depth_mm"]) <= WORN_THROUGH_FRACTION * float(r["new_depth_mm"])
        kpis = pq.read_table(os.path.join(season, "kpis.parquet")).to_pydict()
        for run, wheel, wear, worn in zip(
            kpis["run"], kpis["wheel"], kpis["wear_mean_pct"], kpis["worn_through_readings"]
        ):
            if worn > 0:
                share = capped[(run, wheel)] / readings[(run, wheel)]
                bins[min(int(share * 5), 4)].append(truth[(run, wheel)] - wear)
    total = sum(len(v) for v in bins.values())
    print("| readings capped | tires | true − measured mean wear: median (quartiles), % |")
    print("|---|---|---|")
    for b in sorted(bins):
        v = bins[b]
        q = statistics.quantiles(v, n=4)
        print(
            f"| {20 * b}–{20 * b + 20} % | {len(v)} ({100 * len(v) / total:.0f} %) "
            f"| {statistics.median(v):+.1f} ({q[0]:+.1f}, {q[2]:+.1f}) |"
        )


if __name__ == "__main__":
    main()
