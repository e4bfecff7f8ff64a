"""Stated limits of the design tools and of the controller files they write.

Every limit has a name, a value and a reason; the checks raise an error that names the
limit, says what came and what to do. The numbers are generous for a steering loop
(the project's models are of order 4-10, its MPC horizons 20-100 samples, its files
tens of kilobytes) and small enough that nothing runs for minutes or asks for gigabytes
before it is refused.

=====================  ===========  ==================================================
limit                  value        why
=====================  ===========  ==================================================
``MAX_MODEL_ORDER``    60 states    LMI synthesis and the margin checks grow as n^3-n^6;
                                    order 60 certifies in seconds, 1200 ran over 150 s
``MAX_HORIZON``        1000 steps   50 s at 20 Hz; the condensed QP holds N^2 doubles
``MAX_FILE_BYTES``     4 MiB        a robust file with 15 embedded order-10 models is
                                    about 0.1 MiB
``MAX_NESTING``        16 levels    the deepest controller file nests 7 levels
``MAX_COEFFICIENT``    1e6          largest ``|entry|`` of a compensator or gain matrix
                                    (designed ones stay below 1e3)
=====================  ===========  ==================================================

Physical ranges of the limits a controller file carries (SI units):

* rate limit (steering rate): ``0 < rate <= RATE_LIMIT_MAX`` = 1.0 rad/s (57 deg/s; the
  valve's full-PWM rate is 0.28-0.5 rad/s);
* speed floor of the normalisation: ``SPEED_MIN_RANGE`` = 0.05-3 m/s;
* output clips: ``0 < clip <= OUTPUT_CLIP_MAX`` = 10 in the output's units (s for y/V,
  rad s/m for psi/V, m or rad without normalisation) or none;
* MPC wheel-angle limit: ``0 < limit <= WHEEL_ANGLE_MAX`` = 0.8 rad (46 deg; the stops are
  at 35 deg);
* sample time: ``DT_RANGE`` = 0.001-1 s.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

from autosteer.checks import finite
from identification.model import Model

from design.core.errors import DesignInputError

MAX_MODEL_ORDER = 60
MAX_HORIZON = 1000
MAX_FILE_BYTES = 4 * 1024 * 1024
MAX_NESTING = 16
MAX_COEFFICIENT = 1e6
RATE_LIMIT_MAX = 1.0
SPEED_MIN_RANGE = (0.05, 3.0)
OUTPUT_CLIP_MAX = 10.0
WHEEL_ANGLE_MAX = 0.8
DT_RANGE = (0.001, 1.0)


def check_model_order(models: Sequence[Model], error: type[Exception] = DesignInputError) -> None:
    """Refuse any model of more than :data:`MAX_MODEL_ORDER` states, before any work on it.

    Raises
    ------
    DesignInputError
        (or ``error``) naming the model, its order and the limit.
    """
    for i, m in enumerate(models):
        if m.order > MAX_MODEL_ORDER:
            name = m.meta.get("name", f"model {i}")
            raise error(f"model {name!r} has {m.order} states; the design tools take at most MAX_MODEL_ORDER = "
                        f"{MAX_MODEL_ORDER} (synthesis and certification grow as n^3 or faster); identify a model "
                        "of lower order (identification okid --order) or reduce it first")


def check_horizon(horizon: Any, error: type[Exception] = DesignInputError) -> int:
    """The MPC horizon as an int in ``1..MAX_HORIZON``, checked before anything is allocated."""
    horizon = finite(horizon, "horizon", lo=1, integer=True, error=error)
    if horizon > MAX_HORIZON:
        raise error(f"horizon {horizon} exceeds MAX_HORIZON = {MAX_HORIZON} steps (50 s at 20 Hz); "
                    "use a shorter horizon")
    return horizon


def in_range(value: Any, low: float, high: float, what: str, error: type[Exception] = DesignInputError,
             low_open: bool = True) -> float:
    """``value`` as a float in ``(low, high]`` (``[low, high]`` with ``low_open=False``), else ``error``."""
    ok = not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
    if ok:
        ok = (value > low if low_open else value >= low) and value <= high
    if not ok:
        bracket = "(" if low_open else "["
        raise error(f"{what} must be a finite number in {bracket}{low:g}, {high:g}], got {value!r}")
    return float(value)
