"""Independent reader: Python `mcap` + `mcap-protobuf-support` decode telemetry
files that tirewear wrote (schemas come from the files' own FileDescriptorSet
records), and numpy computes per-channel statistics and the friction energy.

Produces tests/golden/<fixture>.json for tests/oracle_mcap.rs.

    python3 tests/oracles/read_our_mcap.py   # from the repository root

The fixtures themselves were written by tirewear (see make_fixtures.sh).
"""
import json
import pathlib

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

ROOT = pathlib.Path(__file__).resolve().parents[2]
TIRE_FIELDS = ["vx_mps", "vy_mps", "omega_radps", "rolling_radius_m", "fx_n", "fy_n", "fz_n",
               "t_surface_c", "t_inner_c", "pressure_pa", "camber_deg"]
VEHICLE_FIELDS = ["speed_mps", "t_track_c", "t_air_c", "distance_m"]


def read(path):
    series = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, msg in reader.iter_decoded_messages():
            fields = TIRE_FIELDS if channel.topic.startswith("/tire/") else VEHICLE_FIELDS
            s = series.setdefault(channel.topic, {"time_ns": [], **{k: [] for k in fields}})
            if schema.name.endswith("Block"):
                n = len(getattr(msg, fields[0]))
                s["time_ns"].extend(msg.start_time_ns + i * msg.sample_period_ns for i in range(n))
                for k in fields:
                    vals = list(getattr(msg, k))
                    assert len(vals) == n, (path, channel.topic, k)
                    s[k].extend(vals)
            else:
                s["time_ns"].append(message.log_time)
                for k in fields:
                    s[k].append(getattr(msg, k))
    return series


def stats(series):
    out = {}
    for topic, s in sorted(series.items()):
        t = np.array(s["time_ns"], dtype=np.int64)
        entry = {"count": int(t.size), "first_time_ns": int(t[0]), "last_time_ns": int(t[-1])}
        for k, v in s.items():
            if k == "time_ns":
                continue
            a = np.array(v, dtype=np.float64)  # f32 values widened exactly
            entry[k] = {"sum": float(a.sum()), "min": float(a.min()), "max": float(a.max()),
                        "first": float(a[0]), "last": float(a[-1])}
        if topic.startswith("/tire/"):
            # Friction energy by paper eqs. 19-25 with the dissipation sign
            # (ISO axes: friction opposes sliding): P = -(Fx (vx - Omega R) + Fy vy),
            # integrated with the time step to the next sample (gaps excluded).
            vsx = np.array(s["vx_mps"], float) - np.array(s["omega_radps"], float) * np.array(s["rolling_radius_m"], float)
            p = -(np.array(s["fx_n"], float) * vsx + np.array(s["fy_n"], float) * np.array(s["vy_mps"], float))
            dt = np.diff(t) / 1e9
            period = np.median(dt)
            ok = np.isclose(dt, period)
            entry["friction_energy_j"] = float(np.sum(p[:-1][ok] * dt[ok]))
            entry["table4"] = table4(s)
        out[topic] = entry
    return out


def table4(s):
    """Table-4 KPIs of one wheel under docs/kpis.md's cleaning rule: each sample
    stands for the time to the next one; a gap over 0.5 s (a dropout) counts
    one nominal period (the median step). Standard deviations are 1/N."""
    t = np.array(s["time_ns"], dtype=np.int64)
    assert np.all(np.diff(t) > 0), "fixture has no out-of-order samples"
    steps = np.diff(t) / 1e9
    period = np.median(steps)
    dt = np.append(steps, period)
    dt = np.where(dt > 0.5, period, dt)
    a = {k: np.array(v, dtype=np.float64) for k, v in s.items() if k != "time_ns"}
    vsx = a["vx_mps"] - a["omega_radps"] * a["rolling_radius_m"]
    vsy = a["vy_mps"]
    px, py = -a["fx_n"] * vsx, -a["fy_n"] * vsy
    out = {}
    for name, v in [("t_surface", a["t_surface_c"]), ("t_inner", a["t_inner_c"]), ("fx", a["fx_n"]),
                    ("fy", a["fy_n"]), ("fz", a["fz_n"]), ("vsx", np.abs(vsx)), ("vsy", np.abs(vsy))]:
        out[name + "_avg"] = float(v.mean())
        out[name + "_std"] = float(v.std(ddof=0))
    out["friction_energy_x_j"] = float(np.sum(px * dt))
    out["friction_energy_y_j"] = float(np.sum(py * dt))
    out["sliding_distance_m"] = float(np.sum(np.hypot(vsx, vsy) * dt))
    out["duration_s"] = float(dt.sum())
    out["camber_avg_deg"] = float(a["camber_deg"].mean())
    out["pressure_avg_pa"] = float(a["pressure_pa"].mean())
    out["contact_patch_mm2"] = float(np.mean(a["fz_n"] / (a["pressure_pa"] + 40000.0) * 1e6))
    out["pair_maps"] = pair_maps(a, vsx, vsy, (px + py) * dt)
    return out


