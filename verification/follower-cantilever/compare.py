#!/usr/bin/env python3
"""The follower-loaded cantilever against the nonconservative elastica.

The inextensible elastica clamped at s = 0 under an end force P that stays normal to the end
(angle theta_L): theta'' = -k cos(theta - theta_L) on s in [0, 1] (lengths over L,
k = P L^2 / EI), theta(0) = 0, theta'(1) = 0. Solved by shooting on theta_L (secant iterations
continued from the previous level; RK4 with 2000 steps, the end's displacement by the
trapezoid rule on the same steps). The end's displacement is L (U(k), W(k)),
U = int cos(theta) ds - 1, W = int sin(theta) ds.

With a force c per unit width on a strip of width b: k = 12 c L^2 / (E t^3), independent of b,
so dw/db = 0, dw/dL = W + 2 k W'(k), dw/dt = -3 k W'(k) L / t (and the same for u).

Usage: compare.py RESULTS.json [SENSITIVITY.json]
"""

import json
import math
import sys
import tomllib
from pathlib import Path

N = 2000


def shoot(k, theta_l):
    """theta(0), U, W for the end angle theta_l (integrating from the end s = 1 to 0)."""
    h = -1.0 / N
    th, dth, w, x = theta_l, 0.0, 0.0, 0.0

    def f(a, b):
        return b, -k * math.cos(a - theta_l)

    for _ in range(N):
        k1 = f(th, dth)
        k2 = f(th + h / 2 * k1[0], dth + h / 2 * k1[1])
        k3 = f(th + h / 2 * k2[0], dth + h / 2 * k2[1])
        k4 = f(th + h * k3[0], dth + h * k3[1])
        th1 = th + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        dth1 = dth + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        w -= h * (math.sin(th) + math.sin(th1)) / 2
        x -= h * (math.cos(th) + math.cos(th1)) / 2
        th, dth = th1, dth1
    return th, x - 1.0, w


def end_angle(k, guess):
    """theta_L with theta(0) = 0 by secant iterations from `guess`."""
    a, b = guess, guess + 1e-3
    fa, fb = shoot(k, a)[0], shoot(k, b)[0]
    for _ in range(50):
        if fb == fa:
            break
        a, b, fa = b, b - fb * (b - a) / (fb - fa), fb
        fb = shoot(k, b)[0]
        if abs(fb) < 1e-13:
            break
    if abs(fb) > 1e-10:
        sys.exit(f"shooting did not converge at k = {k} (theta(0) = {fb:.3e})")
    return b


class Elastica:
    """U(k), W(k) along the load path, continued from k = 0."""

    def __init__(self):
        self.last = (0.0, 0.0)

    def at(self, k):
        k0, th0 = self.last
        # First-order guess from the last level (theta_L ~ k/2 near k = 0).
        guess = th0 + (k - k0) * (0.5 if k0 == 0.0 else th0 / k0)
        th = end_angle(k, guess)
        self.last = (k, th)
        _, u, w = shoot(k, th)
        return th, u, w

    def derivative(self, k, theta_l):
        """(U'(k), W'(k)) by central differences (dk = 1e-5 k), each side solved anew."""
        dk = 1e-5 * k
        _, up, wp = shoot(k + dk, end_angle(k + dk, theta_l))
        _, um, wm = shoot(k - dk, end_angle(k - dk, theta_l))
        return (up - um) / (2 * dk), (wp - wm) / (2 * dk)


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    results = json.loads(Path(sys.argv[1]).read_text())
    case = tomllib.loads(Path(results["case"]).read_text())
    length = case["surface"]["edge_u"][0]
    width = case["surface"]["edge_v"][1]
    t = case["thickness"]
    e = case["material"]["young"]
    c = case["load"][0]["per_length"][1]
    ei = e * width * t**3 / 12.0
    k_max = c * width * length**2 / ei
    el = Elastica()
    print(f"L = {length}, b = {width}, t = {t}, E = {e}: P L^2/EI = {k_max:g} at load factor 1")
    print(f"{'factor':>7} {'PL2/EI':>7} {'-u shell':>10} {'-u elastica':>11} "
          f"{'w shell':>9} {'w elastica':>10} {'theta_L deg':>11} {'error %':>8}")
    worst = 0.0
    path = {}
    for step in results["steps"]:
        lam = step["load_factor"]
        k = lam * k_max
        th, u, w = el.at(k)
        path[round(lam, 12)] = (k, th)
        tip = step["monitors"]["tip"]["displacement"]
        ue, we = u * length, w * length
        err = math.hypot(tip[0] - ue, tip[2] - we) / math.hypot(ue, we)
        worst = max(worst, err)
        print(f"{lam:7.3f} {k:7.2f} {-tip[0]:10.5f} {-ue:11.5f} {tip[2]:9.5f} {we:10.5f} "
              f"{math.degrees(th):11.2f} {100 * err:8.3f}")
    print(f"largest error along the path: {100 * worst:.3f} %")
    if len(sys.argv) < 3:
        return
    sens = json.loads(Path(sys.argv[2]).read_text())
    print("\nDesign derivatives at the last level (continuum; elastica from U'(k), W'(k)):")
    lam = sens["loads"][-1]
    k, th = path[round(lam, 12)]
    du, dw = el.derivative(k, th)
    _, u, w = shoot(k, th)
    reference = {
        "b": (0.0, 0.0),
        "L": (u + 2 * k * du, w + 2 * k * dw),
        "t": (-3 * k * du * length / t, -3 * k * dw * length / t),
    }
    for var in sens["variables"]:
        name = var["name"]
        if name not in reference:
            continue
        ref = dict(zip(["tip.ux", "tip.uz"], reference[name]))
        for label, series in var["steps"][-1]["monitors"].items():
            value = series["continuum"]
            print(f"  d({label})/d{name}: shell {value: .6e}, elastica {ref[label]: .6e}")


if __name__ == "__main__":
    main()
