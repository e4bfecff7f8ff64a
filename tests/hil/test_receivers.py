"""The emulated receivers: GGA/VTG at 5 Hz and AVR at 10 Hz that the GNSS reader decodes, a downgraded
interval reported as RTK float, and the same bytes at the same times however finely the plant is
advanced (it takes its grid steps as time passes; the epochs are recorded on the grid), with or
without another reader of the plant."""

from __future__ import annotations

import numpy as np
import pytest

from gnss.reader import read_messages
from gnss.field import FieldGeometry
from hil.truth.conditions import condition_for
from hil.links.clock import VirtualClock
from hil.links.memory import memory_link_pair
from hil.devices.plant import SimulatedTractor
from hil.devices.receivers import AttitudeReceiver, PositionReceiver


def _drive(step: float, firmware: bool, which: tuple[int, ...] = (0, 1),
           duration: float = 6.0) -> tuple[list, list, np.ndarray]:
    plant = SimulatedTractor(condition_for("disker", 1.79), duration + 1.0, 3)
    clock = VirtualClock()
    geo = FieldGeometry()
    links = [memory_link_pair(clock, names=("host", n)) for n in ("position", "attitude")]
    both = [PositionReceiver(plant, links[0][1], geo), AttitudeReceiver(plant, links[1][1], geo)]
    both[0].downgraded.append((2.0, 3.0))
    rxs = [both[i] for i in which]
    got: list[list[tuple[float, bytes]]] = [[], []]
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


@pytest.mark.parametrize("step", [0.003, 0.05])
@pytest.mark.parametrize("firmware", [True, False])     # another reader of the plant, or the receivers alone
def test_receivers_send_the_same_bytes_at_the_same_times_however_the_plant_is_advanced(step, firmware):
    new, ref = _drive(step, firmware), _drive(0.0125, False)
    for stream in (0, 1):     # a finer step reads the paced bytes in more pieces: the same bytes, joined
        assert b"".join(d for _, d in new[stream]) == b"".join(d for _, d in ref[stream])
    assert np.array_equal(new[2], ref[2])
    pos = read_messages(b"".join(d for _, d in new[0]))[0]
    att = read_messages(b"".join(d for _, d in new[1]))[0]
    assert len(pos) >= 2 * 5 * 5 and len(att) >= 10 * 5    # GGA + VTG at 5 Hz, AVR at 10 Hz (some lost)
    assert {m.quality for m in pos if hasattr(m, "quality")} >= {5}          # the downgraded second


@pytest.mark.parametrize("which", [(0,), (1,)])
def test_one_receiver_alone_sends_what_it_sends_beside_the_other(which):
    alone, both = _drive(0.0125, False, which), _drive(0.0125, False)
    # the same bytes (the other receiver's wake-ups only change when the host reads them)
    assert b"".join(d for _, d in alone[which[0]]) == b"".join(d for _, d in both[which[0]])
    assert len(alone[which[0]]) >= 50


def test_the_field_geometry_lives_with_the_fields_not_in_the_receivers_module():
    import hil.devices.receivers as receivers
    assert not hasattr(receivers, "FieldGeometry") and FieldGeometry.__module__ == "gnss.field"
