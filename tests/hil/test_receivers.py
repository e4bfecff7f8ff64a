"""The emulated receivers: bytes, timing and the plant's integration as when every read caught the plant up.

The receivers read recorded GPS epochs through ``SimulatedTractor.sim_so_far`` and catch the
integration up only when the epoch they need is not recorded yet. The reference is the same
receiver with ``sim_so_far`` replaced by ``sim`` (every read catches up, as the receivers did
before): the same bytes at the same times, and the same simulator state afterwards.
"""

from __future__ import annotations

from unittest import mock

import numpy as np
import pytest

from gnss.reader import read_messages
from hil.truth.conditions import condition_for
from hil.links.clock import VirtualClock
from hil.links.memory import memory_link_pair
from hil.devices.plant import SimulatedTractor
from hil.devices.receivers import AttitudeReceiver, FieldGeometry, PositionReceiver


def _drive(catch_up_always: bool, step: float, firmware: bool, which: tuple[int, ...] = (0, 1),
           duration: float = 6.0) -> tuple[list, list, np.ndarray]:
    plant = SimulatedTractor(condition_for("disker", 1.79), duration + 1.0, 3)
    clock = VirtualClock()
    geo = FieldGeometry()
    links = [memory_link_pair(clock, names=("host", n)) for n in ("position", "attitude")]
    both = [PositionReceiver(plant, links[0][1], geo), AttitudeReceiver(plant, links[1][1], geo)]
    both[0].downgraded.append((2.0, 3.0))
    rxs = [both[i] for i in which]
    got: list[list[tuple[float, bytes]]] = [[], []]
    patch = (mock.patch.object(SimulatedTractor, "sim_so_far", SimulatedTractor.sim) if catch_up_always
             else mock.patch.object(SimulatedTractor, "sim_so_far", SimulatedTractor.sim_so_far))
    with patch:
        t = 0.0
        while t < duration:
            nxt = min(t + step, *(rx.next_wakeup() for rx in rxs))
            plant.advance(nxt - t)
            clock.advance_to(nxt)
            t = nxt
            for rx in rxs:
                if rx.next_wakeup() <= t + 1e-9:
                    rx.step(t)
            for (host, _), out in zip(links, got):
                data = host.read(1 << 16)
                if data:
                    out.append((t, data))
            if firmware and int(t / 0.05) != int((t - 1e-12) / 0.05):
                plant.wheel_angle_counts()     # another reader of the plant, as the bridge firmware is
    state = np.array([plant.sim.time, plant.sim.n_pos, plant.sim.n_att, plant.wheel_angle_counts()])
    return got[0], got[1], state


@pytest.mark.parametrize("step", [0.003, 0.0125, 0.05])
@pytest.mark.parametrize("firmware", [True, False])     # without it, only the receivers make the plant catch up
def test_receivers_send_the_same_bytes_at_the_same_times_as_when_every_read_caught_up(step, firmware):
    new, ref = _drive(False, step, firmware), _drive(True, step, firmware)
    assert new[0] == ref[0] and new[1] == ref[1]
    assert np.array_equal(new[2], ref[2])
    pos = read_messages(b"".join(d for _, d in new[0]))[0]
    att = read_messages(b"".join(d for _, d in new[1]))[0]
    assert len(pos) >= 2 * 5 * 5 and len(att) >= 10 * 5    # GGA + VTG at 5 Hz, AVR at 10 Hz (some lost)
    assert {m.quality for m in pos if hasattr(m, "quality")} >= {5}          # the downgraded second


@pytest.mark.parametrize("which", [(0,), (1,)])
def test_one_receiver_alone_catches_the_plant_up_itself(which):
    """With no other reader of the plant, a receiver's own catch-up is what records its epochs."""
    new, ref = _drive(False, 0.0125, False, which), _drive(True, 0.0125, False, which)
    assert new[0] == ref[0] and new[1] == ref[1] and np.array_equal(new[2], ref[2])
    assert len(new[which[0]]) >= 50
