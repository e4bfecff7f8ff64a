"""Command-line conventions shared by the toolkit's commands (``gnss``, ``identification``, ``design``, ``hil``).

One parser class for every command and sub-command:

- a mistyped sub-command, choice or option gets the closest spellings
  (``hil comission`` -> ``did you mean: commission?``);
- an option's old spelling stays accepted but is left out of the usage line and shown
  in the help as deprecated (:func:`add_option`);
- an option's default is shown after its help as the user would type it (``(default: 0.35)``,
  ``(0 = none; default: 0.1 0.05 0)``) unless the help already names its default
  (:func:`shown_default`);

and the value types the commands share: seed lists (``0-19``, ``0,1,2``, ``0-4,7``) and
conditions (``all`` or ``IMPLEMENT:SPEED,...``).

This module imports nothing of the project (it sits in :mod:`autosteer`, below every package).
"""

from __future__ import annotations

import argparse
import copy
import difflib
import math
import re
from collections import Counter
from typing import Any, Sequence

__all__ = ["Parser", "Formatter", "RawDescriptionFormatter", "add_option", "add_deprecated_option",
           "deprecated_strings", "shown_default", "suggestion", "option_names", "arguments", "subcommands",
           "help_text", "seed_list", "seeds_or_count", "resolve_seeds", "condition_pairs", "MAX_SEEDS",
           "MAX_SEEDS_PER_RANGE", "MAX_SEED"]

#: Largest seed accepted (numpy's SeedSequence takes any non-negative integer; this keeps seeds in 32 bits).
MAX_SEED = 2 ** 31
#: Most seeds in one option.
MAX_SEEDS = 10_000
#: Most seeds one range may name (a campaign of more is a typo, e.g. 0-10000 for 0-100).
MAX_SEEDS_PER_RANGE = 1000


def deprecated_strings(action: argparse.Action) -> tuple[str, ...]:
    """The old spellings of an option (accepted, hidden from the usage line), set by :func:`add_option`
    and :func:`add_deprecated_option`."""
    return tuple(getattr(action, "deprecated_strings", ())) + tuple(getattr(action, "deprecated_aliases", ()))


def add_option(parser: argparse.ArgumentParser, name: str, *old: str, **kwargs: Any) -> argparse.Action:
    """``parser.add_argument(name, *old, **kwargs)`` with ``old`` marked as deprecated spellings of ``name``.

    The old spellings keep working; the help shows ``name`` only, with the old ones listed as
    deprecated after its text.
    """
    action = parser.add_argument(name, *old, **kwargs)
    action.deprecated_strings = tuple(old)  # type: ignore[attr-defined]
    return action


def add_deprecated_option(parser: argparse.ArgumentParser, old: str, canonical: argparse.Action,
                          **kwargs: Any) -> argparse.Action:
    """An old spelling that takes its value another way than ``canonical`` (e.g. degrees where the option now
    takes radians: give the converting ``type``): a hidden option storing into ``canonical``'s destination,
    named as deprecated in ``canonical``'s help."""
    action = parser.add_argument(old, dest=canonical.dest, default=argparse.SUPPRESS, help=argparse.SUPPRESS,
                                 **kwargs)
    action.canonical = canonical.option_strings[0]  # type: ignore[attr-defined]
    canonical.deprecated_aliases = (*getattr(canonical, "deprecated_aliases", ()), old)  # type: ignore[attr-defined]
    return action


def shown_default(action: argparse.Action) -> str | None:
    """The default of ``action`` as a user would type it on the command line, or None when there is none to
    show: no default (None), a flag (its off state is the default), an empty list, or a suppressed one.

    Floats are printed with up to six significant digits (``0.35``, ``100000``); the values of an option
    that takes several arguments are separated by spaces, those of a single argument parsed into a tuple
    (``FWD,LEFT,UP``) by commas.
    """
    d = action.default
    if d is None or d is argparse.SUPPRESS or action.nargs == 0 or isinstance(d, bool) \
            or (isinstance(d, (list, tuple)) and not d):
        return None

    def one(v: object) -> str:
        return format(v, "g") if isinstance(v, float) else str(v)

    if isinstance(d, (list, tuple)):
        return (" " if action.nargs not in (None, argparse.OPTIONAL) else ",").join(one(v) for v in d)
    return one(d)


class Formatter(argparse.HelpFormatter):
    """Help without the deprecated spellings in the option column (they are named after the help text), and
    with each option's default after its help when the help does not name it (:func:`shown_default`)."""

    def _format_action_invocation(self, action: argparse.Action) -> str:
        old = deprecated_strings(action)
        if any(s in old for s in action.option_strings):
            action = copy.copy(action)
            action.option_strings = [s for s in action.option_strings if s not in old]
        return super()._format_action_invocation(action)

    def _expand_help(self, action: argparse.Action) -> str:
        text = super()._expand_help(action)
        default = shown_default(action)
        if default is not None and "default" not in text.lower():
            text = f"{text[:-1]}; default: {default})" if text.endswith(")") else f"{text} (default: {default})"
        old = deprecated_strings(action)
        return f"{text} (deprecated spelling: {', '.join(old)})" if old else text


