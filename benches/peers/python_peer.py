"""The Python peer of `tirewear extract`: what a user would write with the
official readers (`mcap` + `mcap-protobuf-support`, schemas taken from the
files themselves) and numpy, reducing each wheel of each run to its friction
energy (total, longitudinal, lateral; J), sliding distance (m) and the mean
and standard deviation of every channel.

    python3 benches/peers/python_peer.py SEASON [--jobs N] [--out peer.json]

SEASON is a season archive folder (season.toml, telemetry/*.mcap). Prints the
wall time in seconds on its last line ("seconds: X"); benches/peers/run.sh
compares it with tirewear in the same run. Not needed by CI or the tests.

Friction power as in docs/kpis.md (ISO axes, friction opposes sliding):
P = -(Fx (vx - omega R) + Fy vy); each sample stands for the time to the next
one, the last for the median step.
"""
import argparse
import json
import multiprocessing
import pathlib
import sys
import time
import tomllib

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

TIRE = ["vx_mps", "vy_mps", "omega_radps", "rolling_radius_m", "fx_n", "fy_n", "fz_n",
        "t_surface_c", "t_inner_c", "pressure_pa", "camber_deg"]


def read_run(path):
    """Every wheel topic's channels as numpy arrays, in file order. Values
    are gathered in Python lists and converted once per channel: the fastest
    of the plain routes (np.asarray or np.fromiter per block is slower on
    protobuf's repeated fields)."""
    parts = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, msg in reader.iter_decoded_messages():
            if not channel.topic.startswith("/tire/"):
                continue
            p = parts.setdefault(channel.topic, {"time_ns": [], **{k: [] for k in TIRE}})
            if schema.name.endswith("Block"):
                n = len(msg.vx_mps)
                p["time_ns"].append((msg.start_time_ns, msg.sample_period_ns, n))
                for k in TIRE:
                    p[k].extend(getattr(msg, k))
            else:
                p["time_ns"].append((message.log_time, 0, 1))
                for k in TIRE:
                    p[k].append(getattr(msg, k))
    out = {}
    for topic, p in parts.items():
        times = [start + period * np.arange(n, dtype=np.uint64) for start, period, n in p["time_ns"]]
        s = {"time_ns": np.concatenate(times)}
        s.update({k: np.array(p[k], dtype=np.float32) for k in TIRE})
        out[topic] = s
    return out


def reduce_wheel(s):
    t = s["time_ns"].astype(np.float64) / 1e9
    steps = np.diff(t)
    dt = np.append(steps, np.median(steps) if steps.size else 0.0)
    f = {k: s[k].astype(np.float64) for k in TIRE}
    vsx = f["vx_mps"] - f["omega_radps"] * f["rolling_radius_m"]
    vsy = f["vy_mps"]
    px = -f["fx_n"] * vsx
    py = -f["fy_n"] * vsy
    out = {
        "samples": int(t.size),
        "friction_energy_j": float(np.sum((px + py) * dt)),
        "friction_energy_x_j": float(np.sum(px * dt)),
        "friction_energy_y_j": float(np.sum(py * dt)),
        "sliding_distance_m": float(np.sum(np.hypot(vsx, vsy) * dt)),
    }
    for k in TIRE:
        out[k] = {"mean": float(f[k].mean()), "std": float(f[k].std())}
    return out


def one_run(path):
    return str(path), {topic: reduce_wheel(s) for topic, s in sorted(read_run(path).items())}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("season", type=pathlib.Path)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", type=pathlib.Path)
    a = ap.parse_args()
    manifest = tomllib.loads((a.season / "season.toml").read_text())
    files = [a.season / r["telemetry"] for r in manifest["runs"]]
    start = time.perf_counter()
    if a.jobs > 1:
        with multiprocessing.Pool(a.jobs) as pool:
            results = dict(pool.map(one_run, files))
    else:
        results = dict(map(one_run, files))
    seconds = time.perf_counter() - start
    if a.out:
        a.out.write_text(json.dumps(results, indent=1))
    samples = sum(w["samples"] for r in results.values() for w in r.values())
    print(f"{len(files)} runs, {samples} wheel samples", file=sys.stderr)
    print(f"seconds: {seconds:.3f}")


if __name__ == "__main__":
    main()
