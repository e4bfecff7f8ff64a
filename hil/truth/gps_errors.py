"""GPS measurements of the simulated tractor: truth, then errors, then time stamps.

The simulator provides *values and time stamps*; encoding them as NMEA/UBX is the
GNSS front-end's business. Position (5 Hz) is the roof antenna's horizontal
position in the line frame (x along the line, y left); attitude (10 Hz) is yaw
relative to the line, roll and pitch. Each epoch has a time of validity on the
simulator's grid and an arrival time at the host (latency plus jitter); epochs
inside an outage are lost; RTK float episodes raise the position noise and
report fix quality 5 instead of 4 (NMEA GGA convention).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.truth.noise import episodes, ou_noise
from hil.truth.params import GpsParams, VehicleParams

FIX_RTK_FIXED = 4
FIX_RTK_FLOAT = 5


@dataclass(frozen=True)
class GpsErrors:
    """Pre-drawn errors of one pass (or a stacked batch: a leading ``B`` axis).

    Position arrays have one entry per 5 Hz epoch, attitude arrays one per 10 Hz epoch.
    """

    pos_noise: np.ndarray      # (..., n_pos, 2) m, white, unit variance scaled later by fix state
    multipath: np.ndarray      # (..., n_pos, 2) m
    pos_float: np.ndarray      # (..., n_pos) bool
    pos_lost: np.ndarray       # (..., n_pos) bool
    pos_jitter: np.ndarray     # (..., n_pos) s
    speed_noise: np.ndarray    # (..., n_pos) m/s
    att_noise: np.ndarray      # (..., n_att, 3) rad: yaw, roll, pitch
    att_lost: np.ndarray       # (..., n_att) bool
    att_jitter: np.ndarray     # (..., n_att) s
    pos_corrupt: np.ndarray    # (..., n_pos) float: < 0 intact, else the fraction of the message where a bit flips
    att_corrupt: np.ndarray    # (..., n_att) float, likewise


def draw_errors(g: GpsParams, duration: float, rng: np.random.Generator) -> GpsErrors:
    """Draw every GPS error of a pass of ``duration`` seconds from the pass's generator."""
    n_pos = int(np.floor(duration * g.position_rate + 1e-9)) + 1
    n_att = int(np.floor(duration * g.attitude_rate + 1e-9)) + 1
    dtp = 1.0 / g.position_rate
    mp = np.stack([ou_noise(rng, n_pos, dtp, g.multipath, g.multipath_time_constant) for _ in range(2)], -1)
    return GpsErrors(
        pos_noise=rng.standard_normal((n_pos, 2)),
        multipath=mp,
        pos_float=episodes(rng, n_pos, g.float_rate, g.float_length * g.position_rate),
        pos_lost=episodes(rng, n_pos, g.dropout_rate, g.dropout_length * g.position_rate),
        pos_jitter=rng.uniform(-g.latency_jitter, g.latency_jitter, n_pos),
        speed_noise=g.speed_noise * rng.standard_normal(n_pos),
        att_noise=rng.standard_normal((n_att, 3)) * np.array([g.yaw_noise, g.roll_noise, g.roll_noise]),
        att_lost=episodes(rng, n_att, g.dropout_rate, g.dropout_length * g.attitude_rate),
        att_jitter=rng.uniform(-g.latency_jitter, g.latency_jitter, n_att),
        pos_corrupt=_corruption(rng, n_pos, g.corrupt_rate),
        att_corrupt=_corruption(rng, n_att, g.corrupt_rate),
    )


def _corruption(rng: np.random.Generator, n: int, rate: float) -> np.ndarray:
    """Per message: -1 when intact, else where in the message (0..1) a bit flips (bit = 8 * fraction % 8)."""
    hit = rng.random(n) < rate
    where = rng.random(n)
    return np.where(hit, where, -1.0)


def corrupt(data: bytes, where: float) -> bytes:
    """``data`` with one bit flipped at relative position ``where`` (0..1); unchanged if ``where < 0``."""
    if where < 0 or not data:
        return data
    pos = min(int(where * len(data)), len(data) - 1)
    bit = int(where * len(data) * 8) % 8
    out = bytearray(data)
    out[pos] ^= 1 << bit
    return bytes(out)


def stack_errors(items: list[GpsErrors]) -> GpsErrors:
    """Stack passes' errors along a new leading axis."""
    return GpsErrors(*(np.stack([getattr(e, k) for e in items]) for k in GpsErrors.__dataclass_fields__))


def antenna_offset(psi: np.ndarray, roll: np.ndarray, vp: VehicleParams) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal offset (line frame x, y) of the roof antenna from the CG, m.

    Roll (+ = left side up) tilts the cab: an antenna ``h`` above the ground moves
    ``-h sin(roll)`` sideways (to the right when the left side is up).
    """
    xr = vp.antenna_ahead_of_cg
    yr = vp.antenna_left_of_cg * np.cos(roll) - vp.antenna_height * np.sin(roll)
    c, s = np.cos(psi), np.sin(psi)
    return xr * c - yr * s, xr * s + yr * c


def control_point_from_antenna(y_ant: np.ndarray, psi: np.ndarray, roll: np.ndarray,
                               vp: VehicleParams) -> np.ndarray:
    """Cross-track [m, + = left] of the control point (CG on the ground) from the antenna's.

    Lever-arm and roll compensation with the *measured* heading and roll, as the
    vehicle computer does it.
    """
    return y_ant - antenna_offset(psi, roll, vp)[1]


def position_epoch(x: np.ndarray, y: np.ndarray, psi: np.ndarray, roll: np.ndarray, k: int,
                   err: GpsErrors, g: GpsParams, vp: VehicleParams) -> dict[str, np.ndarray]:
    """Measured antenna position of every tractor in a batch at position epoch ``k``.

    Parameters
    ----------
    x, y, psi, roll
        True CG position [m], heading [rad] and roll [rad] at the epoch's valid time, shape ``(B,)``.
    k
        Epoch index (valid time ``k / position_rate``).
    err
        Stacked errors of the batch.

    Returns
    -------
    dict
        ``x``, ``y`` [m], ``fix`` (4 or 5), ``lost`` (bool), ``t_arrival`` [s].
    """
    dx, dy = antenna_offset(psi, roll, vp)
    flt = err.pos_float[:, k]
    sigma = np.where(flt, g.float_noise, g.position_noise)
    noise = err.pos_noise[:, k, :] * sigma[:, None] + err.multipath[:, k, :]
    t_valid = k / g.position_rate
    return {"x": x + dx + noise[:, 0], "y": y + dy + noise[:, 1],
            "fix": np.where(flt, FIX_RTK_FLOAT, FIX_RTK_FIXED), "lost": err.pos_lost[:, k],
            "t_arrival": t_valid + g.position_latency + err.pos_jitter[:, k]}


def attitude_epoch(psi: np.ndarray, roll: np.ndarray, k: int, err: GpsErrors,
                   g: GpsParams) -> dict[str, np.ndarray]:
    """Measured yaw (relative to the line), roll and pitch [rad] at attitude epoch ``k``."""
    n = err.att_noise[:, k, :]
    t_valid = k / g.attitude_rate
    return {"yaw": psi + n[:, 0], "roll": roll + n[:, 1], "pitch": n[:, 2],
            "lost": err.att_lost[:, k], "t_arrival": t_valid + g.attitude_latency + err.att_jitter[:, k]}