class RawDescriptionFormatter(Formatter, argparse.RawDescriptionHelpFormatter):
    """:class:`Formatter` that keeps the description's line breaks."""


_INVALID_CHOICE = re.compile(r"invalid choice: '(?P<value>[^']*)' \(choose from (?P<choices>.*)\)")


def _close(word: str, candidates: Sequence[str]) -> list[str]:
    """The candidates closest to ``word`` (similarity >= 0.6, within 0.05 of the best), best first; the
    leading dashes of options are left out of the comparison, so that ``--`` alone matches nothing."""
    def score(c: str) -> float:
        return difflib.SequenceMatcher(None, word.lstrip("-"), c.lstrip("-")).ratio()
    scored = sorted(((score(c), c) for c in candidates), key=lambda sc: -sc[0])
    best = scored[0][0] if scored else 0.0
    return [c for sc, c in scored[:3] if sc >= 0.6 and sc >= best - 0.05]


def arguments(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The options and positionals of ``parser`` (its help option included), in the order they were added;
    its sub-commands are :func:`subcommands`. (argparse keeps both in one private list.)"""
    return [a for a in parser._actions if not isinstance(a, argparse._SubParsersAction)]


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The sub-command parsers of ``parser`` by name; empty when it has none."""
    return {name: sub for a in parser._actions if isinstance(a, argparse._SubParsersAction)
            for name, sub in a.choices.items()}


def help_text(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    """The help of ``action`` as ``parser``'s ``--help`` prints it, before line wrapping (with its default and
    old spellings, :class:`Formatter`)."""
    return parser._get_formatter()._expand_help(action)


def option_names(parser: argparse.ArgumentParser, namespace: argparse.Namespace | None = None) -> dict[str, str]:
    """Every option string of ``parser`` and of the sub-parsers the namespace chose -> its canonical spelling."""
    names: dict[str, str] = {}
    for action in parser._actions:
        for s in action.option_strings:
            names[s] = getattr(action, "canonical", action.option_strings[0])
        if isinstance(action, argparse._SubParsersAction) and namespace is not None:
            chosen = getattr(namespace, action.dest, None) if action.dest is not argparse.SUPPRESS else None
            sub = action.choices.get(chosen) if isinstance(chosen, str) else None
            if sub is not None:
                names.update(option_names(sub, namespace))
    return names


def suggestion(message: str, options: dict[str, str] | None = None) -> str:
    """``"; did you mean: ...?"`` for an argparse error ``message`` (an invalid choice, unrecognised
    options among ``options``: spelling -> canonical spelling), or ``""`` when nothing is close."""
    m = _INVALID_CHOICE.search(message)
    if m:
        choices = re.findall(r"'([^']*)'", m.group("choices"))
        close = _close(m.group("value"), choices)
        return f"; did you mean: {', '.join(close)}?" if close else ""
    if message.startswith("unrecognized arguments:") and options:
        hints = []
        for token in message.split(":", 1)[1].split():
            name = token.split("=", 1)[0]
            close = list(dict.fromkeys(options[c] for c in _close(name, list(options)))) if name[:1] == "-" else []
            if close:
                hints.append(f"{name} -> {' or '.join(close)}")
        if len(hints) == 1:
            return f"; did you mean: {hints[0].split(' -> ', 1)[1]}?"
        if hints:
            return f"; did you mean: {'; '.join(hints)}?"
    return ""


class Parser(argparse.ArgumentParser):
    """The toolkit's argument parser: close-match suggestions in usage errors, deprecated spellings hidden.

    Sub-parsers made with ``add_subparsers().add_parser`` are of the same class (argparse makes them
    of the parent's class) and use the same help formatter unless another is given.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", Formatter)
        super().__init__(*args, **kwargs)
        self._options_for_hint: dict[str, str] | None = None

    def parse_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                   namespace: argparse.Namespace | None = None) -> argparse.Namespace:
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            self._options_for_hint = option_names(self, ns)
            self.error(f"unrecognized arguments: {' '.join(extras)}")
        return ns

    def hint(self, message: str) -> str:
        """The closest spellings for a usage error's ``message`` (``"; did you mean: ...?"``), or ``""``."""
        return suggestion(message, self._options_for_hint or option_names(self))

    def error(self, message: str) -> None:  # type: ignore[override]
        super().error(self.without_old_spellings(message) + self.hint(message))

    def without_old_spellings(self, message: str) -> str:
        """``message`` with an option named by its shown spellings only (argparse names a missing required
        option by all its strings, ``--models/--model``)."""
        for action in self._actions:
            old = deprecated_strings(action)
            shown = [s for s in action.option_strings if s not in old]
            if shown and len(shown) < len(action.option_strings):
                message = message.replace("/".join(action.option_strings), "/".join(shown))
        return message


# --- shared value types -------------------------------------------------------------------------------


def seed_list(text: str) -> tuple[int, ...]:
    """argparse type: seeds as ``0-19``, ``3``, ``0,1,2`` or ``0-4,7`` (ranges inclusive, in the order given).

    Raises
    ------
    argparse.ArgumentTypeError
        If a part is not an integer or a range ``FIRST-LAST`` with ``0 <= FIRST <= LAST <= 2**31``,
        a range holds more than :data:`MAX_SEEDS_PER_RANGE` seeds, all more than :data:`MAX_SEEDS`,
        or a seed is named twice.
    """
    seeds: list[int] = []
    for part in text.split(","):
        lo, sep, hi = part.strip().partition("-")
        try:
            a = int(lo)
            b = int(hi) if sep else a
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected seeds like 0-19, 3 or 0-4,7, got {text!r}") from None
        if not 0 <= a <= b <= MAX_SEED:
            raise argparse.ArgumentTypeError(f"expected seeds 0 <= FIRST <= LAST <= {MAX_SEED}, got {part!r}")
        if b - a >= MAX_SEEDS_PER_RANGE:
            raise argparse.ArgumentTypeError(f"at most {MAX_SEEDS_PER_RANGE} seeds in a range, got {part!r}")
        seeds.extend(range(a, b + 1))
        if len(seeds) > MAX_SEEDS:
            raise argparse.ArgumentTypeError(f"at most {MAX_SEEDS} seeds, got more in {text[:80]!r}")
    twice = sorted(s for s, n in Counter(seeds).items() if n > 1)
    if twice:
        raise argparse.ArgumentTypeError(f"seed(s) {twice} named more than once in {text!r}")
    return tuple(seeds)


def seeds_or_count(text: str) -> tuple[int, ...] | int:
    """argparse type of an option that took a count before it took seeds: a bare integer ``N`` is the
    old count (an ``int``: ``N`` seeds from the first seed), anything else :func:`seed_list`
    (``0-1``, ``0,1``; one seed ``7`` as ``7-7``)."""
    if text.strip().isdigit():
        n = int(text)
        if not 0 <= n <= MAX_SEEDS_PER_RANGE:
            raise argparse.ArgumentTypeError(f"expected a count of seeds from 0 to {MAX_SEEDS_PER_RANGE} or seeds "
                                             f"like 0-19 or 0,1,2, got {text!r}")
        return n
    return seed_list(text)


def passes_per_speed(text: str) -> int | tuple[int, ...]:
    """argparse type of the identification passes: one count for every speed (``2``) or a count per speed,
    comma-separated (``1,2,3``), each 1-10."""
    parts = text.split(",")
    if not all(p.strip().isdigit() and 1 <= int(p) <= 10 for p in parts):
        raise argparse.ArgumentTypeError(f"expected a count of passes 1-10, or one per speed like 1,2,3, got "
                                         f"{text!r}")
    return int(parts[0]) if len(parts) == 1 else tuple(int(p) for p in parts)


def resolve_seeds(value: tuple[int, ...] | int, first: int | None, default_first: int,
                  option: str = "--seeds", first_option: str = "--seed") -> tuple[int, ...]:
    """The seeds of ``value`` (from :func:`seeds_or_count`): a count runs from ``first`` (``default_first``
    when not given); a list is taken as given, and refused beside an explicit ``first``.

    Raises
    ------
    ValueError
        If seeds are listed and a first seed is given too (it would be ignored).
    """
    if isinstance(value, int):
        start = default_first if first is None else first
        return tuple(range(start, start + value))
    if first is not None:
        raise ValueError(f"{first_option} {first} is the first seed of a count ({option} N); with the seeds "
                         f"listed ({option} {','.join(map(str, value[:5]))}{',...' if len(value) > 5 else ''}) "
                         f"drop {first_option}")
    return tuple(value)


def condition_pairs(text: str) -> list[tuple[str, float]] | None:
    """argparse type: conditions as ``all`` (None) or ``IMPLEMENT:SPEED[,IMPLEMENT:SPEED...]`` (speed in m/s).

    Raises
    ------
    argparse.ArgumentTypeError
        If a part is not ``NAME:SPEED`` with a finite speed > 0.
    """
    if text.strip() == "all":
        return None
    out = []
    for part in text.split(","):
        name, sep, speed = part.strip().partition(":")
        try:
            v = float(speed)
        except ValueError:
            v = math.nan
        if not sep or not name or not (math.isfinite(v) and v > 0):
            raise argparse.ArgumentTypeError(f"expected 'all' or IMPLEMENT:SPEED[,...] with the speed in m/s "
                                             f"(e.g. none:1.79,disker:2.91), got {text!r}")
        out.append((name, v))
    return out
