"""Shared by the Python tests: where the real data is, and small synthetic scenes."""
import os
import pathlib

import numpy as np

import mcms


def data_root():
    """../shared/data beside the project, or $MCMS_DATA_DIR (as the C++ tests)."""
    env = os.environ.get("MCMS_DATA_DIR")
    if env:
        return pathlib.Path(env)
    src = os.environ.get("MCMS_SOURCE_DIR", str(pathlib.Path(__file__).resolve().parents[2]))
    return pathlib.Path(src) / ".." / "shared" / "data"


def real_data(name):
    """The folder of one real data set, or None when it is not present."""
    p = data_root() / name
    return p if p.is_dir() else None


def look_at(eye, target, up=(0.0, 0.0, 1.0)):
    """T_cam_rig of a camera at `eye` (rig frame) looking at `target`: z forward, y down."""
    eye, target, up = (np.asarray(v, float) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, (0.0, 1.0, 0.0))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R_rig_cam = np.column_stack([x, y, z])
    T = np.eye(4)
    T[:3, :3] = R_rig_cam.T
    T[:3, 3] = -R_rig_cam.T @ eye
    return T


def pinhole_rig(n=4, radius=1.5, height=0.8, width=1280, height_px=1024, f=1400.0):
    """n pinhole cameras on a circle around the origin, all looking at (0, 0, 0)."""
    cams = []
    for i in range(n):
        a = 2 * np.pi * i / n + 0.3
        eye = (radius * np.cos(a), radius * np.sin(a), height)
        cams.append(mcms.CameraModel("LENSMODEL_PINHOLE", [f, f, (width - 1) / 2, (height_px - 1) / 2],
                                     width, height_px, look_at(eye, (0, 0, 0))))
    return mcms.CameraRig(cams)


def transform(T, p):
    return p @ T[:3, :3].T + T[:3, 3]
