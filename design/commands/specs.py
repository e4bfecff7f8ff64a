"""Command-line options shared by ``design robust`` and ``design mpc``: weights from specifications.

    --weights auto [--disk-margin A] [--delay-reserve S] [--actuator-rate R] [--tracking-errors E E E]
                   [--latency S [S S] | --latency-from-logs LOGS...] [--validate-on MODELS...]
                   [--scale-range LO HI] [--scan N] [--search-steps N]

``--weights explicit`` (the default) designs with ``--output-max/--u-max/--integral-max`` as given and,
when a latency is known, reports the specifications it meets without enforcing them.
"""

from __future__ import annotations

import argparse
import sys
from typing import Callable

from design.synthesis.autotune import SearchOptions
from design.laws.disturbance import DisturbanceSpec
from design.core.errors import DesignInputError
from design.core.noise import MEASUREMENT_NOISE
from design.synthesis.recipes import WEIGHT_MODES, WeightSearch
from design.synthesis.specs import Specifications


def parse_past(text: str) -> int | None:
    """``--past``: ``auto`` (None) or an integer >= 1."""
    if text == "auto":
        return None
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected 'auto' or an integer >= 1, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected 'auto' or an integer >= 1, got {text!r}")
    return v


def add_spec_arguments(p: argparse.ArgumentParser, number: Callable[[str], float]) -> None:
    """Register the weights mode, the specifications and the search options on ``p``."""
    p.add_argument("--weights", choices=WEIGHT_MODES, default="explicit",
                   help="explicit: --output-max/--u-max/--integral-max as given; auto: the most aggressive weights "
                        "that meet the specifications below on every model")
    p.add_argument("--disk-margin", type=number, default=Specifications.disk_margin,
                   help="smallest balanced disk margin alpha at the plant input, with the latency in the loop "
                        "(dimensionless, 0 < alpha < 2)")
    p.add_argument("--delay-reserve", type=number, default=Specifications.delay_reserve,
                   help="extra plant-input delay tolerated beyond the latency, s")
    p.add_argument("--actuator-rate", type=number, default=None,
                   help="actuator's steering-rate limit, rad/s (default: --command-limit / --rate-limit): the peak "
                        "command from --tracking-errors must stay within it")
    p.add_argument("--tracking-errors", type=number, nargs="+", default=list(Specifications.initial_errors),
                   help="tracking-error half-widths whose peak command must stay within the actuator rate, model "
                        "units (y/V s, psi/V rad s/m, delta rad)")
    p.add_argument("--latency", type=number, nargs="+", default=None,
                   help="measurement latency per output, s (one value: cross-track and heading, wheel angle 0)")
    p.add_argument("--latency-from-logs", nargs="+", default=None,
                   help="pass logs (files or directories) whose recorded latency the models do not hold")
    p.add_argument("--validate-on", nargs="+", default=[],
                   help="further models (e.g. of a higher order) the specifications must also hold on")
    p.add_argument("--scale-range", type=number, nargs=2, default=[SearchOptions.low, SearchOptions.high],
                   metavar=("LOW", "HIGH"), help="aggressiveness scales searched")
    p.add_argument("--scan", type=int, default=SearchOptions.scan, help="scales scanned before the bisection")
    p.add_argument("--search-steps", type=int, default=SearchOptions.steps, help="bisection steps after the scan")
    p.add_argument("--strict-specifications", action="store_true",
                   help="refuse when no weights meet the specifications (default: relax them in the stated order, "
                        "delay reserve, disk margin, peak command, and say so)")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")


def add_noise_argument(p: argparse.ArgumentParser, what: str) -> None:
    """``--measurement-noise POSITION HEADING ANGLE``: the sensors' 1-sigma of ``what`` noise check
    (:mod:`design.core.noise`)."""
    p.add_argument("--measurement-noise", nargs=3, type=float, metavar=("POSITION", "HEADING", "ANGLE"),
                   default=list(MEASUREMENT_NOISE),
                   help=f"1-sigma of the sensors for {what} noise check: position m, heading rad, wheel angle rad "
                        "(default: %(default)s; the valve test's commissioning.json measures the wheel angle's as "
                        "valve.angle_noise)")


def add_disturbance_arguments(p: argparse.ArgumentParser, number: Callable[[str], float], what: str) -> None:
    """``--disturbance-estimate on|off``, ``--disturbance-tau`` and ``--estimate-tau`` (design.laws.disturbance)."""
    p.add_argument("--disturbance-estimate", choices=("on", "off"), default="off",
                   help=f"estimate the soil's pull from the one-step prediction error and {what} "
                        "(design.laws.disturbance; docs/disturbance_estimate.md)")
    p.add_argument("--disturbance-tau", type=number, default=DisturbanceSpec.tau_d,
                   help="correlation time of the disturbance, s")
    p.add_argument("--estimate-tau", type=number, default=DisturbanceSpec.tau_f,
                   help="time constant of the disturbance estimate's filter, s")


def weight_search_of(args: argparse.Namespace) -> WeightSearch:
    """The :class:`~design.synthesis.recipes.WeightSearch` of the options."""
    return WeightSearch(args.weights, args.disk_margin, args.delay_reserve, args.actuator_rate,
                        tuple(args.tracking_errors), None if args.latency is None else tuple(args.latency),
                        tuple(args.latency_from_logs or ()),
                        SearchOptions(args.scale_range[0], args.scale_range[1], args.scan, args.search_steps,
                                      relax=not args.strict_specifications))


def disturbance_of(args: argparse.Namespace) -> DisturbanceSpec | None:
    """The disturbance estimate of the options (None: off)."""
    return DisturbanceSpec(args.disturbance_tau, args.estimate_tau) if args.disturbance_estimate == "on" else None


def warn_relaxed(record: dict | None) -> None:
    """One line on stderr (even with ``--quiet``) when the search relaxed the specifications."""
    if record and record.get("relaxed"):
        print("warning: no weights met the stated specifications; relaxed, in order: " + "; ".join(record["relaxed"])
              + " (recorded in the controller file's design.auto_weights)", file=sys.stderr, flush=True)


def progress_of(args: argparse.Namespace) -> Callable[[str], None] | None:
    """Progress lines on stderr unless ``--quiet``."""
    if args.quiet:
        return None
    return lambda line: print(line, file=sys.stderr, flush=True)



def refuse_mixed(args: argparse.Namespace) -> None:
    """``--weights auto`` with an explicit ``--output-max/--u-max/--integral-max`` is refused (never silently
    ignored)."""
    names = {"y_max": "--output-max", "u_max": "--u-max", "i_max": "--integral-max"}
    given = [option for dest, option in names.items() if getattr(args, dest) is not None]
    if args.weights == "auto" and given:
        raise DesignInputError(f"--weights auto chooses the weights itself, but {', '.join(given)} were given; "
                               "drop them, or use --weights explicit")
