"""Point clouds as PCD files (the Point Cloud Library's format, version 0.7), which PCL, Open3D and
CloudCompare read.

A file is a text header, one ``KEY value...`` line each (VERSION, FIELDS, SIZE, TYPE, COUNT, WIDTH, HEIGHT,
VIEWPOINT, POINTS, DATA, in that order), then the points: as text, one point a line (``DATA ascii``), or
packed little-endian records (``DATA binary``). ``write_pcd`` writes the fields x y z as 4-byte floats,
an unorganised cloud (HEIGHT 1); VIEWPOINT is the pose of the frame the points are in (tx ty tz qw qx qy
qz). ``read_pcd`` reads what it writes: 4-byte float fields, one value each, ascii or binary (not
binary_compressed).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from dodt.frames import LidarScan

_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")
IDENTITY_VIEWPOINT = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)


class PCDError(ValueError):
    """A file this reader cannot read, with the file's name and the reason."""


def viewpoint_of(T: np.ndarray) -> tuple[float, ...]:
    """A 4x4 rigid transform as a PCD VIEWPOINT: (tx, ty, tz, qw, qx, qy, qz)."""
    T = np.asarray(T, dtype=np.float64)
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    if w < 0:  # the same rotation, written with qw >= 0
        x, y, z, w = -x, -y, -z, -w
    return (*(float(v) for v in T[:3, 3]), float(w), float(x), float(y), float(z))


def write_pcd(path: str | Path, points: np.ndarray, binary: bool = True,
              viewpoint: tuple[float, ...] = IDENTITY_VIEWPOINT) -> Path:
    """Write (N, 3) points as a PCD v0.7 file with the fields x y z (4-byte floats). Returns the path."""
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float32).reshape(-1, 3))
    if len(viewpoint) != 7:
        raise ValueError(f"viewpoint: expected 7 numbers (tx ty tz qw qx qy qz), got {len(viewpoint)}")
    n = len(pts)
    header = ("# .PCD v0.7 - Point Cloud Data file format\n"
              "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
              f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT {' '.join(f'{v:.9g}' for v in viewpoint)}\nPOINTS {n}\n"
              f"DATA {'binary' if binary else 'ascii'}\n")
    path = Path(path)
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        if binary:
            f.write(pts.astype("<f4").tobytes())
        else:
            # 9 significant digits give every float32 back exactly
            f.write("".join(f"{x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in pts.tolist()).encode("ascii"))
    return path


def write_scan(path: str | Path, scan: LidarScan, frame: str = "sensor", binary: bool = True) -> Path:
    """Write a LiDAR scan's returns: in the sensor frame with the scan's pose as VIEWPOINT (``frame="sensor"``),
    or in the world frame (``frame="world"``, identity VIEWPOINT; scans of one flight then overlay)."""
    if frame == "sensor":
        return write_pcd(path, scan.points, binary, viewpoint_of(scan.T_world_sensor))
    if frame == "world":
        return write_pcd(path, scan.points_world(), binary)
    raise ValueError(f"frame: expected 'sensor' or 'world', got {frame!r}")


def read_pcd(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, list[str]]]:
    """Read a PCD file of 4-byte float fields: ({field: (N,) float32}, {header key: its values})."""
    path = Path(path)
    data = path.read_bytes()
    header: dict[str, list[str]] = {}
    pos = 0
    while "DATA" not in header:
        end = data.find(b"\n", pos)
        if end < 0:
            raise PCDError(f"{path}: the header ends before its DATA line")
        line = data[pos:end].decode("ascii", errors="replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        if key not in _KEYS:
            raise PCDError(f"{path}: unknown header key {key!r}")
        header[key] = values
    missing = [k for k in ("FIELDS", "SIZE", "TYPE", "POINTS") if k not in header]
    if missing:
        raise PCDError(f"{path}: the header lacks {', '.join(missing)}")
    fields = header["FIELDS"]
    counts = header.get("COUNT", ["1"] * len(fields))
    if header["SIZE"] != ["4"] * len(fields) or header["TYPE"] != ["F"] * len(fields) or counts != ["1"] * len(fields):
        raise PCDError(f"{path}: only 4-byte float fields of one value each are read (SIZE {header['SIZE']}, "
                       f"TYPE {header['TYPE']}, COUNT {counts})")
    n, mode = int(header["POINTS"][0]), header["DATA"][0]
    if mode == "binary":
        body = data[pos:pos + 4 * len(fields) * n]
        if len(body) != 4 * len(fields) * n:
            raise PCDError(f"{path}: {n} points announced, {len(body) // (4 * len(fields))} in the file")
        values = np.frombuffer(body, dtype="<f4").reshape(n, len(fields))
    elif mode == "ascii":
        rows = [r.split() for r in data[pos:].decode("ascii").splitlines() if r.strip()]
        if len(rows) != n or any(len(r) != len(fields) for r in rows):
            raise PCDError(f"{path}: {n} points of {len(fields)} values announced, {len(rows)} lines in the file")
        values = np.array(rows, dtype=np.float32).reshape(n, len(fields))
    else:
        raise PCDError(f"{path}: DATA {mode} is not read (ascii or binary)")
    return {name: values[:, i].astype(np.float32) for i, name in enumerate(fields)}, header


def read_points(path: str | Path) -> np.ndarray:
    """The (N, 3) float32 x y z of a PCD file."""
    cols, _ = read_pcd(path)
    if not {"x", "y", "z"} <= cols.keys():
        raise PCDError(f"{path}: no x y z fields")
    return np.stack([cols["x"], cols["y"], cols["z"]], axis=1)
