"""Parameters of the truth simulator, each with a default, a unit, a meaning and a source.

``source`` says where a default comes from: ``"paper"`` (the 1997 paper or
DESIGN section 2), ``"design"`` (DESIGN section 5), ``"calibrated"`` (set by the
bench's calibration against the paper's Table 2, :mod:`hil.bench.calibration.calibrate`; the values
are those of ``docs/calibration/result.json``, which a test keeps equal) or
``"assumption"`` (a plausible value for a JD 7800-class row-crop tractor that
nobody measured). ``hil params`` prints the whole table.

Frames: the tractor body frame is x forward, y left, z up (FLU); angles are
counter-clockwise positive seen from above; roll is positive when the left side
is up. All values are SI (m, s, rad, N, kg) unless the unit says otherwise.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Mapping

from hil.errors import SimulatorConfigError


def P(default: float, unit: str, doc: str, source: str = "assumption", *, lo: float | None = 0.0,
      lo_open: bool = False, hi: float | None = None) -> Any:
    """A documented parameter: default, unit, meaning, source and admissible range."""
    return field(default=default, metadata={"unit": unit, "doc": doc, "source": source,
                                            "lo": lo, "lo_open": lo_open, "hi": hi})


class _Group:
    """Validation and (de)serialisation shared by every parameter group."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            v = getattr(self, f.name)
            name = f"{type(self).__name__}.{f.name}"
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise SimulatorConfigError(f"{name} must be a number [{f.metadata['unit']}], got {v!r}")
            if not math.isfinite(v):
                raise SimulatorConfigError(f"{name} must be finite [{f.metadata['unit']}], got {v!r}")
            lo, hi = f.metadata["lo"], f.metadata["hi"]
            if lo is not None and (v < lo or (f.metadata["lo_open"] and v == lo)):
                rel = ">" if f.metadata["lo_open"] else ">="
                raise SimulatorConfigError(f"{name} must be {rel} {lo} [{f.metadata['unit']}], got {v!r}")
            if hi is not None and v > hi:
                raise SimulatorConfigError(f"{name} must be <= {hi} [{f.metadata['unit']}], got {v!r}")
            object.__setattr__(self, f.name, float(v))

    def to_dict(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}  # type: ignore[arg-type]


@dataclass(frozen=True)
class VehicleParams(_Group):
    """Dynamic bicycle model of the tractor (CG frame, linear tyres with friction saturation)."""

    mass: float = P(8000.0, "kg", "tractor mass (DESIGN: about 8 t)", "design", lo_open=True, hi=40000.0)
    yaw_inertia: float = P(20000.0, "kg m^2", "yaw moment of inertia about the CG", lo_open=True, hi=200000.0)
    wheelbase: float = P(2.85, "m", "front to rear axle (DESIGN: about 2.85 m)", "design", lo_open=True, hi=6.0)
    cg_to_front_axle: float = P(1.71, "m", "CG to front axle, d1 (40 % static load on the front axle)",
                                lo_open=True)
    front_cornering_stiffness: float = P(80e3, "N/rad", "both front tyres together", lo_open=True, hi=2e6)
    rear_cornering_stiffness: float = P(160e3, "N/rad", "both rear tyres together", lo_open=True, hi=4e6)
    friction_coefficient: float = P(0.6, "1", "lateral tyre-soil friction (saturation of tyre force)",
                                    lo_open=True)
    slip_speed_floor: float = P(0.5, "m/s", "wheel speed below which slip angles are regularised "
                                "(numerical; the passes run at >= 1 m/s)", lo_open=True)
    standstill_speed: float = P(0.05, "m/s", "below this speed the tyres hold (static friction): "
                                "external lateral forces are not applied", lo_open=True)
    antenna_ahead_of_cg: float = P(-0.3, "m", "GPS antenna position ahead of the CG (cab roof)", lo=None)
    antenna_left_of_cg: float = P(0.0, "m", "GPS antenna lateral position, + = left", lo=None)
    antenna_height: float = P(3.0, "m", "GPS antenna height above the ground (cab roof)", lo_open=True, hi=6.0)
    hitch_behind_rear_axle: float = P(1.0, "m", "drawbar hitch pin behind the rear axle", hi=5.0)


