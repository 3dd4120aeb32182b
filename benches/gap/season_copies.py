"""Copies of kept validation seasons with their KPI table changed: every
file of each season is linked but kpis.parquet, which `change` rewrites.
`gap validate --work DST --keep --reuse` then diagnoses the copies (the
stamp, validate-season.txt, comes along). Shared by the scripts beside it.
Needs pyarrow (benches/peers/requirements.txt plus pyarrow).
"""
import os

import pyarrow as pa
import pyarrow.parquet as pq


def copy_seasons(src, dst, change):
    """For each season under SRC with a kpis.parquet, a copy under DST whose
    KPI table is `change(season_dir, columns)` applied to the table's
    columns as a dict of lists (changed in place); its message is printed
    after the season's name."""
    for name in sorted(os.listdir(src)):
        season, copy = os.path.join(src, name), os.path.join(dst, name)
        if not os.path.isfile(os.path.join(season, "kpis.parquet")):
            continue
        os.makedirs(copy, exist_ok=True)
        for f in os.listdir(season):
            if f != "kpis.parquet" and not os.path.exists(os.path.join(copy, f)):
                os.symlink(os.path.abspath(os.path.join(season, f)), os.path.join(copy, f))
        table = pq.read_table(os.path.join(season, "kpis.parquet"))
        d = table.to_pydict()
        message = change(season, d)
        out = pa.Table.from_pydict(d, schema=table.schema)
        pq.write_table(out.replace_schema_metadata(table.schema.metadata), os.path.join(copy, "kpis.parquet"))
        print(f"{name}: {message}")
