#!/usr/bin/env python3
"""Copies kept validation seasons so that a worn-through tire with under
SHARE of its depth readings capped counts as measured (docs/gap.md, "The
testing gap against the true wear, in the validation"): a trial, without a
change to tirewear, of the rule "a tire worn through at few spots enters as
measured".

Every file of each season is linked but kpis.parquet, which is written with
`worn_through_readings` set to 0 for those tires. `gap validate --work DST
--keep --reuse` with the seasons' own flags then diagnoses the copies (the
stamp, validate-season.txt, comes along).

usage: few_capped_as_measured.py SRC_SEASONS DST_SEASONS SHARE
Needs pyarrow (benches/peers/requirements.txt plus pyarrow).
"""
import collections
import csv
import os
import sys

from season_copies import copy_seasons

WORN_THROUGH_FRACTION = 0.05  # src/kpi/wear.rs


def capped_shares(season):
    readings, capped = collections.Counter(), collections.Counter()
    for r in csv.DictReader(open(os.path.join(season, "wear", "readings.csv"))):
        tire = (r["run"], r["wheel"])
        readings[tire] += 1
        capped[tire] += float(r["depth_mm"]) <= WORN_THROUGH_FRACTION * float(r["new_depth_mm"])
    return {t: capped[t] / readings[t] for t in readings}


def main():
    src, dst, share = sys.argv[1], sys.argv[2], float(sys.argv[3])

    def change(season, d):
        shares = capped_shares(season)
        changed = 0
        for i, (run, wheel, worn) in enumerate(zip(d["run"], d["wheel"], d["worn_through_readings"])):
            if worn > 0 and shares[(run, wheel)] < share:
                d["worn_through_readings"][i] = 0.0
                changed += 1
        return f"{changed} worn-through tires counted as measured"

    copy_seasons(src, dst, change)


if __name__ == "__main__":
    main()
