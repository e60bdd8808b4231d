#!/usr/bin/env python3
"""Upper bound of an accelerometer-aided translation direction (session 42 study, not in the
pipeline; docs/scoreboard-history.md).

Reads `method_on_sim DIRVEC=1` dumps (lines `dirvec t0 t1 est x y z true vx vy vz w wx wy wz ...`:
estimated unit direction, true camera velocity in m/s and the slice's IMU rate in rad/s, camera
frame). For each slice k it fits the velocity v at the window's first slice from the last W
slices' estimated directions, with the velocity increments between slices given ("inertial"):
v_j = Phi_j v + c_j, Phi the rotation by the IMU rate, and reports the fused direction of slice
k (causal). The increments are the *true* ones (an oracle accelerometer with gravity removed
exactly), plus white noise (--noise, m/s per slice) and a constant acceleration error
(--bias, m/s^2, random direction per sequence). With --gravity unknown the increments are the
specific force's (acceleration minus a gravity of 9.81 m/s^2 in a random direction, rotated
with the camera), and gravity at the window's start is fitted too (--norm-weight > 0 adds the
constraint |g| = 9.81). The fit minimises the sine of the angle between each estimate and
v_j (iteratively reweighted, Huber at 0.1 rad).

  python3 inertial_window.py DUMP_DIR [--window 100] [--noise 0.001] [--bias 0.0]
      [--gravity known|unknown] [--norm-weight 0]
"""
import argparse
import glob
import os

import numpy as np


def skew(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def rotation(w, dt):
    th = np.linalg.norm(w) * dt
    if th < 1e-12:
        return np.eye(3)
    k = skew(w / np.linalg.norm(w))
    return np.eye(3) + np.sin(th) * k + (1 - np.cos(th)) * k @ k


def angle_deg(a, b):
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    return np.degrees(np.arccos(np.clip(a @ b, -1, 1)))


def read_dump(path):
    rows = []
    with open(path) as f:
        for line in f:
            p = line.split()
            if not p or p[0] != "dirvec":
                continue
            rows.append((float(p[1]), np.array(p[4:7], float), np.array(p[8:11], float),
                         np.array(p[12:15], float)))
    return rows


def fuse(rows, args, rng):
    n = len(rows)
    gravity = rng.normal(size=3)
    gravity *= 9.81 / np.linalg.norm(gravity)
    bias = rng.normal(size=3)
    bias *= args.bias / np.linalg.norm(bias)
    rot, inc, dts = [], [], []
    for k in range(n - 1):
        dt = rows[k + 1][0] - rows[k][0]
        r = rotation(rows[k][3], dt).T
        c = rows[k + 1][2] - r @ rows[k][2] + rng.normal(size=3) * args.noise + bias * dt
        if args.gravity == "unknown":
            c = c - gravity * dt
        rot.append(r)
        inc.append(c)
        dts.append(dt)
        gravity = r @ gravity
    unknowns = 6 if args.gravity == "unknown" else 3
    raw, fused = [], []
    for k in range(n):
        est, true = rows[k][1], rows[k][2]
        if not np.all(np.isfinite(est)) or np.linalg.norm(est) == 0:
            continue
        raw.append(angle_deg(est, true))
        lo = max(0, k - args.window + 1)
        phi, c, gam = np.eye(3), np.zeros(3), np.zeros((3, 3))
        terms = []
        for j in range(lo, k + 1):
            if j > lo:
                gam = rot[j - 1] @ gam + rot[j - 1] @ phi * dts[j - 1]
                phi = rot[j - 1] @ phi
                c = rot[j - 1] @ c + inc[j - 1]
            d = rows[j][1]
            if np.all(np.isfinite(d)) and np.linalg.norm(d) > 0:
                basis = np.hstack([phi, gam])[:, :unknowns]
                terms.append((basis, c.copy(), d / np.linalg.norm(d)))
        if len(terms) < unknowns:
            fused.append(raw[-1])
            continue
        w = np.ones(len(terms))
        x = None
        for _ in range(12):
            m = np.zeros((unknowns, unknowns))
            r = np.zeros(unknowns)
            for wi, (basis, cc, d) in zip(w, terms):
                a = skew(d) @ basis
                m += wi * a.T @ a
                r += wi * a.T @ (-skew(d) @ cc)
            if x is not None and args.gravity == "unknown" and args.norm_weight > 0:
                row = np.concatenate([np.zeros(3), x[3:] / (np.linalg.norm(x[3:]) + 1e-12)])
                s = args.norm_weight * w.mean() * len(terms)
                m += s * np.outer(row, row)
                r += s * row * 9.81
            x = np.linalg.solve(m + 1e-9 * np.eye(unknowns), r)
            for i, (basis, cc, d) in enumerate(terms):
                v = basis @ x + cc
                nv = np.linalg.norm(v) + 1e-9
                err = np.linalg.norm(np.cross(d, v)) / nv
                w[i] = min(1.0, 0.1 / max(err, 1e-9)) / nv**2
        basis, cc, _ = terms[-1]
        v = basis @ x + cc
        if v @ est < 0:
            v = -v
        fused.append(angle_deg(v, true))
    return np.median(raw), np.median(fused)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("dumps")
    ap.add_argument("--window", type=int, default=100)
    ap.add_argument("--noise", type=float, default=0.001)
    ap.add_argument("--bias", type=float, default=0.0)
    ap.add_argument("--gravity", choices=["known", "unknown"], default="known")
    ap.add_argument("--norm-weight", type=float, default=0.0)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    raws, fuseds = [], []
    for path in sorted(glob.glob(os.path.join(args.dumps, "*.txt"))):
        raw, fused = fuse(read_dump(path), args, rng)
        raws.append(raw)
        fuseds.append(fused)
        print(f"{os.path.basename(path):28s} median direction error {raw:6.2f} -> {fused:6.2f} deg")
    print(f"mean of the medians {np.mean(raws):.3f} -> {np.mean(fuseds):.3f} deg")


if __name__ == "__main__":
    main()
