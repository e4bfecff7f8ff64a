"""Is a model good enough to design on? Thresholds on its held-out multi-step prediction fit.

Every model is judged by the fit of its :data:`~identification.multistep.HORIZON_S`
(3 s) predictions from the Kalman state on held-out data, per output
(:mod:`identification.multistep`). Two stated thresholds:

:data:`REFUSE_FIT` = 50 %
    At a fit of 50 % the prediction error's RMS is half the output's spread:
    the model accounts for less than three quarters of the motion over the
    horizon the controller plans on, and a certificate computed on it says
    little about the tractor. Below it the model is *refused*.
:data:`WARN_FIT` = 65 %
    Below it the model is accepted with a warning. On the default simulated
    tractor (``hil sysid``, 15 conditions, 3 passes) today's order-4 local
    models give 69-94 % for y/V, 73-94 % for psi/V and 90-95 % for delta, so
    a sound model clears it with a margin and a warning means something.

Each message names the model, the output, the fit against its threshold and
the fixes that usually help, e.g.
``local_disker_11th: 3 s prediction fit of y/V -264.7 %, psi/V -585.0 %, delta
-157.1 % < 50 %; record longer or more passes, raise --order (or use --order
validate), check the GPS latency (--latency), or check the sensor`` (the worn-valve
tractor's order-2 model of today's recipe).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .data import IOData
from .errors import ModelRefusedError, OptionError
from .model import Model
from .multistep import HORIZON_S, MultiStepResult, multistep_fit

#: Held-out multi-step fit below which a model is refused, % (module docstring).
REFUSE_FIT = 50.0
#: Held-out multi-step fit below which a model is accepted with a warning, % (module docstring).
WARN_FIT = 65.0


@dataclass(frozen=True)
class Acceptance:
    """The verdict on one model.

    Attributes
    ----------
    name
        Model name.
    status
        ``"accepted"``, ``"warning"`` or ``"refused"``.
    prediction
        The held-out multi-step fits the verdict rests on.
    messages
        At most two messages (the outputs below each threshold), each with its fix.
    refusals
        The message of the outputs below :data:`REFUSE_FIT` (empty if none).
    """

    name: str
    status: str
    prediction: MultiStepResult
    messages: tuple[str, ...]
    refusals: tuple[str, ...] = ()
    fix: str = ""

    def as_dict(self) -> dict:
        """JSON-friendly verdict (for the model's metadata)."""
        return {"status": self.status, "messages": list(self.messages), "refuse_fit": REFUSE_FIT,
                "warn_fit": WARN_FIT, "horizon_s": self.prediction.horizon_s,
                "fit": dict(zip(self.prediction.output_names, (float(v) for v in self.prediction.fit)))}


def _fix(model: Model) -> str:
    """The fixes worth trying, given how the order was chosen."""
    sel = model.meta.get("selection") or {}
    tried = [c["order"] for c in sel.get("candidates", []) if "order" in c]
    if sel.get("method", "").startswith("multi-step") and tried and model.order < max(tried):
        order = "the order was chosen by validation (a higher one predicted no better)"
    elif tried:
        order = f"raise --order above {max(tried)}"
    else:
        order = "raise --order (or use --order validate)"
    return f"record longer or more passes, {order}, check the GPS latency (--latency), or check the sensor"


def assess(name: str, model: Model, data: IOData, warmup: int = 0, horizon_s: float = HORIZON_S) -> Acceptance:
    """Judge ``model`` by its multi-step prediction fits on held-out ``data``.

    Parameters
    ----------
    name
        Model name for the messages.
    model
        The identified model (units of ``data``).
    data
        Held-out data (not used for the fit nor for choosing the order).
    warmup
        Samples of each experiment before the first window (the observer's past).
    horizon_s
        Prediction horizon, s.
    """
    pred = multistep_fit(model.A, model.B, model.C, model.D, model.K, data, horizon_s, warmup=warmup)
    low = [(o, f) for o, f in zip(pred.output_names, pred.fit) if not np.isfinite(f) or f < REFUSE_FIT]
    weak = [(o, f) for o, f in zip(pred.output_names, pred.fit) if np.isfinite(f) and REFUSE_FIT <= f < WARN_FIT]

    def listed(items: list) -> str:
        return ", ".join(f"{o} {f:.1f} %" for o, f in items)

    refusals, messages = [], []
    if low:
        refusals.append(f"{name}: {pred.horizon_s:g} s prediction fit of {listed(low)} < {REFUSE_FIT:.0f} %; "
                        f"{_fix(model)}")
        messages += refusals
    if weak:
        messages.append(f"{name}: {pred.horizon_s:g} s prediction fit of {listed(weak)} < {WARN_FIT:.0f} % "
                        f"(accepted with a warning); {_fix(model)}")
    status = "refused" if low else "warning" if weak else "accepted"
    return Acceptance(name, status, pred, tuple(messages), tuple(refusals), _fix(model))


def enforce(verdicts: Sequence[Acceptance], policy: str = "refuse",
            conditions: Sequence[Sequence[dict]] | None = None) -> list[str]:
    """Raise :class:`ModelRefusedError` if any verdict is a refusal (``policy="refuse"``).

    ``conditions`` (one list per verdict, as in a model's ``meta["conditions"]``) are carried by the
    error's ``refused`` so a caller can record more passes of exactly those conditions. Returns the
    warnings (and, with ``policy="warn"``, the refusals as warnings).
    """
    if conditions is not None and len(conditions) != len(verdicts):
        raise OptionError(f"{len(conditions)} condition lists for {len(verdicts)} verdicts")
    if policy not in ("refuse", "warn"):
        raise OptionError(f"acceptance policy must be 'refuse' or 'warn', got {policy!r}")
    bad_at = [k for k, v in enumerate(verdicts) if v.refusals]
    bad = [verdicts[k] for k in bad_at]
    if bad and policy == "refuse":
        fixes = {v.fix for v in bad}
        if len(fixes) == 1:      # one fix for all: said once, after the list
            lines = [m[:-len(v.fix) - 2] if m.endswith("; " + v.fix) else m for v in bad for m in v.refusals]
            lines.append(f"to fix: {fixes.pop()}")
        else:
            lines = [m for v in bad for m in v.refusals]
        raise ModelRefusedError(f"{len(bad)} model(s) do not predict well enough to design on:\n  "
                                + "\n  ".join(lines)
                                + "\n(--acceptance warn writes them anyway, marked refused in their metadata)",
                                refused={verdicts[k].name: [dict(c) for c in (conditions[k] if conditions is not None
                                                                              else [])] for k in bad_at})
    return [m for v in verdicts for m in v.messages]
