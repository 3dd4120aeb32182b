"""Levenberg-Marquardt oracle: scipy.optimize.least_squares(method="lm")
(MINPACK) on an exponential-decay fit y = a·exp(−b·t) + c with fixed noisy
data. Writes the data, the start point and scipy's solution to
tests/golden/lm.json for the LM test in tests/oracle_models.rs.

    python3 tests/oracles/lm_oracle.py   # from the repository root
"""
import json
import pathlib

import numpy as np
from scipy.optimize import least_squares

ROOT = pathlib.Path(__file__).resolve().parents[2]


def main():
    rng = np.random.default_rng(42)
    t = np.linspace(0.0, 4.0, 40)
    y = 2.5 * np.exp(-1.3 * t) + 0.5 + 0.02 * rng.standard_normal(t.size)
    x0 = np.array([1.0, 0.5, 0.0])
    res = least_squares(lambda p: p[0] * np.exp(-p[1] * t) + p[2] - y, x0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    out = {"t": list(t), "y": list(y), "x0": list(x0), "solution": list(res.x), "cost": float(res.cost)}
    (ROOT / "tests" / "golden" / "lm.json").write_text(json.dumps(out, indent=1) + "\n")
    print("wrote tests/golden/lm.json", res.x, res.cost)


if __name__ == "__main__":
    main()
