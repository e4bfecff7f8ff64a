"""Discrete linear compensators and their closed loop with a model.

A compensator reads the (normalised) measured outputs ``y`` and returns the
steering-rate command ``u`` [rad/s]::

    xc[k+1] = Ac xc[k] + Bc y[k] + Ec (u_applied[k] - u[k])
    u[k]    = Cc xc[k] + Dc y[k]

``Ec`` is the anti-windup (back-calculation) gain: when the loop clips the
command, the compensator's memory of its own command follows what the plant
received. In the linear regime ``u_applied = u`` and ``Ec`` plays no part, so
every closed-loop check below ignores it. ``X0`` is the bumpless engage: on the
first step after a reset the state is set to ``xc = X0 y`` (e.g. the remembered
past outputs equal the present ones) instead of zeros, so the compensator does
not see a step from zero to the present errors.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from autosteer.checks import finite

from design.core.errors import DesignInputError


def as_matrix(value: Any, name: str, shape: tuple[int, int] | None = None,
              error: type[Exception] = DesignInputError) -> np.ndarray:
    """Copy ``value`` into a finite, read-only 2-D float array (``shape`` checked when given)."""
    try:
        arr = np.array(value, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise error(f"{name} must be a numeric matrix, got {type(value).__name__} ({exc})") from None
    if arr.ndim == 1 and shape is not None and 0 in shape:
        arr = arr.reshape(shape)
    if arr.ndim != 2:
        raise error(f"{name} must be 2-D, got shape {arr.shape}")
    if shape is not None and arr.shape != shape:
        raise error(f"{name} has shape {arr.shape}, expected {shape}")
    if not np.all(np.isfinite(arr)):
        raise error(f"{name} has non-finite entries")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class Compensator:
    """A discrete state-space compensator ``y -> u`` (validated once, read-only).

    Parameters
    ----------
    Ac, Bc, Cc, Dc
        (nc, nc), (nc, q), (m, nc), (m, q); ``q`` measured outputs in the models'
        (normalised) units, ``m`` commands in rad/s.
    dt
        Sample time, s (> 0).
    Ec
        (nc, m) anti-windup gain; zeros when not given.
    X0
        (nc, q) engage initialisation ``xc = X0 y``; zeros when not given.
    """

    Ac: np.ndarray
    Bc: np.ndarray
    Cc: np.ndarray
    Dc: np.ndarray
    dt: float
    Ec: np.ndarray | None = None
    X0: np.ndarray | None = None

    def __post_init__(self) -> None:
        dc = as_matrix(self.Dc, "Dc")
        m, q = dc.shape
        ac = as_matrix(self.Ac, "Ac")
        nc = ac.shape[0]
        if ac.shape != (nc, nc):
            raise DesignInputError(f"Ac must be square, got shape {ac.shape}")
        bc = as_matrix(self.Bc, "Bc", (nc, q))
        cc = as_matrix(self.Cc, "Cc", (m, nc))
        ec = as_matrix(np.zeros((nc, m)) if self.Ec is None else self.Ec, "Ec", (nc, m))
        x0 = as_matrix(np.zeros((nc, q)) if self.X0 is None else self.X0, "X0", (nc, q))
        dt = finite(self.dt, "dt", lo=0.0, lo_open=True, unit="s", noun="a finite sample time",
                    error=DesignInputError)
        for name, v in (("Ac", ac), ("Bc", bc), ("Cc", cc), ("Dc", dc), ("Ec", ec), ("X0", x0)):
            object.__setattr__(self, name, v)
        object.__setattr__(self, "dt", float(dt))

    @property
    def order(self) -> int:
        """Number of compensator states nc."""
        return self.Ac.shape[0]

    @property
    def n_measurements(self) -> int:
        """Number of outputs it reads, q."""
        return self.Bc.shape[1]

    @property
    def n_commands(self) -> int:
        """Number of commands it writes, m."""
        return self.Cc.shape[0]


def closed_loop_matrix(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
                       comp: Compensator) -> np.ndarray:
    """State matrix of plant ``(a, b, c, d)`` in feedback with ``comp`` (state ``[x; xc]``).

    ``u = Cc xc + Dc y`` with ``y = C x + D u`` (positive feedback, as the compensator's
    sign is part of it). Raises :class:`DesignInputError` on a dimension mismatch or an
    ill-posed algebraic loop.
    """
    _check_dimensions(b, c, comp)
    ux, uc = _command_gains(c, d, comp)
    return np.vstack([_plant_rows(a, b, ux, uc), _compensator_rows(c, d, comp, ux, uc)])


def input_gain_loop(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
                    comp: Compensator) -> Callable[[float], np.ndarray]:
    """The closed loop with a gain ``k > 0`` at the plant input, as a function of ``k``.

    ``loop(k)`` is ``closed_loop_matrix(a, k b, c, k d, comp)`` to the last bit. For a strictly
    proper plant (``d`` all zero) the algebraic loop is the identity and the compensator's rows do not
    depend on ``k``: they are formed once, and each gain forms only the plant's rows (a gain-margin
    bisection asks for a hundred gains of one loop).
    """
    _check_dimensions(b, c, comp)
    if d.any():
        return lambda k: closed_loop_matrix(a, b * k, c, d * k, comp)
    ux, uc = _command_gains(c, d, comp)          # k d is d for k > 0: zeros of the same sign
    bottom = _compensator_rows(c, d, comp, ux, uc)
    return lambda k: np.vstack([_plant_rows(a, b * k, ux, uc), bottom])


def _check_dimensions(b: np.ndarray, c: np.ndarray, comp: Compensator) -> None:
    m, q = b.shape[1], c.shape[0]
    if (comp.n_measurements, comp.n_commands) != (q, m):
        raise DesignInputError(f"compensator reads {comp.n_measurements} outputs and writes {comp.n_commands} "
                               f"inputs; the model has q={q} outputs and m={m} inputs")


def _command_gains(c: np.ndarray, d: np.ndarray, comp: Compensator) -> tuple[np.ndarray, np.ndarray]:
    """``(ux, uc)`` with ``u = ux x + uc xc``: the algebraic loop ``u = Cc xc + Dc (C x + D u)`` solved.

    With ``d`` all zero ``I - Dc D`` is exactly the identity, whose inverse LAPACK returns exactly:
    the identity is used as it is, without the condition number and the inverse.
    """
    m = d.shape[1]
    if d.any():
        w = np.eye(m) - comp.Dc @ d
        if np.linalg.cond(w) > 1e12:
            raise DesignInputError("algebraic loop I - Dc D is singular: the closed loop is ill-posed")
        mi = np.linalg.inv(w)
    else:
        mi = np.eye(m)
    return mi @ comp.Dc @ c, mi @ comp.Cc


def _plant_rows(a: np.ndarray, b: np.ndarray, ux: np.ndarray, uc: np.ndarray) -> np.ndarray:
    return np.hstack([a + b @ ux, b @ uc])


def _compensator_rows(c: np.ndarray, d: np.ndarray, comp: Compensator, ux: np.ndarray,
                      uc: np.ndarray) -> np.ndarray:
    return np.hstack([comp.Bc @ (c + d @ ux), comp.Ac + comp.Bc @ d @ uc])


def spectral_radius(a: np.ndarray) -> float:
    """Largest eigenvalue modulus of ``a`` (0 for an empty matrix)."""
    return float(np.max(np.abs(np.linalg.eigvals(a)))) if a.size else 0.0


def integrator_states(comp: Compensator) -> tuple[int, ...]:
    """Indices of the compensator's pure integrators of a measured output.

    A state ``i`` is one when its update is ``xc_i[k+1] = xc_i[k] + b y_j[k]`` and nothing
    else: row ``i`` of ``Ac`` is the unit row ``e_i``, row ``i`` of ``Bc`` has exactly one
    non-zero entry, and ``Ec`` leaves it alone (the integral of y/V of
    :func:`design.core.iostate.feedback_compensator` is such a state). The vehicle holds these
    during line acquisition (:mod:`design.laws.acquisition`).
    """
    out = []
    for i in range(comp.order):
        unit = np.zeros(comp.order)
        unit[i] = 1.0
        if (np.array_equal(comp.Ac[i], unit) and np.count_nonzero(comp.Bc[i]) == 1
                and not np.any(comp.Ec[i])):
            out.append(i)
    return tuple(out)