# The pair maps of docs/kpis.md ("Pair maps"), transcribed from the docs:
# each condition's formula and its coarse bins (lo, width, 8 bins, clamped at
# both ends, NaN to the first), binned in float32 as the docs say.
COARSE = {
    "slip_ratio": (-0.06, 0.015), "lateral_slip": (-0.06, 0.015), "combined_slip": (0.02, 0.01),
    "sliding_speed_mps": (1.0, 0.5), "friction_utilisation": (1.0, 0.1), "t_surface_c": (45.0, 5.0),
    "t_bulk_c": (65.0, 5.0), "relative_load": (0.5, 0.2), "camber_deg": (-4.0, 0.5),
    "speed_mps": (24.0, 8.0),
}
PAIRS = [("combined_slip", "t_surface_c"), ("combined_slip", "t_bulk_c"),
         ("sliding_speed_mps", "t_surface_c"), ("friction_utilisation", "t_surface_c"),
         ("combined_slip", "relative_load"), ("slip_ratio", "relative_load"),
         ("lateral_slip", "camber_deg"), ("combined_slip", "speed_mps")]


def coarse_bin(x, name):
    lo, width = COARSE[name]
    i = (x.astype(np.float32) - np.float32(lo)) * np.float32(1.0 / width)
    i = np.where(np.isnan(i), 0.0, np.floor(i))
    return np.clip(i, 0, 7).astype(int)


def pair_maps(a, vsx, vsy, energy_j):
    v_ref = np.maximum(np.abs(a["vx_mps"]), 1.0)
    v_s = np.sqrt(vsx * vsx + vsy * vsy)
    mean_fz = max(a["fz_n"].mean(), 100.0)
    cond = {
        "slip_ratio": -vsx / v_ref,
        "lateral_slip": vsy / v_ref,
        "combined_slip": v_s / v_ref,
        "sliding_speed_mps": v_s,
        "friction_utilisation": np.hypot(a["fx_n"], a["fy_n"]) / np.maximum(a["fz_n"], 100.0),
        "t_surface_c": a["t_surface_c"],
        "t_bulk_c": 0.5 * (a["t_surface_c"] + a["t_inner_c"]),
        # Stored as float32 by the host before binning (docs/kpis.md).
        "relative_load": (a["fz_n"] / mean_fz).astype(np.float32).astype(np.float64),
        "camber_deg": a["camber_deg"],
        "speed_mps": a["vx_mps"],
    }
    out = {}
    for first, second in PAIRS:
        cell = coarse_bin(cond[first], first) * 8 + coarse_bin(cond[second], second)
        out[f"{first}:{second}"] = np.bincount(cell, weights=energy_j, minlength=64).tolist()
    return out


def main():
    for name in ["tiny-sample", "tiny-block"]:
        path = ROOT / "tests" / "fixtures" / f"{name}.mcap"
        golden = ROOT / "tests" / "golden" / f"{name}.json"
        golden.write_text(json.dumps(stats(read(path)), indent=1, sort_keys=True) + "\n")
        print("wrote", golden)


if __name__ == "__main__":
    main()
