"""Independent writer: Python `mcap-protobuf-support` writes telemetry files
with tirewear's schemas compiled by protoc (grpcio-tools), not by our build.
Values follow closed forms that tests/oracle_mcap.rs recomputes, so the test
checks every sample our reader returns.

    python3 tests/oracles/write_python_mcap.py   # from the repository root

Writes tests/fixtures/python-sample.mcap (per-sample messages, a dropout
between samples 20 and 25) and tests/fixtures/python-block.mcap (two blocks),
and the telemetry and Parquet road file of datasets/handwritten/.
"""
import importlib
import pathlib
import shutil
import subprocess
import sys
import tempfile

from mcap_protobuf.writer import Writer

ROOT = pathlib.Path(__file__).resolve().parents[2]
N = 40
T0 = 1_772_000_000_000_000_000
PERIOD = 10_000_000  # 100 Hz
WHEELS = ["FL", "FR", "RL", "RR"]


def tire_values(w, i):
    """Closed form of sample i of wheel index w (kept in sync with tests/oracle_mcap.rs)."""
    return dict(vx_mps=50.0 + 0.25 * i + w, vy_mps=-0.5 + 0.01 * i, omega_radps=150.0 + 0.5 * i,
                rolling_radius_m=0.33, fx_n=1000.0 - 25.0 * i, fy_n=2000.0 + 10.0 * w,
                fz_n=4000.0 + 100.0 * w, t_surface_c=60.0 + 0.125 * i, t_inner_c=100.0 + 0.5 * w,
                pressure_pa=130000.0 + i, camber_deg=-3.0 + 0.25 * w)


def vehicle_values(i):
    return dict(speed_mps=50.0 + 0.25 * i, t_track_c=35.5, t_air_c=22.25, distance_m=0.5 * i)


def main():
    out = pathlib.Path(tempfile.mkdtemp())
    subprocess.run([sys.executable, "-m", "grpc_tools.protoc", f"-I{ROOT / 'proto'}",
                    f"--python_out={out}", "tirewear.proto"], check=True)
    sys.path.insert(0, str(out))
    pb = importlib.import_module("tirewear_pb2")

    kept = [i for i in range(N) if not 20 <= i < 25]
    with open(ROOT / "tests" / "fixtures" / "python-sample.mcap", "wb") as f, Writer(f) as w:
        for i in kept:
            t = T0 + i * PERIOD
            for k, wheel in enumerate(WHEELS):
                w.write_message(topic=f"/tire/{wheel}", message=pb.TireSample(**tire_values(k, i)),
                                log_time=t, publish_time=t)
            w.write_message(topic="/vehicle", message=pb.VehicleSample(**vehicle_values(i)),
                            log_time=t, publish_time=t)
    with open(ROOT / "tests" / "fixtures" / "python-block.mcap", "wb") as f, Writer(f) as w:
        for start, stop in [(0, 20), (25, N)]:
            t = T0 + start * PERIOD
            for k, wheel in enumerate(WHEELS):
                block = pb.TireBlock(start_time_ns=t, sample_period_ns=PERIOD)
                for i in range(start, stop):
                    for name, v in tire_values(k, i).items():
                        getattr(block, name).append(v)
                w.write_message(topic=f"/tire/{wheel}", message=block, log_time=t, publish_time=t)
            vb = pb.VehicleBlock(start_time_ns=t, sample_period_ns=PERIOD)
            for i in range(start, stop):
                for name, v in vehicle_values(i).items():
                    getattr(vb, name).append(v)
            w.write_message(topic="/vehicle", message=vb, log_time=t, publish_time=t)
    # The hand-written example archive uses the per-sample file as its run's telemetry.
    shutil.copyfile(ROOT / "tests" / "fixtures" / "python-sample.mcap",
                    ROOT / "datasets" / "handwritten" / "telemetry" / "H1-car1-R1.mcap")
    # ... and pyarrow for its bulk road file: two profiles, z = 0.1*sin + 0.05*location (mm).
    import math
    import pyarrow as pa
    import pyarrow.parquet as pq
    rows = {"track": [], "location": [], "x_mm": [], "z_mm": []}
    for loc in (1, 2):
        for i in range(32):
            rows["track"].append("paper-ring")
            rows["location"].append(f"L{loc}")
            rows["x_mm"].append(i * 0.25)
            rows["z_mm"].append(0.1 * math.sin(0.5 * i) + 0.05 * loc)
    pq.write_table(pa.table(rows), ROOT / "datasets" / "handwritten" / "road" / "profiles.parquet")
    print("wrote tests/fixtures/python-*.mcap and datasets/handwritten/{telemetry,road}")


if __name__ == "__main__":
    main()
