"""Road-roughness oracle: surfalize (Ra, Rq, Rsk, Rku and the ISO 16610-21
Gaussian macro/micro split) and scipy (Welch PSD), numpy for λa, the HDC and
the Hurst fit under tirewear's documented definitions (docs/kpis.md).

    python3 tests/oracles/road_oracle.py   # from the repository root

Reads the profile CSVs listed below and writes tests/golden/road.json, which
tests/oracle_kpi.rs compares with tirewear's CPU engine.
"""
import json
import pathlib

import numpy as np
import scipy.signal
from surfalize import Profile

ROOT = pathlib.Path(__file__).resolve().parents[2]
PROFILES = [
    "tests/fixtures/valle-rossa-L2.csv",      # written by `tirewear simulate --preset tiny --seed 3`
    "tests/fixtures/nordkamm-L2.csv",
    "datasets/handwritten/road/paper-ring-L3.csv",  # a hand-made sine
]
CUTOFF_MM = 0.5
WELCH_SEGMENT = 4096
HDC_LAGS = 48
HURST_BAND_MM = (0.1, 5.0)


def average_wavelength(z, dx):
    ra = np.mean(np.abs(z - z.mean()))
    delta_a = np.mean(np.abs(np.diff(z))) / dx
    return 2 * np.pi * ra / delta_a


def log_bin(q, c, bins):
    lo, hi = np.log(q[0]), np.log(q[-1])
    b = np.minimum(((np.log(q) - lo) / (hi - lo) * bins).astype(int), bins - 1)
    bq, bc = [], []
    for k in range(bins):
        m = b == k
        if m.any():
            bq.append(np.exp(np.mean(np.log(q[m]))))
            bc.append(np.mean(c[m]))
    return np.array(bq), np.array(bc)


def slope(x, y, lo, hi):
    m = (x >= lo) & (x <= hi) & (y > 0)
    return np.polyfit(np.log(x[m]), np.log(y[m]), 1)[0]


def oracle(path):
    data = np.loadtxt(ROOT / path, delimiter=",", skiprows=1)
    x, z = data[:, 0], data[:, 1]
    dx = (x[-1] - x[0]) / (len(x) - 1)
    p = Profile(z, dx * 1000.0)  # surfalize works in µm
    high, low = p.filter("both", CUTOFF_MM * 1000.0)
    zl, zh = low.data, high.data
    # PSD, SurfaceTopography convention: C(q) = G(f)/2 with q = 2πf (domain notes).
    nseg = min(WELCH_SEGMENT, len(z))
    f, g = scipy.signal.welch(z, fs=1.0 / dx, window="hann", nperseg=nseg, noverlap=nseg // 2,
                              detrend="constant", scaling="density")
    q, c = 2 * np.pi * f[1:-1], g[1:-1] / 2.0
    bq, bc = log_bin(q, c, 64)
    hurst = (-slope(bq, bc, 2 * np.pi / HURST_BAND_MM[1], 2 * np.pi / HURST_BAND_MM[0]) - 1) / 2
    max_lag = max(len(z) // 4, 2)
    lags = sorted(set(int(np.floor(max_lag ** (i / (HDC_LAGS - 1)) + 0.5)) for i in range(HDC_LAGS)))
    hdc = np.array([np.mean((z[k:] - z[:-k]) ** 2) for k in lags])
    lag_mm = np.array(lags) * dx
    hurst_hdc = slope(lag_mm, hdc, HURST_BAND_MM[0] / 10, HURST_BAND_MM[1] / 10) / 2
    return {
        "ra_mm": p.Ra(), "rq_mm": p.Rq(), "skewness": p.Rsk(), "kurtosis": p.Rku(),
        "ra_macro_mm": low.Ra(), "ra_micro_mm": high.Ra(),
        "macro_wavelength_mm": average_wavelength(zl, dx), "micro_wavelength_mm": average_wavelength(zh, dx),
        "peakyness_mm": np.sqrt(2) * p.Rq(), "hurst": hurst, "hurst_hdc": hurst_hdc,
        "lowpass_first": list(zl[:5]), "lowpass_mid": float(zl[len(zl) // 2]),
        "psd_q": list(q[::37]), "psd_c": list(c[::37]), "hdc_lag_mm": list(lag_mm), "hdc": list(hdc),
    }


def main():
    out = {p: {k: (float(v) if not isinstance(v, list) else [float(a) for a in v]) for k, v in oracle(p).items()}
           for p in PROFILES}
    (ROOT / "tests" / "golden" / "road.json").write_text(json.dumps(out, indent=1) + "\n")
    print("wrote tests/golden/road.json")


if __name__ == "__main__":
    main()
