"""The NMPC's observer: a Kalman filter on its kinematic model with two slowly varying disturbances.

Without it the NMPC (:mod:`design.mpc.nmpc`) takes the measured cross-track, heading error and wheel
angle as its state: the GPS noise goes straight into a high-gain law, and a steady pull is
removed only by the slow integral. The observer estimates, on the linearised kinematic model of
:func:`design.core.kinematic.kinematic_model` about the path (speed ``V`` m/s, wheelbase ``L``,
control point ``d2`` ahead of the rear axle, path curvature ``kappa`` 1/m a known input)::

    y'     = V psi + V d2 / L (delta + b) + v          cross-track, m (+ left)
    psi'   = V / L (delta + b) - V kappa               heading error, rad (+ CCW)
    delta' = u                                         wheel angle, rad; u the command sent, rad/s
    b'     = 0  (random walk)                          steering offset, rad: what the wheel must hold
                                                       against a pull that turns the tractor
    v'     = 0  (random walk)                          lateral drift, m/s: a pull that crabs it

from the measured ``[y, psi, delta]``, with the steady-state (speed-scheduled) Kalman gain of its
zero-order-hold discretisation, in the current-estimate form (correct with this tick's
measurement, then command, then predict with the command sent). The NMPC is given the effective
state ``[y, psi + v / V, delta + b]``: its own kinematic model written for the wheel angle that
turns the tractor and the heading that moves it along the path, so its prediction and its
steady state on a curve hold under the estimated pull. Both disturbances are observable from the
three measurements; the cross-track integral of the NMPC stays (its file requires it), so what
the two states do not model still leaves no steady error.

The disturbances start from zero on every engage and on entering and leaving a headland turn (a
turn's slip is not the next pass's pull), as the linear controllers' estimate does, and are held at
zero over the turn. The filter is
linear in its state, so at a fixed speed observer and certified law are one linear compensator
(:func:`observed_law`); that is what the NMPC's controller file certifies and ``design verify``
re-checks, with the command the observer is told clipped to the rate limit as on the vehicle.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any, Mapping, Protocol

import numpy as np

from autosteer.checks import positive
from design.core.errors import DesignInputError
from design.mpc.nmpc_law import dare_doubling, nilpotent_zoh

__all__ = ["ObserverSettings", "NMPCObserver", "observer_model", "observer_gain_table", "observed_law"]

#: Observer states: cross-track m, heading error rad, wheel angle rad, steering offset rad, drift m/s.
N_OBSERVER = 5
_C = np.eye(3, N_OBSERVER)


@dataclass(frozen=True)
class ObserverSettings:
    """Noise levels of the NMPC's Kalman filter (standard deviations; validated, all > 0).

    Attributes
    ----------
    noise_y, noise_psi, noise_delta
        Measurement noise of the cross-track (m), heading error (rad) and wheel angle (rad).
    process_y, process_psi, process_delta
        Model error per tick of the same states (m, rad, rad): the valve's lag and flow curve,
        tyre slip and the latencies the kinematic model leaves out.
    offset_rate
        Random walk of the steering offset, rad per sqrt(s).
    drift_rate
        Random walk of the lateral drift, m/s per sqrt(s).

    The defaults trust the measurements (a fast filter: its lag is what the rate-limited loop
    cannot afford) and let the disturbances move slowly: with 0.01 for both rates the certificate's
    rate-limited check fails at 2.24-2.91 m/s on the demo's models. Chosen on AB lines (seed 0,
    2.91 m/s none and disker, 1.79 none; docs/nmpc.md), not on the fields they are compared on.
    """

    noise_y: float = 0.005
    noise_psi: float = 0.001
    noise_delta: float = 0.003
    process_y: float = 0.005
    process_psi: float = 0.005
    process_delta: float = 0.02
    offset_rate: float = 0.003
    drift_rate: float = 0.003

    def __post_init__(self) -> None:
        for k, v in asdict(self).items():
            positive(v, k, where="ObserverSettings", noun="a finite standard deviation", error=DesignInputError)

    def to_dict(self) -> dict[str, float]:
        """The settings as a JSON object (the NMPC file's ``settings.observer``)."""
        return {k: float(v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "ObserverSettings":
        """Settings from a mapping holding exactly the field names (unknown or missing ones refused)."""
        names = sorted(f.name for f in fields(cls))
        if not isinstance(d, Mapping) or sorted(d) != names:
            got = sorted(d) if isinstance(d, Mapping) else type(d).__name__
            raise DesignInputError(f"observer settings must hold exactly {', '.join(names)}; got {got}")
        return cls(**{k: d[k] for k in names})


class _Geometry(Protocol):
    """What the observer reads of :class:`design.mpc.nmpc.NMPCSettings`."""

    dt: float
    wheelbase: float
    d2: float
    speed_range: tuple[float, float]
    observer: ObserverSettings | None


def observer_model(s: _Geometry, speed: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold ``(Ad (5x5), Bd (5x2))`` of the observer's model at ``speed`` m/s (module
    docstring); the inputs are the steering rate (rad/s) and the path curvature (1/m). Exact: ``A``
    is nilpotent, so the series ends."""
    v, lw, d2 = float(speed), s.wheelbase, s.d2
    a = np.zeros((N_OBSERVER, N_OBSERVER))
    a[0, 1], a[0, 2], a[0, 3], a[0, 4] = v, v * d2 / lw, v * d2 / lw, 1.0
    a[1, 2] = a[1, 3] = v / lw
    b = np.zeros((N_OBSERVER, 2))
    b[2, 0], b[1, 1] = 1.0, -v
    return nilpotent_zoh(a, b, s.dt)


def _kalman_gain(s: _Geometry, speed: float) -> np.ndarray:
    """Steady-state current-estimate Kalman gain ``L`` (5x3) at ``speed`` m/s."""
    o = s.observer
    ad, _ = observer_model(s, speed)
    r = np.diag([o.noise_y, o.noise_psi, o.noise_delta]) ** 2
    q = np.diag([o.process_y ** 2, o.process_psi ** 2, o.process_delta ** 2,
                 o.offset_rate ** 2 * s.dt, o.drift_rate ** 2 * s.dt])
    # the filter's Riccati equation is the regulator's of (A', C'); dare_doubling needs only B R^-1 B'
    p = dare_doubling(ad.T, _C.T @ np.diag(1.0 / np.sqrt(np.diag(r))), q, 1.0)
    return p @ _C.T @ np.linalg.inv(_C @ p @ _C.T + r)


def observer_gain_table(s: _Geometry) -> tuple[np.ndarray, np.ndarray]:
    """``(speeds, gains)``: the Kalman gain on the NMPC's speed grid (0.05 m/s steps of ``speed_range``)."""
    lo, hi = s.speed_range
    speeds = np.linspace(lo, hi, int(round((hi - lo) / 0.05)) + 1)
    return speeds, np.array([_kalman_gain(s, v) for v in speeds])


def _interpolated(speeds: np.ndarray, table: np.ndarray, speed: float) -> np.ndarray:
    v = float(np.clip(speed, speeds[0], speeds[-1]))
    i = int(min(np.searchsorted(speeds, v, side="right") - 1, len(speeds) - 2))
    t = (v - speeds[i]) / (speeds[i + 1] - speeds[i])
    return (1 - t) * table[i] + t * table[i + 1]


def effective_map(speed: float) -> np.ndarray:
    """``T`` (3x5): the NMPC's state ``[y, psi + v / V, delta + b]`` from the observer's."""
    t = np.eye(3, N_OBSERVER)
    t[1, 4], t[2, 3] = 1.0 / float(speed), 1.0
    return t


class NMPCObserver:
    """The filter itself, at the measured speed each tick (module docstring).

    Parameters
    ----------
    settings
        The NMPC's settings (:class:`design.mpc.nmpc.NMPCSettings`) with ``observer`` set.
    """

    def __init__(self, settings: _Geometry) -> None:
        if settings.observer is None:
            raise DesignInputError("NMPCObserver needs settings with an observer (ObserverSettings)")
        self.settings = settings
        self.speeds, self._gains = observer_gain_table(settings)
        #: Disturbances held at zero (a headland turn: its wheel angles are where the linear model's
        #: ``tan`` is off by 5-10 %, which the estimates would take for a pull; measured: 1.8 m off at
        #: 2.91 m/s with the disker on gentle-curves without the hold).
        self.held = False
        self.reset()

    def gain(self, speed: float) -> np.ndarray:
        """Kalman gain ``L`` (5x3) at ``speed`` m/s, interpolated on the grid (clamped outside)."""
        return _interpolated(self.speeds, self._gains, speed)

    def reset(self) -> None:
        """Forget everything: the next measurement is taken as the state, the disturbances are 0."""
        self._prior: np.ndarray | None = None
        self.state = np.zeros(N_OBSERVER)

    def forget_disturbance(self) -> None:
        """Set the steering offset and the drift back to 0 (a headland turn's start or end)."""
        self.state[3:] = 0.0
        if self._prior is not None:
            self._prior[3:] = 0.0

    def correct(self, y: float, psi: float, delta: float, speed: float) -> np.ndarray:
        """Filtered state after this tick's measurement (m, rad, rad); returns the NMPC's effective
        state ``[y, psi + v / V, delta + b]`` at ``speed`` m/s."""
        z = np.array([y, psi, delta])
        if self._prior is None:
            self.state = np.r_[z, 0.0, 0.0]
        else:
            self.state = self._prior + self.gain(speed) @ (z - self._prior[:3])
        if self.held:
            self.state[3:] = 0.0
        return effective_map(speed) @ self.state

    def predict(self, u: float, speed: float, curvature: float) -> None:
        """Advance by one tick with the command sent ``u`` rad/s and the path curvature 1/m."""
        ad, bd = observer_model(self.settings, speed)
        self._prior = ad @ self.state + bd @ np.array([u, curvature])

    @property
    def disturbance(self) -> tuple[float, float]:
        """``(steering offset rad, lateral drift m/s)`` now."""
        return float(self.state[3]), float(self.state[4])


def observed_law(s: _Geometry, speed: float, k: np.ndarray) -> tuple[np.ndarray, ...]:
    """Observer and linear law ``u = -k [T x_hat, i]`` at ``speed`` m/s as one compensator on the
    identified models' normalised outputs ``m = [y/V, psi/V, delta]``.

    The state is ``[prior estimate (5), integral i]``; ``i`` advances by ``dt y`` (the measured
    cross-track), as the NMPC's. Returns ``(Ac, Bc, Cc, Dc, Bu)``: ``u = Cc xc + Dc m`` and
    ``xc+ = Ac xc + Bc m`` when the observer is told the law's own command, ``xc+ = Ac xc + Bc m +
    Bu (u_sent - u)`` when it is told a clipped one (the rate-limited check).
    """
    v = float(speed)
    ad, bd = observer_model(s, v)
    gain = _interpolated(*observer_gain_table(s), v)
    dz = np.diag([v, v, 1.0])                        # physical measurement from the normalised one
    kx, ki = np.asarray(k, dtype=float)[:3] @ effective_map(v), float(k[3])
    corr = np.eye(N_OBSERVER) - gain @ _C
    n = N_OBSERVER + 1
    cc = np.r_[-kx @ corr, -ki].reshape(1, n)
    dc = (-kx @ gain @ dz).reshape(1, 3)
    ao = np.zeros((n, n))
    ao[:N_OBSERVER, :N_OBSERVER], ao[N_OBSERVER, N_OBSERVER] = ad @ corr, 1.0
    bo = np.zeros((n, 3))
    bo[:N_OBSERVER], bo[N_OBSERVER, 0] = ad @ gain @ dz, s.dt * v
    bu = np.zeros((n, 1))
    bu[:N_OBSERVER, 0] = bd[:, 0]
    return ao + bu @ cc, bo + bu @ dc, cc, dc, bu
