"""PCD files (experiments.pcd): the header point-cloud tools expect, and points back exactly."""
import math

import numpy as np
import pytest

from dodt.frames import LidarScan
from experiments.pcd import PCDError, read_pcd, read_points, viewpoint_of, write_pcd, write_scan
from experiments.sequences import quaternion_to_matrix
from experiments.simulate import simulate


def _points(n=500, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.normal(size=(n, 3)) * [10.0, 5.0, 1.0]).astype(np.float32)


@pytest.mark.parametrize("binary", [True, False])
def test_points_come_back_exactly_with_the_standard_header(tmp_path, binary):
    pts = _points()
    path = write_pcd(tmp_path / "cloud.pcd", pts, binary=binary)
    np.testing.assert_array_equal(read_points(path), pts)
    _, header = read_pcd(path)
    assert header["VERSION"] == ["0.7"] and header["FIELDS"] == ["x", "y", "z"]
    assert header["SIZE"] == ["4"] * 3 and header["TYPE"] == ["F"] * 3 and header["COUNT"] == ["1"] * 3
    assert header["WIDTH"] == header["POINTS"] == [str(len(pts))] and header["HEIGHT"] == ["1"]
    assert header["DATA"] == ["binary" if binary else "ascii"]
    lines = path.read_bytes().split(b"\n")
    keys = [ln.split(b" ")[0].decode() for ln in lines[1:11]]
    assert keys == ["VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA"]
    if binary:  # the records follow the header, 12 bytes a point, little-endian
        assert path.stat().st_size == len(b"\n".join(lines[:11])) + 1 + 12 * len(pts)


def test_an_empty_cloud_is_a_valid_file(tmp_path):
    for binary in (True, False):
        assert read_points(write_pcd(tmp_path / f"e{binary}.pcd", np.zeros((0, 3)), binary=binary)).shape == (0, 3)


def test_a_scan_is_written_in_its_frame_with_its_pose_as_the_viewpoint(tmp_path):
    T = np.eye(4)
    c, s = math.cos(0.7), math.sin(0.7)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = [1.0, 2.0, 1.3]
    pts = _points(50)
    scan = LidarScan(points=pts, ranges=np.linalg.norm(pts, axis=1), azimuth=np.zeros(50, np.float32),
                     elevation=np.zeros(50, np.float32), stamp=0.1, T_world_sensor=T, seq=1, n_rays=60)
    _, header = read_pcd(write_scan(tmp_path / "s.pcd", scan))
    vp = [float(v) for v in header["VIEWPOINT"]]
    np.testing.assert_allclose(vp, [1.0, 2.0, 1.3, math.cos(0.35), 0.0, 0.0, math.sin(0.35)], atol=1e-7)
    assert viewpoint_of(np.eye(4)) == (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
    world = read_points(write_scan(tmp_path / "w.pcd", scan, frame="world"))
    np.testing.assert_allclose(world, pts @ T[:3, :3].T + T[:3, 3], atol=1e-5)


def test_files_it_cannot_read_are_refused_by_name(tmp_path):
    bad = tmp_path / "bad.pcd"
    bad.write_bytes(b"VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 0\nHEIGHT 1\n"
                    b"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 0\nDATA binary\n")
    with pytest.raises(PCDError, match="bad.pcd.*4-byte float"):
        read_pcd(bad)
    short = write_pcd(tmp_path / "short.pcd", _points(10))
    short.write_bytes(short.read_bytes()[:-5])
    with pytest.raises(PCDError, match="10 points announced"):
        read_pcd(short)


def test_simulate_writes_the_lidar_scans_with_their_poses(tmp_path):
    s = simulate("crossing", 0, tmp_path, duration=0.5, save_every=15, segmentation=False, lidar=True)
    lines = [ln.split() for ln in (tmp_path / "lidar.txt").read_text().splitlines() if not ln.startswith("#")]
    assert s["lidar_scans_saved"] == len(lines) == 6  # 10 Hz over 0.5 s, the first at 0
    stamps = [float(ln[0]) for ln in lines]
    assert np.allclose(np.diff(stamps), 0.1)
    first = read_pcd(tmp_path / lines[0][8])
    pts = read_points(tmp_path / lines[0][8])
    assert len(pts) > 5000
    # the viewpoint is the pose of lidar.txt; points in the sensor frame: the floor lies 1.32 m below it
    vp = [float(v) for v in first[1]["VIEWPOINT"]]
    assert np.allclose(vp[:3], [float(v) for v in lines[0][1:4]], atol=1e-5)
    R = quaternion_to_matrix(np.array([float(v) for v in lines[0][4:8]]))
    world_z = pts @ R.T[:, 2] + float(lines[0][3])
    assert np.min(world_z) == pytest.approx(0.0, abs=0.1)
