"""Identified tractor families for design tests: the worn-valve tractor's models
(tests/design/data/worn_valve_models.npz) and random-11's (random11_models.npz); see PROVENANCE.txt.

The worn valve: 15 local models of orders 4-10 (chosen by held-out 3 s prediction) and the central model (order 4),
as identified by ``hil commission --tractor worn-valve --passes 2 --duration 90`` (seed 1997): the
family on which the robust LMIs were infeasible before the design models (design/core/reduction.py).
Only A, B, C, K, dt and the metadata the design reads are kept.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from identification.model import Model

DATA = Path(__file__).parent / "data" / "worn_valve_models.npz"
#: random-11's 15 local models (artefact-free orders 4-6; see PROVENANCE.txt)
RANDOM11 = Path(__file__).parent / "data" / "random11_models.npz"


def worn_models() -> tuple[list[Model], Model, tuple[float, ...]]:
    """``(local models, central model, latency per output in s)`` of the worn-valve tractor."""
    models, latency = load_family(DATA)
    local = [m for m in models if m.meta.get("kind") == "local"]
    central = next(m for m in models if m.meta.get("kind") == "central")
    return local, central, latency


def random11_models() -> tuple[list[Model], tuple[float, ...]]:
    """``(local models, latency per output in s)`` of the generated tractor random-11."""
    return load_family(RANDOM11)


def load_family(path: Path) -> tuple[list[Model], tuple[float, ...]]:
    """The models of a family file (A, B, C, K and meta per name; dt, names, latency_s) and its latency."""
    with np.load(path, allow_pickle=False) as z:
        names = json.loads(str(z["names"]))
        dt = float(z["dt"])
        latency = tuple(json.loads(str(z["latency_s"])))
        models = []
        for n in names:
            a, b, c, k = (np.array(z[f"{n}/{x}"]) for x in "ABCK")
            meta = json.loads(str(z[f"{n}/meta"]))
            models.append(Model(a, b, c, np.zeros((c.shape[0], b.shape[1])), k, dt, meta))
    return models, latency
