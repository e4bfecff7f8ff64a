"""Checks of the numbers a user or a file gives, each refusal one line in the caller's error class.

Settings objects of every package check their numbers here instead of each keeping its own helper,
so that every refusal reads alike::

    wheelbase must be a finite number > 0 m, got -1.0
    IsobusDriverConfig.timeout must be a finite number > 0 s, got nan
    horizon must be an integer >= 1, got 2.5
    lever_arm must be 3 finite numbers m, got (0.0, 1.0)

A number is an ``int`` or ``float`` (numpy's scalars included), never a ``bool``; NaN and the
infinities are refused. The error class is the caller's (a subclass of :class:`ValueError` from its
package's errors module), so callers catch what they always caught.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable

__all__ = ["finite", "positive", "finite_tuple", "finite_or_none"]


def _label(name: str, where: str) -> str:
    return f"{where}.{name}" if where else name


def _wanted(integer: bool, lo: float | None, hi: float | None, lo_open: bool, hi_open: bool, unit: str,
            noun: str = "") -> str:
    what = noun or ("an integer" if integer else "a finite number")
    bounds = []
    if lo is not None:
        bounds.append(f"{'>' if lo_open else '>='} {lo:g}")
    if hi is not None:
        bounds.append(f"{'<' if hi_open else '<='} {hi:g}")
    return " ".join([what, " and ".join(bounds), unit]).replace("  ", " ").strip()


def _is_number(value: object, integer: bool) -> bool:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral if integer else numbers.Real):
        return False
    return integer or math.isfinite(value)  # type: ignore[arg-type]


def _within(v: float, lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> bool:
    if lo is not None and (v <= lo if lo_open else v < lo):
        return False
    return hi is None or (v < hi if hi_open else v <= hi)


def finite(value: object, name: str, *, lo: float | None = None, hi: float | None = None, lo_open: bool = False,
           hi_open: bool = False, integer: bool = False, unit: str = "", where: str = "", noun: str = "",
           error: type[Exception] = ValueError, fix: str = "") -> float:
    """``value`` as a float (an int with ``integer=True``) if it is a finite number within the bounds.

    Parameters
    ----------
    value : object
        What was given.
    name : str
        The setting, key or option as the user knows it (``"wheelbase"``, ``"model.json: dt"``).
    lo, hi : float, optional
        Bounds, in the value's unit; inclusive unless ``lo_open`` / ``hi_open``.
    lo_open, hi_open : bool
        The bound itself is refused (``lo=0, lo_open=True`` is ``> 0``).
    integer : bool
        Only an integer is accepted (``2.0`` is not one).
    unit : str
        The value's unit, named in the message (``"m"``, ``"rad/s"``).
    where : str
        The object that owns the setting (``"IsobusDriverConfig"``), prefixed to ``name`` with a dot.
    noun : str
        What the value is, in the message (default ``"a finite number"``, ``"an integer"``; e.g.
        ``"a finite sample time"``: ``"dt must be a finite sample time > 0 s, got 0"``).
    error : type
        The exception raised, the caller's (its package's subclass of :class:`ValueError`).
    fix : str
        What to do, appended to the message after ``"; "``.

    Returns
    -------
    float or int
        The value, as a builtin ``float`` (``int`` with ``integer=True``).

    Raises
    ------
    error
        One line: ``"<where>.<name> must be <noun> <bounds> <unit>, got <value>[; <fix>]"``.
    """
    if _is_number(value, integer) and _within(value, lo, hi, lo_open, hi_open):  # type: ignore[arg-type]
        return int(value) if integer else float(value)  # type: ignore[arg-type, call-overload]
    wanted = _wanted(integer, lo, hi, lo_open, hi_open, unit, noun)
    message = f"{_label(name, where)} must be {wanted}, got {value!r:.60}"
    raise error(message + (f"; {fix}" if fix else ""))


def positive(value: object, name: str, *, unit: str = "", where: str = "", allow_zero: bool = False,
             noun: str = "", error: type[Exception] = ValueError, fix: str = "") -> float:
    """``value`` as a float if it is a finite number > 0 (>= 0 with ``allow_zero``).

    The parameters are those of :func:`finite`; the message reads ``"... must be a finite number > 0 s, got ..."``.
    """
    return finite(value, name, lo=0.0, lo_open=not allow_zero, unit=unit, where=where, noun=noun, error=error,
                  fix=fix)


def finite_tuple(values: object, name: str, *, n: int | None = None, lo: float | None = None,
                 hi: float | None = None, lo_open: bool = False, unit: str = "", where: str = "",
                 error: type[Exception] = ValueError, fix: str = "") -> tuple[float, ...]:
    """``values`` as a tuple of floats if it is a sequence of ``n`` (any number if ``None``, at least one)
    finite numbers within the bounds.

    The parameters are those of :func:`finite`; the message names the whole sequence
    (``"lever_arm must be 3 finite numbers m, got (0.0, 1.0)"``).

    Returns
    -------
    tuple of float
        The values.
    """
    items = tuple(values) if isinstance(values, Iterable) and not isinstance(values, (str, bytes)) else None
    if items is not None and (len(items) == n if n is not None else len(items) > 0) and all(
            _is_number(v, False) and _within(v, lo, hi, lo_open, False) for v in items):  # type: ignore[arg-type]
        return tuple(float(v) for v in items)  # type: ignore[arg-type]
    count = f"{n} " if n is not None else ""
    wanted = _wanted(False, lo, hi, lo_open, False, unit).replace("a finite number", f"{count}finite numbers", 1)
    message = f"{_label(name, where)} must be {wanted}, got {values!r:.80}"
    raise error(message + (f"; {fix}" if fix else ""))


def finite_or_none(value: float) -> float | None:
    """``value`` as a float for a file's record, None where it is not finite (JSON has no NaN or infinity: an
    unstable loop's cost or margin is recorded as unknown)."""
    v = float(value)
    return v if math.isfinite(v) else None
