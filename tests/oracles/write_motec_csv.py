#!/usr/bin/env python3
"""Writes tests/fixtures/import/python-motec.csv, a MoTeC CSV export in the
layout MoTeC i2 writes (header block of key/value pairs, channel names,
units, data in quoted cells), with iRacing/ACC-style spellings and non-SI
units (mph, rpm, degF, psi, rad/s, rad), and its golden
tests/golden/import-python-motec.json: every archive channel the importer
must produce, computed here from the formulas of docs/import.md ("Virtual
sensors"), independently of tirewear's Rust code.

Plain Python (csv, json, math): no package needed.
    python3 tests/oracles/write_motec_csv.py
"""
import csv
import json
import math

RATE = 25.0
N = 40
G = 9.80665

# The vehicle: datasets/import/car.toml.
CAR = dict(m=798.0, wf=0.445, h=0.30, L=3.60, tf=1.60, tr=1.55, brake_front=0.57,
           rsf=0.55, ratio=12.0, cla=3.2, cda=1.05, aero_front=0.42, rho=1.2,
           r0=[0.330, 0.335], k=600000.0, camber_static=[-3.2, -1.9],
           roll_grad=0.35, camber_per_roll=0.6)

CORNERS = ["LF", "RF", "LR", "RR"]          # iRacing's spelling; FL FR RL RR
SIDE = [1.0, -1.0, 1.0, -1.0]               # left +y
AXLE = [0, 0, 1, 1]


def row(i):
    t = i / RATE
    mph = 90.0 + 10.0 * math.sin(0.3 * t)
    g_lat = 1.6 * math.sin(0.5 * t)
    g_long = -0.8 + 0.05 * i
    yaw = 0.35 * math.sin(0.5 * t)               # rad/s
    slip = 0.01 * math.cos(0.4 * t)              # rad
    steer_sw = 40.0 * math.sin(0.5 * t)          # deg at the steering wheel
    rpm = [1250.0 + 3.0 * i + 5.0 * k for k in range(4)]
    temps_f = [[180.0 + k + z + 0.1 * i for z in (0.0, 2.0, 4.0)] for k in range(4)]
    psi = [26.0 + 0.01 * i + 0.1 * k for k in range(4)]
    return dict(t=t, mph=mph, g_lat=g_lat, g_long=g_long, yaw=yaw, slip=slip,
                steer_sw=steer_sw, rpm=rpm, temps_f=temps_f, psi=psi,
                air_f=68.0, track_f=95.0 + 0.05 * i)


def golden(r):
    c = CAR
    v = r["mph"] * 1609.344 / 3600.0
    ax, ay, yaw = r["g_long"] * G, r["g_lat"] * G, r["yaw"]
    df = 0.5 * c["rho"] * c["cla"] * v * v
    drag = 0.5 * c["rho"] * c["cda"] * v * v
    long = c["m"] * ax * c["h"] / c["L"]
    axle = [c["m"] * G * c["wf"] + df * c["aero_front"] - long,
            c["m"] * G * (1 - c["wf"]) + df * (1 - c["aero_front"]) + long]
    share = [c["rsf"], 1 - c["rsf"]]
    tw = [c["tf"], c["tr"]]
    fz = [max(0.5 * axle[AXLE[k]] - SIDE[k] * share[AXLE[k]] * c["m"] * ay * c["h"] / tw[AXLE[k]], 50.0)
          for k in range(4)]
    fx_total = c["m"] * ax + drag
    axle_fx = [0.0, fx_total] if fx_total >= 0 else [fx_total * c["brake_front"], fx_total * (1 - c["brake_front"])]
    axle_fy = [c["m"] * ay * c["wf"], c["m"] * ay * (1 - c["wf"])]
    a, b = c["L"] * (1 - c["wf"]), c["L"] * c["wf"]
    tb = math.tan(r["slip"])
    td = math.tan(math.radians(r["steer_sw"] / c["ratio"]))
    vv = max(v, 1.0)
    s_axle = [tb + a * yaw / vv - td, tb - b * yaw / vv]
    out = []
    for k in range(4):
        ai = AXLE[k]
        pair = fz[0] + fz[1] if ai == 0 else fz[2] + fz[3]
        vx = max(v - yaw * SIDE[k] * 0.5 * tw[ai], 0.5)
        roll = c["roll_grad"] * ay / G
        out.append(dict(
            vx_mps=vx,
            vy_mps=s_axle[ai] * vx,
            omega_radps=r["rpm"][k] * 2 * math.pi / 60,
            rolling_radius_m=c["r0"][ai] - fz[k] / c["k"],
            fx_n=axle_fx[ai] * fz[k] / pair,
            fy_n=axle_fy[ai] * fz[k] / pair,
            fz_n=fz[k],
            t_surface_c=(sum(r["temps_f"][k]) / 3 - 32) * 5 / 9,
            # No TPMS gas temperature in this log: the surface temperature.
            t_inner_c=(sum(r["temps_f"][k]) / 3 - 32) * 5 / 9,
            pressure_pa=r["psi"][k] * 6894.757293168,
            camber_deg=c["camber_static"][ai] - SIDE[k] * c["camber_per_roll"] * roll,
        ))
    veh = dict(speed_mps=v, t_air_c=(r["air_f"] - 32) * 5 / 9, t_track_c=(r["track_f"] - 32) * 5 / 9)
    return dict(wheels=out, vehicle=veh)


