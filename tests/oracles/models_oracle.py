"""Model oracles: statsmodels OLS (coefficients, standard errors, p-values,
R², adjusted R², and the prediction intervals of the front rows as new
observations of the rear fit, at 95 % and 80 %) and scikit-learn PCA (proportions, loadings) on a committed
table, tests/fixtures/model_table.csv (rear-axle and front rows of the demo
season's KPI database, written by `tirewear demo`).

    python3 tests/oracles/models_oracle.py   # from the repository root

Writes tests/golden/models.json for tests/oracle_models.rs.
"""
import json
import pathlib

import pandas as pd
import statsmodels.api as sm
from sklearn.decomposition import PCA
from sklearn.preprocessing import StandardScaler

ROOT = pathlib.Path(__file__).resolve().parents[2]
OLS_INPUTS = ["skewness", "kurtosis", "t_surface_avg_c", "friction_energy_j", "contact_patch_mm2", "loss_factor"]
PCA_INPUTS = ["fz_avg_n", "pressure_avg_pa", "sliding_distance_m", "t_inner_avg_c", "t_surface_avg_c",
              "friction_energy_j", "hurst", "skewness"]


def main():
    t = pd.read_csv(ROOT / "tests" / "fixtures" / "model_table.csv")
    rear = t[t["axle"] == "rear"]
    fit = sm.OLS(rear["wear_mean_pct"], sm.add_constant(rear[OLS_INPUTS])).fit()
    front = t[t["axle"] == "front"]
    intervals = {}
    for level in (0.95, 0.8):
        frame = fit.get_prediction(sm.add_constant(front[OLS_INPUTS])).summary_frame(alpha=1 - level)
        intervals[str(level)] = {
            "mean": list(frame["mean"]), "lower": list(frame["obs_ci_lower"]),
            "upper": list(frame["obs_ci_upper"]),
        }
    pca = PCA().fit(StandardScaler().fit_transform(t[PCA_INPUTS]))
    out = {
        "ols": {
            "inputs": OLS_INPUTS, "n": int(fit.nobs),
            "coef": list(fit.params), "std_err": list(fit.bse), "t_values": list(fit.tvalues),
            "p_values": list(fit.pvalues), "r2": fit.rsquared, "r2_adj": fit.rsquared_adj,
            "sigma2": fit.scale,
            "front_rows_intervals": intervals,
        },
        "pca": {
            "inputs": PCA_INPUTS, "proportions": list(pca.explained_variance_ratio_),
            "loadings": [list(c) for c in pca.components_],
        },
    }
    (ROOT / "tests" / "golden" / "models.json").write_text(json.dumps(out, indent=1) + "\n")
    print("wrote tests/golden/models.json")


if __name__ == "__main__":
    main()
