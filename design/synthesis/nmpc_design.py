"""From the NMPC's settings to a certified controller file of kind ``"nmpc"``.

:func:`design_nmpc` checks that a reader will accept the settings, certifies the NMPC on the identified
models (:func:`design.files.nmpc.certify_nmpc`: its linearisation at each model's speed, unconstrained
and with the rate limit) and refuses settings that fail on any model, naming them, as
:func:`design.synthesis.mpc_design.design_mpc` does for the MPC.
"""

from __future__ import annotations

from typing import Sequence

from identification.model import Model

from design.core.errors import VerificationError
from design.core.verify import model_hash
from design.files.nmpc import RATE_FIX, NMPCFile, certify_nmpc, rate_limited_failures, settings_from_dict, settings_to_dict
from design.mpc.nmpc import NMPCSettings


def design_nmpc(models: Sequence[Model], settings: NMPCSettings, name: str = "nmpc") -> NMPCFile:
    """An NMPC file certified on ``models``; refuses settings whose linearisation fails on one.

    Raises
    ------
    VerificationError
        Naming every model on which the linearised loop is not stable.
    ControllerFileError
        Settings a file cannot carry (no integral state, limits outside :mod:`design.core.limits`).
    """
    settings_from_dict(settings_to_dict(settings), settings.dt)          # what a reader will accept
    cert = certify_nmpc(settings, models)
    if not cert["passed"]:
        bad = [f"{r['name']} (spectral radius {r['spectral_radius']:.6f})" for r in cert["models"]
               if not r["spectral_radius"] < 1.0]
        if bad:
            raise VerificationError(f"the NMPC's linearisation does not stabilise {len(bad)} of {len(models)} models: "
                                    f"{', '.join(bad)}; lower y_max/raise u_max, or check the models")
        bad = rate_limited_failures(cert["rate_limited"])
        raise VerificationError(f"the NMPC's law fails the rate-limited check on {len(bad)} of {len(models)} models: "
                                f"{', '.join(bad[:3])}{', ...' if len(bad) > 3 else ''}; {RATE_FIX}")
    return NMPCFile(name, settings, {"method": "nonlinear MPC (kinematic bicycle, path coordinates)",
                                     "integral": "cross-track, as a model state",
                                     "observer": ("Kalman filter with a steering offset and a lateral drift"
                                                  if settings.observer is not None else "none (measured state)")},
                    cert,
                    tuple({"name": str(m.meta.get("name", f"model {i}")), "hash": model_hash(m)}
                          for i, m in enumerate(models)))
