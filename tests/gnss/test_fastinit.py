"""gnss.fastinit builds records equal to what their __init__ builds; the XOR checksum is the byte-wise one."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import reduce
from operator import xor

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gnss.fastinit import positional_maker
from gnss.frontend import NavSolution
from gnss.integrity import FixQuality, Integrity, IntegrityState
from gnss.messages import Avr, Gga, Vtg
from gnss.nmea import nmea_checksum
from gnss.reader import Received


@dataclass(frozen=True)
class _Plain:
    a: int
    b: float = 1.0


@dataclass(frozen=True)
class _Checked:
    a: int

    def __post_init__(self) -> None:
        if self.a < 0:
            raise ValueError("a < 0")


@pytest.mark.parametrize("cls, values", [
    (Gga, ("GP", 43210.2, 0.65, -2.13, 4, 14, 0.8, 33.1, 0.0, 1.0, 1)),
    (Vtg, ("GP", 0.35, None, 1.79, "D")),
    (Avr, (43210.2, 0.35, 0.001, -0.02, 1.5, 3, 1.6, 12)),
    (Received, (Vtg("GP", 0.1, None, 1.0, "D"), 2.5, b"$GPVTG")),
    (NavSolution, (1.0, 0.9, 0.95, 1.0, 2.0, 3.0, 0.1, 0.0, 0.0, 0.0, 1.8, 0.1, 1.7, FixQuality.RTK_FIXED,
                   Integrity(IntegrityState.RTK_FIXED, "RTK fixed"))),
    (_Plain, (3, 2.0)),
])
def test_made_record_is_the_constructed_record(cls, values):
    made, built = positional_maker(cls)(*values), cls(*values)
    assert type(made) is cls and made == built and repr(made) == repr(built) and hash(made) == hash(built)
    with pytest.raises(AttributeError):
        made.__setattr__(next(iter(cls.__dataclass_fields__)), 0)   # still frozen


def test_classes_whose_init_does_more_than_store_are_refused():
    with pytest.raises(TypeError, match="only a frozen dataclass"):
        positional_maker(_Checked)

    @dataclass
    class Mutable:
        a: int
    with pytest.raises(TypeError, match="only a frozen dataclass"):
        positional_maker(Mutable)

    @dataclass(frozen=True)
    class NotInInit:
        a: int
        b: list = field(default_factory=list, init=False)
    with pytest.raises(TypeError):
        positional_maker(NotInInit)
    with pytest.raises(TypeError, match="dataclass type"):
        positional_maker(math)


@given(body=st.binary(max_size=300))
def test_checksum_is_the_xor_of_every_byte(body):
    assert nmea_checksum(body) == reduce(xor, body, 0)
