"""Golden values for the gap statistics (src/gap/stats.rs):
Benjamini-Hochberg adjusted p-values by statsmodels' multipletests(fdr_bh),
and the event-clustered slice test (src/gap/stats.rs: clustered_difference):
the mean squares within and between events from statsmodels' one-way ANOVA
(anova_lm of OLS r ~ C(event)), the variance of the difference of means under
a random intercept per event written out here, and scipy's Student t.

Run: python tests/oracles/gap_oracle.py > tests/golden/gap_stats.json
"""
import json

import numpy as np
import pandas as pd
import statsmodels.formula.api as smf
from scipy import stats
from statsmodels.stats.anova import anova_lm
from statsmodels.stats.multitest import multipletests

rng = np.random.default_rng(11)
p = np.concatenate([rng.uniform(0, 1, 25), rng.uniform(0, 0.01, 5), [0.0, 1.0, 0.04, 0.04]])
_, p_adj, _, _ = multipletests(p, method="fdr_bh")



def clustered(r, event, inside):
    df = pd.DataFrame({"r": r, "event": event})
    table = anova_lm(smf.ols("r ~ C(event)", df).fit())
    msb, msw = table["mean_sq"].iloc[0], table["mean_sq"].iloc[1]
    df_b, df_w = table["df"].iloc[0], table["df"].iloc[1]
    n = len(r)
    sizes = np.bincount(event)
    sizes = sizes[sizes > 0]
    n0 = (n - (sizes**2).sum() / n) / (len(sizes) - 1)
    between = max(0.0, (msb - msw) / n0)
    na, nb = inside.sum(), (~inside).sum()
    d = r[inside].mean() - r[~inside].mean()
    wa = np.bincount(event[inside], minlength=sizes.size) / na
    wb = np.bincount(event[~inside], minlength=sizes.size) / nb
    a = msw * (1 / na + 1 / nb)
    b = between * ((wa - wb) ** 2).sum()
    var = a + b
    nu = var**2 / (a**2 / df_w + b**2 / df_b)
    se = np.sqrt(var)
    p = 2 * stats.t.sf(abs(d) / se, nu)
    q = stats.t.ppf(0.975, nu)
    return d, [d - q * se, d + q * se], p


cases = []
for n_events, per, sd_event, shift in [(6, 12, 1.0, 0.8), (10, 8, 0.3, 0.0), (4, 30, 2.0, 1.5)]:
    event = np.repeat(np.arange(n_events), per)
    r = rng.normal(0, sd_event, n_events)[event] + rng.normal(0, 1.0, event.size)
    # Slice: a third of the tires of most events, plus all of event 0.
    inside = (rng.uniform(size=event.size) < 0.33) | (event == 0)
    r = r + shift * inside
    d, ci, p_slice = clustered(r, event, inside)
    cases.append(
        {
            "r": r.tolist(),
            "event": event.tolist(),
            "inside": inside.tolist(),
            "difference": float(d),
            "ci": [float(ci[0]), float(ci[1])],
            "p": float(p_slice),
        }
    )

print(json.dumps({"p": p.tolist(), "p_bh": p_adj.tolist(), "clustered": cases}, indent=1))
