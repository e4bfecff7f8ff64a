"""Exogenous inputs of one simulated pass, generated up front from its own generator.

Everything that does not depend on what the controller does is drawn here for
the whole pass (speed, slope, soil forces, implement draft and pull, hop), so a
pass is reproducible from its seed whatever else runs beside it in a batch.
Spatial processes (slope, soil) have correlation lengths in metres and are
turned into time constants at the nominal speed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.truth.conditions import Condition
from hil.truth.noise import ou_noise
from hil.truth.params import SimParams


@dataclass(frozen=True)
class Exogenous:
    """Exogenous sequences of one pass on the integration grid (``n`` samples, step ``dt``).

    Attributes
    ----------
    speed
        Longitudinal speed, m/s (>= 0).
    roll
        Side-slope roll, rad, + = left side up.
    force_y
        Soil lateral force on the tractor at the CG, N, + = left.
    ripper_force, ripper_moment
        Lateral force at the shanks [N] and yaw moment [N m] of a hitched ripper (0 otherwise).
    draft, gang_pull
        Disker draft [N] along the tongue and lateral gang pull [N, + = left] (0 otherwise).
    front_load
        Front-axle load relative to no implement: implement weight transfer times hop.
    """

    speed: np.ndarray
    roll: np.ndarray
    force_y: np.ndarray
    ripper_force: np.ndarray
    ripper_moment: np.ndarray
    draft: np.ndarray
    gang_pull: np.ndarray
    front_load: np.ndarray


def hop_depth(cond: Condition, p: SimParams) -> float:
    """Fraction of front load lost at the peak of a bounce at this condition (0 without draft)."""
    if cond.implement == "none" or cond.speed <= 0:
        return 0.0
    h = p.hop
    return float(h.amplitude * np.exp(-0.5 * ((cond.speed - h.center_speed) / h.speed_width) ** 2))


def soil_force_sigma(cond: Condition, p: SimParams) -> float:
    """1-sigma of the soil lateral force on the tractor at this condition's nominal speed, N.

    ``field.lateral_force * (V / field.force_reference_speed) ** field.force_speed_exponent``
    (the plain ``lateral_force`` at a standstill or with exponent 0).
    """
    f = p.field
    if cond.speed <= 0 or f.force_speed_exponent == 0:
        return f.lateral_force
    return float(f.lateral_force * (cond.speed / f.force_reference_speed) ** f.force_speed_exponent)


def generate(cond: Condition, p: SimParams, n: int, rng: np.random.Generator) -> Exogenous:
    """Draw the exogenous sequences of one pass.

    Parameters
    ----------
    cond
        Implement and nominal speed.
    p
        Simulator parameters.
    n
        Number of integration steps (samples).
    rng
        The pass's own generator.
    """
    dt, f = p.dt, p.field
    v0 = cond.speed
    vref = max(v0, 0.1)  # spatial correlation -> time constant (a standstill never moves anyway)
    speed = np.maximum(v0 * (1.0 + ou_noise(rng, n, dt, f.speed_variation, f.speed_time_constant)), 0.0)
    roll = f.roll_mean + ou_noise(rng, n, dt, f.roll, f.roll_correlation_length / vref)
    force_y = ou_noise(rng, n, dt, soil_force_sigma(cond, p), f.force_correlation_length / vref)
    zeros = np.zeros(n)
    ripper_force = ripper_moment = draft = gang_pull = zeros
    load_static = 1.0
    if cond.implement == "ripper":
        r = p.ripper
        tau = r.soil_correlation_length / vref
        ripper_force = ou_noise(rng, n, dt, r.lateral_force, tau)
        ripper_moment = ou_noise(rng, n, dt, r.yaw_moment, tau)
        load_static = r.front_load_factor
    elif cond.implement == "disker":
        d = p.disker
        tau = d.soil_correlation_length / vref
        draft_mean = d.draft + d.draft_per_speed * v0
        draft = np.maximum(draft_mean * (1.0 + ou_noise(rng, n, dt, d.draft_variation, tau)), 0.0)
        gang_pull = d.gang_pull * (1.0 + ou_noise(rng, n, dt, d.pull_variation, tau))
        load_static = d.front_load_factor
    depth = hop_depth(cond, p)
    front_load = np.full(n, load_static)
    if depth > 0:
        t = np.arange(n) * dt
        phase = rng.uniform(0, 2 * np.pi)
        bounce = 0.5 + 0.5 * np.sin(2 * np.pi * p.hop.frequency * t + phase)
        bounce = np.clip(bounce + ou_noise(rng, n, dt, p.hop.irregularity, 0.3), 0.0, 1.0)
        front_load = load_static * (1.0 - depth * bounce)
    return Exogenous(speed, roll, force_y, ripper_force, ripper_moment, draft, gang_pull, front_load)


def stack(items: list[Exogenous]) -> Exogenous:
    """Stack several passes' sequences into ``(B, n)`` arrays (same ``n``)."""
    return Exogenous(*(np.stack([getattr(e, k) for e in items]) for k in Exogenous.__dataclass_fields__))
