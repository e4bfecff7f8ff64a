"""Geodesy, angle conventions, attitude from antennas, lever arm and guidance lines."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gnss.attitude import AntennaGeometry, solve_attitude, solve_attitude_from_baselines
from gnss.errors import ConfigError, GeometryError
from gnss.frames import enu_angle_to_yaw, euler_from_rotation, rotation_enu_from_body, yaw_to_enu_angle
from gnss.geodesy import LocalFrame
from gnss.guidance import ABLine, CurvedLine, ParallelLines
from gnss.lever_arm import antenna_enu, control_point_enu

FIELD = LocalFrame.from_degrees(41.5749659, -93.7505719, 246.7)


def fl(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


# ------------------------------------------------------------------ geodesy
@settings(max_examples=100, deadline=None)
@given(fl(-5000, 5000), fl(-5000, 5000), fl(-50, 50))
def test_enu_geodetic_round_trip_sub_millimetre(e, n, u):
    lat, lon, h = FIELD.to_geodetic([e, n, u])
    back = FIELD.to_enu(lat, lon, h)
    assert np.max(np.abs(back - [e, n, u])) < 1e-4


def test_enu_known_offsets():
    # one arc-second of latitude north of the origin is ~30.9 m north, no east
    p = FIELD.to_enu(FIELD.lat0 + math.radians(1 / 3600), FIELD.lon0, FIELD.h0)
    assert p[0] == pytest.approx(0.0, abs=1e-6) and p[1] == pytest.approx(30.86, abs=0.02)
    assert p[2] == pytest.approx(-7.5e-5, abs=1e-4)  # earth curvature, ~n^2 / 2R
    q = FIELD.to_enu(FIELD.lat0, FIELD.lon0 + math.radians(1 / 3600), FIELD.h0)
    assert q[0] == pytest.approx(30.92 * math.cos(FIELD.lat0), abs=0.05)
    assert FIELD.to_enu([FIELD.lat0] * 4, [FIELD.lon0] * 4, [FIELD.h0] * 4).shape == (4, 3)


def test_local_frame_refuses_degrees():
    with pytest.raises(ConfigError, match="from_degrees"):
        LocalFrame(41.57, -93.75, 0.0)


# --------------------------------------------------------------- conventions
def test_yaw_enu_angle_conventions():
    assert yaw_to_enu_angle(0.0) == pytest.approx(math.pi / 2)  # north
    assert yaw_to_enu_angle(math.pi / 2) == pytest.approx(0.0)  # east
    assert enu_angle_to_yaw(math.pi) == pytest.approx(3 * math.pi / 2)  # west
    R = rotation_enu_from_body(math.pi / 2, 0.0, 0.0)  # facing east
    assert R @ [1, 0, 0] == pytest.approx([1, 0, 0], abs=1e-12)  # forward -> east
    assert R @ [0, 1, 0] == pytest.approx([0, 1, 0], abs=1e-12)  # left -> north
    R = rotation_enu_from_body(0.0, 0.1, 0.0)
    assert (R @ [1, 0, 0])[2] > 0  # positive pitch = nose up
    R = rotation_enu_from_body(0.0, 0.0, 0.1)
    assert (R @ [-0.0, -1, 0])[2] < 0  # positive roll = right side down


@settings(deadline=None)
@given(fl(0, 2 * math.pi - 1e-6), fl(-1.2, 1.2), fl(-3.0, 3.0))
def test_euler_round_trip(yaw, pitch, roll):
    y, p, r = euler_from_rotation(rotation_enu_from_body(yaw, pitch, roll))
    assert abs((y - yaw + math.pi) % (2 * math.pi) - math.pi) < 1e-9
    assert p == pytest.approx(pitch, abs=1e-9) and r == pytest.approx(roll, abs=1e-9)


# ------------------------------------------------------------------ attitude
FOUR = AntennaGeometry(np.array([[0.0, 0.0, 3.0], [2.0, 0.0, 3.0], [0.0, 1.5, 3.0], [1.0, -1.5, 3.05]]))


@pytest.mark.parametrize("n_ant", [3, 4])
def test_attitude_from_3_and_4_antennas_with_noise(n_ant):
    rng = np.random.default_rng(4)
    geo = AntennaGeometry(FOUR.positions[:n_ant])
    errs = []
    for _ in range(50):
        yaw, pitch, roll = rng.uniform(0, 2 * np.pi), rng.uniform(-0.2, 0.2), rng.uniform(-0.3, 0.3)
        R = rotation_enu_from_body(yaw, pitch, roll)
        ant = geo.positions @ R.T + [100.0, -50.0, 2.0] + rng.normal(0, 0.005, (n_ant, 3))
        att = solve_attitude(geo, ant)
        assert att.full
        errs.append([(att.yaw - yaw + np.pi) % (2 * np.pi) - np.pi, att.pitch - pitch, att.roll - roll])
    rms = np.sqrt(np.mean(np.square(errs), axis=0))
    # 5 mm noise on ~2 m baselines: a few mrad
    assert np.all(rms < 0.006) and np.all(rms > 1e-4)


def test_attitude_noise_free_is_exact_and_more_antennas_help():
    R = rotation_enu_from_body(1.0, 0.05, -0.1)
    att = solve_attitude(FOUR, FOUR.positions @ R.T)
    assert (att.yaw, att.pitch, att.roll) == pytest.approx((1.0, 0.05, -0.1), abs=1e-12)
    assert att.residual_rms < 1e-12


def test_two_antennas_fore_aft_gives_yaw_and_pitch_only():
    geo = AntennaGeometry(np.array([[0.0, 0.0, 3.0], [1.5, 0.0, 3.0]]))
    R = rotation_enu_from_body(4.26, 0.04, 0.2)  # roll unobservable from this baseline
    att = solve_attitude(geo, geo.positions @ R.T)
    assert not att.full
    assert att.yaw == pytest.approx(4.26, abs=1e-6) and att.pitch == pytest.approx(0.04, abs=1e-6)
    assert att.roll == pytest.approx(0.0, abs=1e-6)  # minimum-tilt choice


def test_attitude_geometry_validated():
    with pytest.raises(GeometryError, match="N = 2..4"):
        AntennaGeometry(np.zeros((5, 3)))
    with pytest.raises(GeometryError, match="0.05 m"):
        AntennaGeometry(np.array([[0, 0, 0], [0.01, 0, 0]]))
    with pytest.raises(GeometryError, match="finite"):
        solve_attitude_from_baselines([[1, 0, 0]], [[np.nan, 0, 0]])


# ------------------------------------------------------------------ lever arm
def test_roll_on_side_slope_is_compensated():
    # tractor heading north on a 10 % side slope, right side down; antenna 3 m above the control point
    roll = math.atan(0.10)
    arm = [0.0, 0.0, 3.0]
    cp_true = np.array([10.0, 20.0, 0.0])
    ant = antenna_enu(cp_true, 0.0, 0.0, roll, arm)
    assert ant[0] - cp_true[0] == pytest.approx(3.0 * math.sin(roll))  # antenna displaced ~0.3 m east
    cp = control_point_enu(ant, 0.0, 0.0, roll, arm)
    assert cp == pytest.approx(cp_true, abs=1e-12)
    line = ABLine([10.0, 0.0], [10.0, 100.0])
    assert abs(line.errors(ant[0], ant[1]).cross_track) > 0.29  # uncompensated: looks like 0.3 m off-line
    assert abs(line.errors(cp[0], cp[1]).cross_track) < 1e-12


def test_lever_arm_vectorised_and_forward_offset():
    yaw = np.array([0.0, math.pi / 2, math.pi])
    ant = np.zeros((3, 3))
    cp = control_point_enu(ant, yaw, 0.0, 0.0, [2.0, 0.0, 0.0])
    assert cp == pytest.approx(np.array([[0, -2, 0], [-2, 0, 0], [0, 2, 0]]), abs=1e-12)


# ------------------------------------------------------------------ guidance
@settings(deadline=None)
@given(fl(-50, 50), fl(-500, 500), fl(0, 2 * math.pi), fl(-3, 3))
def test_ab_line_sign_and_magnitude(offset, station, line_yaw, dpsi):
    a = np.array([3.0, -7.0])
    u = np.array([math.sin(line_yaw), math.cos(line_yaw)])  # yaw -> (east, north)
    left = np.array([-u[1], u[0]])
    line = ABLine(a, a + 30 * u)
    p = a + station * u + offset * left
    # vehicle yaw turned counter-clockwise by dpsi from the line heading
    err = line.errors(p[0], p[1], (line_yaw - dpsi) % (2 * math.pi))
    assert err.cross_track == pytest.approx(offset, abs=1e-9)
    assert err.station == pytest.approx(station, abs=1e-9)
    assert err.heading_error == pytest.approx(dpsi, abs=1e-9)


def test_ab_line_left_is_positive_concrete():
    north = ABLine([0.0, 0.0], [0.0, 10.0])
    e = north.errors([-1.0, 1.0], [5.0, 5.0], [0.0, 0.0])
    assert list(e.cross_track) == [1.0, -1.0]  # west of a northbound line is left
    assert north.errors(0.0, 0.0, 0.1).heading_error < 0  # turned clockwise = to the right


def test_parallel_rows_one_metre_apart():
    rows = ParallelLines(ABLine([0.0, 0.0], [100.0, 0.0]), spacing=1.0)  # eastbound, rows to the north
    n = np.array([0.2, 0.9, 2.6, -1.3])
    e = np.full(4, 50.0)
    assert list(rows.row_index(e, n)) == [0, 1, 3, -1]
    assert rows.errors(e, n).cross_track == pytest.approx([0.2, -0.1, -0.4, -0.3])
    assert rows.errors(e, n, row=2).cross_track == pytest.approx(n - 2.0)
    assert rows.base.offset(2.0).errors(e, n).cross_track == pytest.approx(n - 2.0)


def test_curved_line_on_circle():
    arc = CurvedLine.arc([0.0, 0.0], 50.0, -math.pi / 2, math.pi / 2, spacing=0.1)  # CCW half circle
    th = np.linspace(-1.2, 1.2, 25)
    for r in (47.0, 50.0, 53.5):
        pts = r * np.column_stack([np.cos(th), np.sin(th)])
        tangent_yaw = enu_angle_to_yaw(th + math.pi / 2)
        err = arc.errors(pts[:, 0], pts[:, 1], tangent_yaw)
        assert err.cross_track == pytest.approx(np.full(th.size, 50.0 - r), abs=2e-3)  # inside = left
        assert err.station == pytest.approx(50.0 * (th + math.pi / 2), rel=1e-3)
        assert np.max(np.abs(err.heading_error)) < 0.003


def test_curved_line_offset_and_spline():
    pts = np.array([[0.0, 0.0], [20.0, 5.0], [40.0, 0.0], [60.0, -5.0], [80.0, 0.0]])
    line = CurvedLine.from_spline(pts, spacing=0.2)
    # the sampled polyline passes the control points within its chord error (spacing^2 * curvature / 8)
    assert line.errors(pts[:, 0], pts[:, 1]).cross_track == pytest.approx(np.zeros(5), abs=2e-4)
    off = line.offset(1.0)
    v = off.vertices[5:-5:10]
    assert line.errors(v[:, 0], v[:, 1]).cross_track == pytest.approx(np.ones(len(v)), abs=5e-3)


def test_curved_straight_matches_ab_line_vectorised():
    rng = np.random.default_rng(1)
    ab = ABLine([0.0, 0.0], [30.0, 40.0])
    poly = CurvedLine(np.array([[0.0, 0.0], [15.0, 20.0], [30.0, 40.0]]))
    e, n = rng.uniform(-100, 100, (2, 1000))
    y = rng.uniform(0, 2 * np.pi, 1000)
    a, b = ab.errors(e, n, y), poly.errors(e, n, y, chunk=128)
    # beyond-the-ends extension and segment projection agree with the infinite line
    assert b.cross_track == pytest.approx(a.cross_track, abs=1e-9)
    assert b.station == pytest.approx(a.station, abs=1e-9)
    assert b.heading_error == pytest.approx(a.heading_error, abs=1e-12)


def test_guidance_geometry_validated():
    with pytest.raises(GeometryError, match="0.1 m apart"):
        ABLine([0, 0], [0, 0.01])
    with pytest.raises(GeometryError, match="spacing"):
        ParallelLines(ABLine([0, 0], [0, 1]), spacing=0.0)
    with pytest.raises(GeometryError, match="duplicates"):
        CurvedLine(np.array([[0, 0], [0, 0], [1, 1]]))
