#!/usr/bin/env python3
"""Writes the example robot log: robot_log.csv (for `mcms audit robot`) and the same
measurements as robot_measurements.yaml (for `mcms calib-robot`).

    python3 examples/make_robot_log.py [--out examples]

A KUKA KR 5 arc (the built-in robot, model/robots/kuka_kr5_arc.yaml: standard DH,
T = Rz(q + theta_offset) Tz(d) Tx(a) Rx(alpha)) carries a target 60 mm off its flange to
30 poses, measured 4 times each (pass by pass, one measurement a minute, 2 h) by a laser
tracker that stands 2 m away, turned by 143 deg about its vertical (the registration and
the tool are unknown to the commands: they fit both). The noise is 0.02 / 0.03 / 0.05 mm
along three rotated axes; the temperature column is 21 C with 0.01 C noise.

The hidden effect: joint 3's zero is off by 0.01 deg (a mastering error, e.g. after a
motor swap); everything else is the nominal table. `mcms audit robot` names it as
`joint_offset at joint 3` and `mcms calib-robot` finds it as A3's theta offset.
Everything is drawn from a fixed seed (the standard library only), so the files are reproducible.
"""
import argparse
import math
import os

import random

# The built-in KR 5 arc (model/robots/kuka_kr5_arc.yaml): d, a, alpha, theta_offset.
DH = [(0.400, 0.180, -math.pi / 2, 0.0), (0.0, 0.600, 0.0, -math.pi / 2), (0.0, 0.120, math.pi / 2, 0.0),
      (-0.620, 0.0, -math.pi / 2, 0.0), (0.0, 0.0, math.pi / 2, 0.0), (-0.115, 0.0, math.pi, 0.0)]
HIDDEN_JOINT, HIDDEN_OFFSET_DEG = 2, 0.01  # joint 3 (0-based 2)
TOOL_M = [0.0, 0.0, 0.060]
LO = [-1.2, -1.6, 0.2, -2.5, -1.6, -3.0]
HI = [1.2, 0.4, 2.2, 2.5, 1.6, 3.0]


def rot(axis, angle):
    c, s = math.cos(angle), math.sin(angle)
    if axis == "x":
        return [[1, 0, 0], [0, c, -s], [0, s, c]]
    return [[c, -s, 0], [s, c, 0], [0, 0, 1]]


def mul(A, B):  # 3x3 times 3x3
    return [[sum(A[i][k] * B[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def app(A, v):  # 3x3 times a 3-vector
    return [sum(A[i][k] * v[k] for k in range(3)) for i in range(3)]


def add(u, v):
    return [x + y for x, y in zip(u, v)]


def flange(q, offsets):
    R, t = [[1, 0, 0], [0, 1, 0], [0, 0, 1]], [0.0, 0.0, 0.0]
    for j, (d, a, alpha, th0) in enumerate(DH):
        Rz = rot("z", q[j] + th0 + offsets[j])
        # T_{j-1,j} = Rz(theta) Tz(d) Tx(a) Rx(alpha)
        tj = add([0, 0, d], app(Rz, [a, 0, 0]))
        t = add(t, app(R, tj))
        R = mul(mul(R, Rz), rot("x", alpha))
    return R, t


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--out", default=os.path.dirname(os.path.abspath(__file__)))
    a = p.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rng = random.Random(26)
    poses = [[rng.uniform(LO[j], HI[j]) for j in range(6)] for _ in range(30)]
    R_meas_base = rot("z", 2.5)
    t_meas_base = [2.0, 0.5, -0.2]
    # Noise axes: a fixed rotation of the tracker's frame.
    noise_R = mul(rot("z", 0.5), rot("x", 0.3))
    sigma = [0.02e-3, 0.03e-3, 0.05e-3]
    offsets = [0.0] * 6
    offsets[HIDDEN_JOINT] = math.radians(HIDDEN_OFFSET_DEG)
    csv = ["time_s,q1_rad,q2_rad,q3_rad,q4_rad,q5_rad,q6_rad,x_m,y_m,z_m,temperature_c"]
    yml = ["# Example measurements for `mcms calib-robot` (examples/README.md): the rows of robot_log.csv.",
           "# q_rad: joint values; position_m: the target in the laser tracker's frame.",
           "measurements:"]
    for k in range(120):
        q = poses[k % 30]
        R, t = flange(q, offsets)
        noise = app(noise_R, [s * rng.gauss(0, 1) for s in sigma])
        x = add(add(app(R_meas_base, add(app(R, TOOL_M), t)), t_meas_base), noise)
        temp = 21.0 + 0.01 * rng.gauss(0, 1)
        qs = [f"{v:.10f}" for v in q]
        xs = [f"{v:.9f}" for v in x]
        csv.append(",".join([f"{60.0 * k:g}"] + qs + xs + [f"{temp:.3f}"]))
        yml.append(f"  - {{q_rad: [{', '.join(qs)}], position_m: [{', '.join(xs)}]}}")
    with open(os.path.join(a.out, "robot_log.csv"), "w") as f:
        f.write("\n".join(csv) + "\n")
    with open(os.path.join(a.out, "robot_measurements.yaml"), "w") as f:
        f.write("\n".join(yml) + "\n")


if __name__ == "__main__":
    main()
