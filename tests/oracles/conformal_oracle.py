"""Split-conformal oracle: the half-width of the network's prediction
interval (src/model/interval.rs, `conformal_half_width`) as numpy computes
the split-conformal quantile (Lei et al. 2018): of n calibration scores
|y − ŷ|, np.quantile at ⌈(n + 1)·level⌉ / n with method="inverted_cdf"
(the smallest score whose empirical CDF reaches that share), the rank
taken exactly with fractions; null where the rank exceeds n (too few
scores for the level).

    python3 tests/oracles/conformal_oracle.py   # from the repository root

Writes tests/golden/conformal.json for tests/oracle_models.rs.
"""
import json
import math
import pathlib
from fractions import Fraction

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
LEVELS = ["0.28", "0.5", "0.8", "0.9", "0.95", "0.99"]
COUNTS = [1, 12, 18, 19, 24, 45, 100, 250]


def main():
    rng = np.random.default_rng(20261203)
    cases = []
    for n in COUNTS:
        # |N(0, 3)| errors in % of the tread, with ties (rounded to 0.01).
        scores = np.round(np.abs(rng.normal(0.0, 3.0, n)), 2)
        for level in LEVELS:
            rank = math.ceil((n + 1) * Fraction(level))
            half = None
            if rank <= n:
                half = float(np.quantile(scores, Fraction(rank, n).__float__(), method="inverted_cdf"))
            cases.append({"scores": [float(s) for s in scores], "level": float(level), "half_width": half})
    out = ROOT / "tests" / "golden" / "conformal.json"
    out.write_text(json.dumps({"numpy": np.__version__, "cases": cases}, indent=1) + "\n")
    print(f"wrote {out}: {len(cases)} cases")


if __name__ == "__main__":
    main()
