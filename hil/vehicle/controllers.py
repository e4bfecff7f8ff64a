"""Controllers the vehicle can run, from a spec: a controller file or a named built-in law.

A spec is ``kinematic``, ``pure-pursuit`` or ``stanley``, the latter two optionally with gains
(``pure-pursuit?lookahead_time=1.2&servo=4``, names of :class:`~design.laws.baselines.PurePursuitGains`
/ :class:`~design.laws.baselines.StanleyGains`), ``aog-pure-pursuit`` or ``aog-stanley`` (AgOpenGPS's
own laws and default settings, :mod:`design.laws.agopengps_baselines`, same ``?name=value`` form), or a
controller file (``*.json`` of kind ``linear``, ``mpc`` or ``nmpc``, see :mod:`design.files`). The bench adds the oracle (:mod:`hil.bench.runs.campaign`), which is
designed on the simulator's truth and cannot steer a real vehicle.
"""

from __future__ import annotations

from pathlib import Path

from design.laws.agopengps_baselines import (AogPurePursuitController, AogPurePursuitSettings, AogStanleyController,
                                       AogStanleySettings)
from design.laws.baselines import PurePursuitController, PurePursuitGains, StanleyController, StanleyGains
from design.laws.controller import Controller, KinematicLQRController
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from design.core.errors import ControllerFileError
from design.files.load import load_controller

from hil.vehicle.errors import VehicleConfigError

#: Named laws a vehicle can run without a file.
VEHICLE_CONTROLLERS = ("kinematic", "pure-pursuit", "stanley", "aog-pure-pursuit", "aog-stanley")


def split_spec(spec: str) -> tuple[str, dict[str, float]]:
    """``name?key=value&key=value`` -> ``(name, {key: value})``."""
    name, _, query = spec.partition("?")
    opts: dict[str, float] = {}
    for part in filter(None, query.split("&")):
        key, eq, value = part.partition("=")
        try:
            opts[key] = float(value)
        except ValueError:
            raise VehicleConfigError(f"controller option {part!r} in {spec!r}: expected key=number") from None
        if not eq:
            raise VehicleConfigError(f"controller option {part!r} in {spec!r}: expected key=number")
    return name, opts


def vehicle_controller(spec: str, public_key: Ed25519PublicKey | None = None,
                       legacy_certificate: bool = False) -> Controller:
    """Build the controller a spec names (see the module docstring).

    A controller file goes through :func:`design.files.load.load_controller`, which refuses
    it if its certificate is missing, failed or does not match its matrices.

    Parameters
    ----------
    spec
        The name or the file.
    public_key
        If given, a controller file must be signed by this key (``hil drive
        --require-signature``); a built-in law is then refused too.
    legacy_certificate
        Accept a file whose certificate predates the re-checkable ones (the simulation
        bench's historical files only; never on the vehicle).

    Raises
    ------
    VehicleConfigError
        For an unknown name, an unknown gain or a missing file.
    ControllerFileError
        For a controller file that fails a check.
    """
    if spec.endswith(".json"):
        if not Path(spec).is_file():
            raise VehicleConfigError(f"controller file {spec!r} does not exist")
        return load_controller(spec, public_key=public_key, legacy_certificate=legacy_certificate)
    if public_key is not None:
        raise ControllerFileError(f"a signed controller file is required, got the built-in law {spec!r}")
    name, opts = split_spec(spec)
    gains = {"pure-pursuit": (PurePursuitController, PurePursuitGains), "stanley": (StanleyController, StanleyGains),
             "aog-pure-pursuit": (AogPurePursuitController, AogPurePursuitSettings),
             "aog-stanley": (AogStanleyController, AogStanleySettings)}
    if name in gains:
        cls, gcls = gains[name]
        known = set(gcls.__dataclass_fields__)
        if set(opts) - known:
            raise VehicleConfigError(f"unknown {name} gain(s) {sorted(set(opts) - known)}; known: {sorted(known)}")
        return cls(gcls(**opts))
    if name == "kinematic" and not opts:
        return KinematicLQRController()
    raise VehicleConfigError(f"unknown controller {spec!r}; give one of {list(VEHICLE_CONTROLLERS)} "
                             "(pure-pursuit, stanley and the aog- laws take ?gain=value&...) or a controller file (.json)")


def controller_label(spec: str) -> str:
    """Short name of a controller spec for tables and file names (a file's stem; gains kept)."""
    if spec.endswith(".json"):
        return Path(spec).stem
    return spec.replace("?", "[").replace("&", ",") + ("]" if "?" in spec else "")