@dataclass(frozen=True)
class SteeringParams(_Group):
    """Electro-hydraulic steering valve driven by PWM (the paper: strongly non-linear)."""

    max_rate: float = P(0.35, "rad/s", "wheel-angle rate at full PWM duty to the left", lo_open=True, hi=2.0)
    right_gain: float = P(0.85, "1", "rate to the right relative to the left at equal duty "
                          "(left/right asymmetry)", lo_open=True)
    deadband: float = P(0.08, "duty", "PWM duty below which the valve does not open", hi=0.9)
    flow_exponent: float = P(1.3, "1", "valve flow curve: rate ~ (duty beyond deadband)^exponent",
                             lo_open=True)
    lag: float = P(0.08, "s", "first-order time constant of spool and cylinder", lo_open=True, hi=2.0)
    max_wheel_angle: float = P(0.61, "rad", "mechanical wheel-angle stop, both sides (35 deg)",
                               lo_open=True)


@dataclass(frozen=True)
class WheelSensorParams(_Group):
    """Wheel-angle potentiometer digitised by the HC11's 8-bit ADC (the paper: non-linear)."""

    rate: float = P(20.0, "Hz", "sample and report rate of the bridge", "paper", lo_open=True)
    center_counts: float = P(128.0, "counts", "ADC reading at zero wheel angle", hi=255.0)
    counts_at_stop: float = P(100.0, "counts", "counts from centre to either stop (linear part)",
                              lo_open=True, hi=127.0)
    cubic: float = P(0.15, "1", "cubic non-linearity of the potentiometer: counts deviate by "
                     "cubic*(s^3 - s)*counts_at_stop, s = angle/stop", lo=-0.3,
                     hi=0.3)
    noise: float = P(0.5, "counts", "potentiometer and ADC noise before quantisation (1-sigma)", hi=20.0)
    latency: float = P(0.01, "s", "report age when it reaches the host (serial frame time)", hi=1.0)


@dataclass(frozen=True)
class DiskerParams(_Group):
    """Towed offset disk harrow: its own hitch-angle dynamics and a steady pull to the left."""

    draft: float = P(12000.0, "N", "draft (tongue tension) at standstill speed", hi=200000.0)
    draft_per_speed: float = P(4000.0, "N s/m", "increase of draft with speed", hi=100000.0)
    draft_offset: float = P(0.25, "m", "line of draft left of the tractor centreline (offset "
                            "harrow, non-symmetrical loading)", lo=None)
    gang_pull: float = P(187.5, "N", "lateral force of the angled gangs, + = left (the paper: "
                         "the disker pulls to the left; here its offset line of draft does most of it) "
                         "(calibrated, knob 'disker_pull')", "calibrated", lo=None)
    gang_cornering_stiffness: float = P(60e3, "N/rad", "lateral stiffness of the gangs in the soil",
                                        lo_open=True, hi=2e6)
    tongue_length: float = P(4.5, "m", "hitch pin to the gangs' centre of resistance", lo_open=True, hi=20.0)
    front_load_factor: float = P(0.85, "1", "front-axle load relative to no implement (the paper: "
                                 "implements reduce front authority; the value is assumed)", lo_open=True, hi=1.5)
    draft_variation: float = P(0.6, "1", "soil variation of the draft, relative 1-sigma (calibrated, "
                               "knob 'disker_variation')", "calibrated")
    pull_variation: float = P(1.0, "1", "soil variation of the gang pull, relative 1-sigma (calibrated, "
                              "knob 'disker_variation')", "calibrated")
    soil_correlation_length: float = P(4.0, "m", "distance over which soil variation decorrelates",
                                       lo_open=True, hi=1000.0)


