"""Golden values for the gap statistics (src/gap/stats.rs):
Benjamini-Hochberg adjusted p-values by statsmodels' multipletests(fdr_bh),
and Welch's t-test (difference, 95 % CI, p) by scipy's ttest_ind(equal_var=False).

Run: python tests/oracles/gap_oracle.py > tests/golden/gap_stats.json
"""
import json

import numpy as np
from scipy import stats
from statsmodels.stats.multitest import multipletests

rng = np.random.default_rng(11)
p = np.concatenate([rng.uniform(0, 1, 25), rng.uniform(0, 0.01, 5), [0.0, 1.0, 0.04, 0.04]])
_, p_adj, _, _ = multipletests(p, method="fdr_bh")

cases = []
for n_a, n_b, shift, scale_b in [(12, 40, 0.8, 1.0), (30, 31, -0.1, 3.0), (10, 300, 2.5, 0.5)]:
    a = rng.normal(shift, 1.0, n_a)
    b = rng.normal(0.0, scale_b, n_b)
    r = stats.ttest_ind(a, b, equal_var=False)
    ci = r.confidence_interval(0.95)
    cases.append(
        {
            "a": a.tolist(),
            "b": b.tolist(),
            "difference": float(a.mean() - b.mean()),
            "ci": [float(ci.low), float(ci.high)],
            "p": float(r.pvalue),
        }
    )

print(json.dumps({"p": p.tolist(), "p_bh": p_adj.tolist(), "welch": cases}, indent=1))