def main():
    rows = [row(i) for i in range(N)]
    names = ["Time", "Speed", "G Lat", "G Long", "Yaw Rate", "Body Slip Angle", "Steering Wheel Angle"]
    units = ["s", "mph", "G", "G", "rad/s", "rad", "deg"]
    for k, c in enumerate(CORNERS):
        names += [f"wheel_speed_{c.lower()}", f"{c}tempCL", f"{c}tempCM", f"{c}tempCR", f"{c}pressure"]
        units += ["rpm", "F", "F", "F", "psi"]
    names += ["Air Temp", "Track Temp", "Engine RPM"]
    units += ["F", "F", "rpm"]
    with open("tests/fixtures/import/python-motec.csv", "w", newline="") as f:
        w = csv.writer(f, quoting=csv.QUOTE_ALL, lineterminator="\n")
        w.writerow(["Format", "MoTeC CSV File", "", "", "Workbook", "Untitled"])
        w.writerow(["Venue", "Valle Rossa", "", "", "Worksheet", "Tyres"])
        w.writerow(["Vehicle", "car1", "", "", "Vehicle Desc", ""])
        w.writerow(["Driver", "Python", "", "", "Engine ID", ""])
        w.writerow(["Device", "", "", "", "Date", "05/04/2026"])
        w.writerow(["Comment", "independent writer", "", "", "Time", "2:30:00 PM"])
        w.writerow(["Log Date", "05/04/2026", "", "", "Origin Time", "0.000", "s"])
        w.writerow(["Log Time", "2:30:00 PM", "", "", "Start Time", "0.000", "s"])
        w.writerow(["Sample Rate", f"{RATE:.3f}", "Hz", "", "End Time", f"{(N - 1) / RATE:.3f}", "s"])
        w.writerow(["Duration", f"{(N - 1) / RATE:.3f}", "s", "", "Start Distance", "0", "m"])
        w.writerow(["Range", "entire outing", "", "", "End Distance", "0", "m"])
        w.writerow(["Beacon Markers", ""])
        w.writerow([])
        w.writerow([])
        w.writerow(names)
        w.writerow(units)
        w.writerow([])
        w.writerow([])
        for r in rows:
            cells = [f"{r['t']:.3f}", repr(r["mph"]), repr(r["g_lat"]), repr(r["g_long"]), repr(r["yaw"]),
                     repr(r["slip"]), repr(r["steer_sw"])]
            for k in range(4):
                cells += [repr(r["rpm"][k])] + [repr(x) for x in r["temps_f"][k]] + [repr(r["psi"][k])]
            cells += [repr(r["air_f"]), repr(r["track_f"]), "7000"]
            w.writerow(cells)
    gold = [golden(r) for r in rows]
    # Distance: the trapezoidal integral of speed from the first sample.
    d = 0.0
    for i, g in enumerate(gold):
        if i:
            d += 0.5 * (g["vehicle"]["speed_mps"] + gold[i - 1]["vehicle"]["speed_mps"]) / RATE
        g["vehicle"]["distance_m"] = d
    with open("tests/golden/import-python-motec.json", "w") as f:
        json.dump(dict(rate_hz=RATE, start_unix_s=1775399400, samples=gold), f, indent=1)


if __name__ == "__main__":
    main()