@dataclass(frozen=True)
class RipperParams(_Group):
    """Hitched (rigid three-point) 3-shank ripper: soil forces pass straight to the tractor."""

    shank_behind_rear_axle: float = P(1.5, "m", "shanks' centre of resistance behind the rear axle", hi=5.0)
    lateral_force: float = P(375.0, "N", "random lateral soil force on the shanks, 1-sigma (the paper: "
                             "hitched implements pass soil forces to the tractor) (calibrated, "
                             "knob 'ripper_soil')", "calibrated")
    yaw_moment: float = P(375.0, "N m", "random soil yaw moment, 1-sigma (calibrated, "
                          "knob 'ripper_soil')", "calibrated", hi=1e5)
    soil_correlation_length: float = P(2.0, "m", "distance over which the soil forces decorrelate",
                                       lo_open=True, hi=1000.0)
    front_load_factor: float = P(0.8999785367799116, "1", "front-axle load relative to no implement (draft "
                                 "transfers weight to the rear) (calibrated, knob 'ripper_front_load', "
                                 "bounded to 0.6-0.9)", "calibrated", lo_open=True, hi=1.5)


@dataclass(frozen=True)
class HopParams(_Group):
    """Power hop: the tractor bounces on its tyres under draft, front contact varies in time."""

    amplitude: float = P(0.125, "1", "largest fraction of front load lost at the peak of a bounce "
                         "(calibrated, knob 'hop')", "calibrated",
                         hi=0.95)
    center_speed: float = P(2.24, "m/s", "speed at which hop is strongest (11th gear)", lo_open=True)
    speed_width: float = P(0.35, "m/s", "1-sigma width of the hop band in speed", lo_open=True)
    frequency: float = P(1.8, "Hz", "bounce frequency", lo_open=True, hi=20.0)
    irregularity: float = P(0.2, "1", "random part of the bounce, 1-sigma")


@dataclass(frozen=True)
class FieldParams(_Group):
    """The field: side slope, general soil forces and the speed held by the engine and gearbox."""

    roll: float = P(0.0175, "rad", "side-slope roll, 1-sigma (about 1 deg) (calibrated, "
                    "knob 'slope')", "calibrated")
    roll_mean: float = P(0.0, "rad", "mean side slope along the pass, + = left side up", lo=None)
    roll_correlation_length: float = P(25.0, "m", "distance over which the slope changes",
                                       lo_open=True, hi=10000.0)
    lateral_force: float = P(4036.3027932178297, "N", "soil lateral force on the tractor itself, 1-sigma "
                             "at force_reference_speed (calibrated, knob 'soil')", "calibrated")
    force_correlation_length: float = P(3.0, "m", "correlation length of that force", lo_open=True, hi=1000.0)
    force_speed_exponent: float = P(0.35, "1", "growth of that force with speed: its 1-sigma is lateral_force "
                                    "x (V / force_reference_speed)^exponent at nominal speed V (ruts and clods "
                                    "kick the tyres sideways harder the faster the tractor goes) (calibrated, "
                                    "knob 'soil_speed')", "calibrated", hi=2.0)
    force_reference_speed: float = P(1.79, "m/s", "speed at which that force's 1-sigma is lateral_force "
                                     "(9th gear, the middle of the paper's range)", lo_open=True)
    speed_variation: float = P(0.02, "1", "relative 1-sigma of speed about the gear's nominal value")
    speed_time_constant: float = P(4.0, "s", "time constant of the speed variation", lo_open=True, hi=1000.0)


