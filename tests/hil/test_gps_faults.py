"""The receivers' fault layer (hil.devices.gps_faults): outages, RTK-float windows and bit flips decided in
one place, on its own and in an emulated receiver read back by the GNSS reader."""

from __future__ import annotations

import pytest

from gnss.messages import Gga
from gnss.reader import StreamDecoder
from gnss.field import FieldGeometry
from hil.devices.gps_faults import RTK_FLOAT_QUALITY, ReceiverFaults
from hil.devices.plant import SimulatedTractor
from hil.devices.receivers import PositionReceiver
from hil.errors import SimulatorConfigError
from hil.links.clock import VirtualClock
from hil.links.memory import memory_link_pair
from hil.truth.conditions import condition_for


def test_outages_are_the_truths_dropouts_and_the_injected_windows():
    f = ReceiverFaults([False, True, False, False], [-1.0] * 4)
    f.outages.append((0.6, 0.8))
    assert [f.drops(k, 0.2 * k) for k in range(4)] == [False, True, False, True]


def test_rtk_float_windows_report_quality_5_inside_only():
    f = ReceiverFaults([False] * 3, [-1.0] * 3)
    f.rtk_float.append((1.0, 2.0))
    assert [f.quality(4, t) for t in (0.99, 1.0, 1.99, 2.0)] == [4, RTK_FLOAT_QUALITY, RTK_FLOAT_QUALITY, 4]


def test_damage_flips_one_bit_where_the_truth_drew_it_and_counts():
    data = bytes(range(100))
    f = ReceiverFaults([False, False], [-1.0, 0.505])
    assert f.damage(0, data) == data and f.corrupted == 0
    out = f.damage(1, data)
    diff = [i for i, (a, b) in enumerate(zip(data, out)) if a != b]
    assert diff == [50] and bin(data[50] ^ out[50]).count("1") == 1 and f.corrupted == 1


def test_draws_of_different_lengths_are_refused():
    with pytest.raises(SimulatorConfigError, match="one dropout and one corruption draw per epoch"):
        ReceiverFaults([False] * 3, [-1.0] * 2)


def test_a_receiver_applies_its_windows_and_the_reader_refuses_what_it_corrupted():
    plant = SimulatedTractor(condition_for("none", 1.79), 12.0, 5)
    clock = VirtualClock()
    host, dev = memory_link_pair(clock, names=("host", "position"))
    rx = PositionReceiver(plant, dev, FieldGeometry())
    rx.faults.outages.append((3.0, 5.0))
    rx.faults.rtk_float.append((6.0, 8.0))
    assert rx.suppressed is rx.faults.outages and rx.downgraded is rx.faults.rtk_float   # the bench's names
    dec, got, t = StreamDecoder(), [], 0.0
    while t < 10.0:
        nxt = min(t + 0.05, rx.next_wakeup())
        plant.advance(nxt - t)
        clock.advance_to(nxt)
        t = nxt
        if rx.next_wakeup() <= t + 1e-9:
            rx.step(t)
        got += dec.feed(host.read(1 << 16))
    got += dec.flush()
    utc0 = FieldGeometry().utc_start
    gga = [(r.message.time - utc0, r.message.quality) for r in got if isinstance(r.message, Gga)]
    assert gga and not any(3.0 <= tv < 5.0 for tv, _ in gga)                       # the outage
    assert {q for tv, q in gga if 6.0 <= tv < 8.0} == {RTK_FLOAT_QUALITY}           # the float window
    assert any(q == 4 for tv, q in gga if tv < 3.0 or tv >= 8.0)                   # fixed outside it
    assert dec.stats.n_errors <= rx.corrupted == rx.faults.corrupted               # refused, never accepted
