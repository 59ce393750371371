#!/usr/bin/python3
"""Writes the example chessboard images for `mcms calib-rig`: examples/boards/.

    /usr/bin/python3 examples/make_boards.py [--out examples/boards]

Debian's interpreter (numpy, cv2). One camera, cam0: 320 x 240 pixels, pinhole fx = fy =
300 px, centre (159.5, 119.5), OpenCV distortion k1 = -0.2, k2 = 0.05 (an OPENCV4 lens),
sees a 7 x 4 inner-corner chessboard of 60 mm squares (board.yaml, Kalibr's layout) in
10 poses 0.55-0.75 m away, tilted up to 35 deg. Each pixel is the mean of 4 x 4 sub-pixel
samples through the lens model (pixel centres at integer coordinates), blurred
(sigma 0.6 px) and with 1 DN of noise; 8-bit PNG. Seeded: the same files on every run.
"""
import argparse
import os

import cv2
import numpy as np

W, H = 320, 240
K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
DIST = np.array([-0.2, 0.05, 0.0, 0.0])
COLS, ROWS, SQ = 7, 4, 0.06  # inner corners, square (m): >= 25 px, for cornerSubPix's 23 px window
BOARD_YAML = f"""target_type: checkerboard
targetCols: {COLS}
targetRows: {ROWS}
rowSpacingMeters: {SQ}
colSpacingMeters: {SQ}
"""


def render(R, t, rng, ss=4):
    # Sub-pixel sample positions (pixel centres at integers), through the lens to rays.
    off = (np.arange(ss) + 0.5) / ss - 0.5
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    shape = (H, W, ss, ss)
    su = np.broadcast_to(u[..., None, None] + off[None, None, None, :], shape).reshape(-1)
    sv = np.broadcast_to(v[..., None, None] + off[None, None, :, None], shape).reshape(-1)
    pts = np.stack([su, sv], -1).astype(np.float64).reshape(-1, 1, 2)
    n = cv2.undistortPointsIter(pts, K, DIST, None, None,
                                (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-12)).reshape(-1, 2)
    rays = np.concatenate([n, np.ones((len(n), 1))], 1)
    # Board plane z = 0 in board coordinates: p_cam = R p_board + t.
    normal, d = R[:, 2], R[:, 2] @ t
    s = d / (rays @ normal)
    p = (rays * s[:, None] - t) @ R  # to board coordinates
    x, y = p[:, 0] / SQ, p[:, 1] / SQ
    # Inner corners at integer (x, y) in [0, COLS-1] x [0, ROWS-1]; squares around them.
    inside = (x > -1) & (x < COLS) & (y > -1) & (y < ROWS) & (s > 0)
    black = (np.floor(x).astype(int) + np.floor(y).astype(int)) % 2 == 0
    val = np.where(inside, np.where(black, 25.0, 215.0), 215.0)
    frame = (x > -1.6) & (x < COLS + 0.6) & (y > -1.6) & (y < ROWS + 0.6) & (s > 0)
    val = np.where(frame, val, 90.0)  # the board's white margin, then the background
    img = val.reshape(H, W, ss * ss).mean(-1)
    img = cv2.GaussianBlur(img, (0, 0), 0.6) + rng.normal(0, 1.0, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "boards"))
    a = p.parse_args()
    os.makedirs(os.path.join(a.out, "cam0"), exist_ok=True)
    open(os.path.join(a.out, "board.yaml"), "w").write(BOARD_YAML)
    rng = np.random.default_rng(9283)
    centre = np.array([(COLS - 1) * SQ / 2, (ROWS - 1) * SQ / 2, 0])
    k = 0
    while k < 10:
        rv = np.radians(rng.uniform(-35, 35, 3)) * np.array([1, 1, 0.3])
        R = cv2.Rodrigues(rv)[0] @ cv2.Rodrigues(np.array([np.pi, 0, 0]))[0]
        dist = rng.uniform(0.55, 0.75)
        shift = np.array([rng.uniform(-0.06, 0.06), rng.uniform(-0.04, 0.04), dist])
        t = shift - R @ centre
        corners = np.array([[x * SQ, y * SQ, 0] for y in (-1.6, ROWS + 0.6) for x in (-1.6, COLS + 0.6)])
        q, _ = cv2.projectPoints(corners, cv2.Rodrigues(R)[0], t, K, DIST)
        q = q.reshape(-1, 2)
        if q[:, 0].min() < 4 or q[:, 0].max() > W - 5 or q[:, 1].min() < 4 or q[:, 1].max() > H - 5:
            continue  # the whole board in view
        cv2.imwrite(os.path.join(a.out, "cam0", f"{k:02d}.png"), render(R, t, rng))
        k += 1


if __name__ == "__main__":
    main()