@dataclass(frozen=True)
class GpsParams(_Group):
    """Carrier-phase DGPS position (5 Hz) and multi-antenna attitude (10 Hz) measurements."""

    position_rate: float = P(5.0, "Hz", "position output rate", "paper", lo_open=True, hi=100.0)
    attitude_rate: float = P(10.0, "Hz", "attitude output rate", "paper", lo_open=True, hi=100.0)
    position_noise: float = P(0.01, "m", "white position noise per horizontal axis, RTK fixed",
                              "design", hi=1.0)
    multipath: float = P(0.02, "m", "slowly varying (multipath) error per axis, 1-sigma (calibrated, "
                         "knob 'multipath')", "calibrated", hi=1.0)
    multipath_time_constant: float = P(30.0, "s", "time constant of the multipath error", lo_open=True, hi=10000.0)
    float_noise: float = P(0.05, "m", "white position noise per axis during RTK float", hi=5.0)
    yaw_noise: float = P(0.00175, "rad", "yaw noise (0.1 deg)", "paper", hi=0.5)
    roll_noise: float = P(0.00175, "rad", "roll and pitch noise (0.1 deg)", "paper", hi=0.5)
    speed_noise: float = P(0.02, "m/s", "ground-speed noise", hi=2.0)
    position_latency: float = P(0.08, "s", "valid time to arrival at the host, position", hi=1.0)
    attitude_latency: float = P(0.05, "s", "valid time to arrival at the host, attitude", hi=1.0)
    latency_jitter: float = P(0.005, "s", "uniform +- jitter of the arrival time", hi=0.1)
    dropout_rate: float = P(0.0003, "1/epoch", "probability that an outage starts at an epoch (calibrated: "
                            "set by judgement, reference 0.003; see docs/calibration)", "calibrated", hi=1.0)
    dropout_length: float = P(0.6, "s", "mean outage length", lo_open=True, hi=600.0)
    float_rate: float = P(0.0005, "1/epoch", "probability that RTK float starts at a position epoch",
                          hi=1.0)
    float_length: float = P(8.0, "s", "mean duration of an RTK float episode", lo_open=True, hi=3600.0)
    corrupt_rate: float = P(0.0002, "1/message", "probability that a receiver message reaches the host with "
                            "one flipped bit (line noise) (calibrated: set by judgement, reference 0.002; "
                            "see docs/calibration)", "calibrated", hi=1.0)


@dataclass(frozen=True)
class SimParams:
    """Every parameter of the truth simulator, grouped."""

    vehicle: VehicleParams = dataclasses.field(default_factory=VehicleParams)
    steering: SteeringParams = dataclasses.field(default_factory=SteeringParams)
    sensor: WheelSensorParams = dataclasses.field(default_factory=WheelSensorParams)
    disker: DiskerParams = dataclasses.field(default_factory=DiskerParams)
    ripper: RipperParams = dataclasses.field(default_factory=RipperParams)
    hop: HopParams = dataclasses.field(default_factory=HopParams)
    field: FieldParams = dataclasses.field(default_factory=FieldParams)
    gps: GpsParams = dataclasses.field(default_factory=GpsParams)
    dt: float = P(0.01, "s", "integration step (RK4)", lo_open=True, hi=0.01)

    def __post_init__(self) -> None:
        if not (isinstance(self.dt, (int, float)) and math.isfinite(self.dt) and 0 < self.dt <= 0.01):
            raise SimulatorConfigError(f"SimParams.dt must be in (0, 0.01] s, got {self.dt!r}")
        v = self.vehicle
        if v.cg_to_front_axle >= v.wheelbase:
            raise SimulatorConfigError(f"vehicle.cg_to_front_axle ({v.cg_to_front_axle} m) must be "
                                       f"shorter than the wheelbase ({v.wheelbase} m)")
        s = self.sensor
        if s.center_counts - s.counts_at_stop * (1 + abs(s.cubic)) < 0 or \
                s.center_counts + s.counts_at_stop * (1 + abs(s.cubic)) > 255:
            raise SimulatorConfigError("sensor: centre +- counts at the stops must stay within 0..255")
        # ticks of the 20/10/5 Hz channels must fall on the integration grid
        for name, rate in (("sensor.rate", s.rate), ("gps.position_rate", self.gps.position_rate),
                           ("gps.attitude_rate", self.gps.attitude_rate)):
            ratio = 1.0 / (rate * self.dt)
            if abs(ratio - round(ratio)) > 1e-9:
                raise SimulatorConfigError(f"{name} = {rate} Hz is not a whole number of {self.dt} s steps")

    def to_dict(self) -> dict[str, Any]:
        """Nested plain dict (JSON-serialisable), e.g. for a pass log's metadata."""
        out: dict[str, Any] = {g: getattr(self, g).to_dict() for g in GROUPS}
        out["dt"] = self.dt
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "SimParams":
        """Inverse of :meth:`to_dict`; missing entries take their defaults, unknown ones are refused."""
        if not isinstance(d, Mapping):
            raise SimulatorConfigError("simulator parameters must be a mapping of groups")
        unknown = set(d) - set(GROUPS) - {"dt"}
        if unknown:
            raise SimulatorConfigError(f"unknown parameter group(s) {sorted(unknown)}; "
                                       f"groups are {list(GROUPS)} and 'dt'")
        kw: dict[str, Any] = {}
        for g, typ in GROUPS.items():
            if g in d:
                known = {f.name for f in dataclasses.fields(typ)}
                bad = set(d[g]) - known
                if bad:
                    raise SimulatorConfigError(f"unknown parameter(s) {sorted(bad)} in group {g!r}; "
                                               f"known: {sorted(known)}")
                kw[g] = typ(**d[g])
        if "dt" in d:
            kw["dt"] = d["dt"]
        return cls(**kw)

    def with_overrides(self, overrides: Mapping[str, float]) -> "SimParams":
        """Copy with ``{"group.name": value}`` overrides, validated."""
        d = self.to_dict()
        for key, value in overrides.items():
            group, _, name = key.partition(".")
            if key == "dt":
                d["dt"] = value
                continue
            if group not in GROUPS or name not in d[group]:
                raise SimulatorConfigError(f"unknown parameter {key!r}; use 'group.name', see `hil params`")
            d[group][name] = value
        return SimParams.from_dict(d)


