"""Worn-through tires in the fits: left out (tirewear's rule) against counted
as measured when under a share of their readings is capped, judged on every
testing tire's true wear (the simulator's truth/wear_truth.csv).

    python few_capped_in_fits.py WORK PRESET NOISE SEEDS [SHARE] [SIMULATE-FLAGS]
    python few_capped_in_fits.py /tmp/wt season realistic 601,602,603 0.4 "--scale 0.5 --rate 5"

For each seed: simulate, extract, then a copy of the KPI table whose
`worn_through_readings` is 0 on tires with under SHARE of their readings at
or below 5 % of the new depth (tirewear's worn-through rule,
src/kpi/wear.rs); fit the physical and PCA methods on both tables; predict
the original table; RMSE, bias and new-event-interval coverage of the
testing events' tires against their true wear. `TIREWEAR` names the binary
(default: `tirewear` on the PATH). Needs numpy, pandas, pyarrow.
docs/models.md, "Worn-through tires in the fits".
"""
import json, os, subprocess, sys

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

T = [os.environ.get("TIREWEAR", "tirewear"), "--quiet", "--log", "error"]


def sh(*a):
    subprocess.run(T + list(a), check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def main():
    work, preset, noise, seeds = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4]
    share = float(sys.argv[5]) if len(sys.argv) > 5 else 0.4
    extra = sys.argv[6].split() if len(sys.argv) > 6 else []
    rows = []
    for seed in [int(s) for s in seeds.split(",")]:
        d = f"{work}/{preset}-{noise}-{seed}"
        if not os.path.exists(d + "/kpis.parquet"):
            sh("simulate", "--preset", preset, "--seed", str(seed), "--wear-scatter", noise, *extra, "--out", d)
            sh("extract", d, "--out", d + "/kpis.parquet")
        rd = pd.read_csv(d + "/wear/readings.csv")
        rd["capped"] = rd.depth_mm <= 0.05 * rd.new_depth_mm
        g = rd.groupby(["run", "wheel"]).agg(n=("capped", "size"), c=("capped", "sum")).reset_index()
        g["share"] = g.c / g.n
        t = pq.read_table(d + "/kpis.parquet")
        m = t.to_pandas().merge(g, on=["run", "wheel"], how="left")
        few = (m.worn_through_readings > 0) & (m.share < share)
        wt = m.worn_through_readings.values.copy()
        wt[few.values] = 0.0
        i = t.schema.get_field_index("worn_through_readings")
        t2 = t.set_column(i, "worn_through_readings", pa.array(wt, type=t.schema.field(i).type))
        # A table from another tool: no tirewear checksum to refuse it by.
        pq.write_table(t2.replace_schema_metadata(None), d + "/kpis_few.parquet")
        truth = pd.read_csv(d + "/truth/wear_truth.csv")[["run", "wheel", "wear_total_pct"]]
        row = {"seed": seed, "worn": int((m.worn_through_readings > 0).sum()), "counted": int(few.sum())}
        for name, table in [("leave", d + "/kpis.parquet"), ("few", d + "/kpis_few.parquet")]:
            sh("fit", table, "--method", "physical,pca", "--out", f"{d}/m_{name}")
            for meth in ["physical", "pca"]:
                out = f"{d}/p_{name}_{meth}.csv"
                sh("predict", f"{d}/m_{name}/{meth}.json", d + "/kpis.parquet", "--out", out)
                testing = set(json.load(open(f"{d}/m_{name}/{meth}.json"))["testing_events"])
                p = pd.read_csv(out)
                p = p[p.event.isin(testing)].merge(truth, on=["run", "wheel"])
                e = p.predicted_wear_pct - p.wear_total_pct
                inside = (p.new_event_low_pct <= p.wear_total_pct) & (p.wear_total_pct <= p.new_event_high_pct)
                row[f"{name}_{meth}_rmse"] = float(np.sqrt(np.mean(e**2)))
                row[f"{name}_{meth}_bias"] = float(e.mean())
                row[f"{name}_{meth}_cov"] = float(inside.mean())
        rows.append(row)
        print(row, flush=True)
    r = pd.DataFrame(rows)
    for meth in ["physical", "pca"]:
        ratio = r[f"few_{meth}_rmse"] / r[f"leave_{meth}_rmse"]
        print(
            f"{meth}: testing RMSE against the truth, median left out {r[f'leave_{meth}_rmse'].median():.2f} %, "
            f"counted {r[f'few_{meth}_rmse'].median():.2f} %; ratio median {ratio.median():.3f}, "
            f"counted better in {int((ratio < 1).sum())} of {len(r)}; new-event 95 % coverage median "
            f"{r[f'leave_{meth}_cov'].median():.3f} / {r[f'few_{meth}_cov'].median():.3f}; "
            f"tires worn through {int(r.worn.sum())}, counted {int(r.counted.sum())}"
        )


if __name__ == "__main__":
    main()
