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

import pyarrow as pa
import pyarrow.parquet as pq

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
    for name in sorted(os.listdir(src)):
        season, copy = os.path.join(src, name), os.path.join(dst, name)
        if not os.path.isfile(os.path.join(season, "kpis.parquet")):
            continue
        os.makedirs(copy, exist_ok=True)
        for f in os.listdir(season):
            if f != "kpis.parquet" and not os.path.exists(os.path.join(copy, f)):
                os.symlink(os.path.abspath(os.path.join(season, f)), os.path.join(copy, f))
        shares = capped_shares(season)
        table = pq.read_table(os.path.join(season, "kpis.parquet"))
        d = table.to_pydict()
        changed = 0
        for i, (run, wheel, worn) in enumerate(zip(d["run"], d["wheel"], d["worn_through_readings"])):
            if worn > 0 and shares[(run, wheel)] < share:
                d["worn_through_readings"][i] = 0.0
                changed += 1
        out = pa.Table.from_pydict(d, schema=table.schema)
        pq.write_table(out.replace_schema_metadata(table.schema.metadata), os.path.join(copy, "kpis.parquet"))
        print(f"{name}: {changed} worn-through tires counted as measured")


if __name__ == "__main__":
    main()