#: The parameter groups of :class:`SimParams` (attribute name -> dataclass), in the order they are listed.
GROUPS: dict[str, type] = {"vehicle": VehicleParams, "steering": SteeringParams,
                            "sensor": WheelSensorParams, "disker": DiskerParams,
                            "ripper": RipperParams, "hop": HopParams, "field": FieldParams,
                            "gps": GpsParams}


def parameter_table(params: SimParams | None = None) -> list[dict[str, Any]]:
    """Rows ``{name, value, unit, source, doc}`` for every parameter (for docs and ``hil params``)."""
    params = params or SimParams()
    rows = []
    for g, typ in GROUPS.items():
        grp = getattr(params, g)
        for f in dataclasses.fields(typ):
            rows.append({"name": f"{g}.{f.name}", "value": getattr(grp, f.name),
                         "unit": f.metadata["unit"], "source": f.metadata["source"],
                         "doc": f.metadata["doc"]})
    dt = next(f for f in dataclasses.fields(SimParams) if f.name == "dt")
    rows.append({"name": "dt", "value": params.dt, "unit": "s", "source": "assumption",
                 "doc": dt.metadata["doc"]})
    return rows


def parameter_markdown(params: SimParams | None = None) -> str:
    """The parameter table as Markdown (``docs/simulator_parameters.md`` is this, kept in sync by a test)."""
    lines = ["# Truth simulator parameters", "",
             "Generated by `hil params --markdown`; a test keeps this file equal to the code's defaults.",
             "Source: `paper` = the 1997 paper / DESIGN section 2, `design` = DESIGN section 5,",
             "`calibrated` = set by `hil calibrate` against the paper's Table 2 (docs/calibration),",
             "`assumption` = a plausible value for a JD 7800-class tractor that nobody measured.", "",
             "| parameter | default | unit | source | meaning |", "|---|---:|---|---|---|"]
    for r in parameter_table(params):
        lines.append(f"| `{r['name']}` | {r['value']:.6g} | {r['unit']} | {r['source']} | {r['doc']} |")
    return "\n".join(lines) + "\n"
