"""Golden values for the censored-normal (Tobit) fit in src/gap/stats.rs
(`CensoredNormal`), which imputes worn-through tires' wear on the log scale
(`--worn-through tobit`, docs/gap.md):

- the maximum-likelihood mean and standard deviation of right-censored
  normal samples, by scipy's own censored fit (`scipy.stats.norm.fit` on
  `scipy.stats.CensoredData`), refined by Nelder-Mead on the censored
  log-likelihood written out here (both must agree);
- E[X | X > c] by `scipy.stats.truncnorm.mean`;
- E[exp X | X > c] by numerical integration (`scipy.integrate.quad`).

Run: python tests/oracles/tobit_oracle.py > tests/golden/tobit.json
"""
import json

import numpy as np
from scipy import integrate, optimize, stats

rng = np.random.default_rng(14)


def negative_log_likelihood(theta, observed, bounds):
    mean, log_sd = theta
    sd = np.exp(log_sd)
    return -(
        stats.norm.logpdf(observed, mean, sd).sum()
        + stats.norm.logsf(bounds, mean, sd).sum()
    )


cases = []
for n, mean, sd, censor_share in [(400, 0.2, 0.3, 0.4), (150, -1.0, 2.0, 0.1), (60, 0.0, 1.0, 0.6)]:
    x = rng.normal(mean, sd, n)
    # Each value censored at a bound of its own, drawn so that about
    # `censor_share` of the values lie beyond theirs.
    bound = rng.normal(np.quantile(x, 1 - censor_share), sd / 2, n)
    censored = x > bound
    value = np.where(censored, bound, x)
    data = stats.CensoredData(uncensored=value[~censored], right=value[censored])
    m0, s0 = stats.norm.fit(data)
    fit = optimize.minimize(
        negative_log_likelihood,
        [m0, np.log(s0)],
        args=(value[~censored], value[censored]),
        method="Nelder-Mead",
        options={"xatol": 1e-12, "fatol": 1e-14, "maxiter": 20000},
    )
    m, s = fit.x[0], float(np.exp(fit.x[1]))
    assert abs(m - m0) < 1e-4 and abs(s - s0) < 1e-4, (m, m0, s, s0)
    at = [m - s, m, m + 0.5 * s, m + 2 * s, m + 5 * s]
    beyond = [float(stats.truncnorm.mean((c - m) / s, np.inf, loc=m, scale=s)) for c in at]
    exp_beyond = [
        integrate.quad(
            lambda t: np.exp(t + stats.norm.logpdf(t, m, s)),
            c,
            max(c, m + s * s) + 40 * s,
            epsabs=0,
            epsrel=1e-12,
            limit=200,
        )[0]
        / stats.norm.sf(c, m, s)
        for c in at
    ]
    cases.append(
        {
            "values": value.tolist(),
            "censored": censored.tolist(),
            "mean": float(m),
            "sd": s,
            "at": at,
            "mean_beyond": beyond,
            "mean_exp_beyond": exp_beyond,
        }
    )

print(json.dumps({"cases": cases}))
