# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 05 - The GPS front-end on a real RTK capture
#
# Decode the Trimble RTK capture (gpsd regression log, 10 Hz GGA/RMC), summarise it, replay it
# through the front-end at a fixed 10 Hz and compute cross-track against an AB line along the
# track's main direction.  Units: m, s, rad; degrees only when printed.

# %%
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Image, display

from gnss import ABLine, FrontEndConfig, GnssFrontEnd, IntegrityConfig, IntegrityState, LocalFrame
from gnss.frontend import replay_solutions, stamp_from_tags
from gnss.reader import StreamDecoder, strip_comment_header
from gnss.summary import summarize_capture

import gnss

ROOT = Path(gnss.__file__).resolve().parents[1]  # the repository (the project is installed editable)
CAPTURE = ROOT / "notebooks" / "data" / "trimble_nmea_rtk.log"  # gpsd's nmea-rtk.log (data/PROVENANCE.txt)
OUT = Path("nb_out")  # the figure is written here, in the working directory

# %%
summary, messages, stats = summarize_capture(CAPTURE.read_bytes())
print(summary.messages, summary.fix_quality, f"{summary.median_interval_s} s")
assert stats.n_errors == 0 and summary.fix_quality == {"gga2": 104, "gga4": 18}

# %% [markdown]
# Replay at 10 Hz.  There is no heading receiver in this capture, so the front-end runs with
# `require_attitude=False` and takes yaw from the course over ground while moving.

# %%
dec = StreamDecoder()
received = stamp_from_tags(dec.feed(strip_comment_header(CAPTURE.read_bytes())) + dec.flush())
first = summary.first_fix
origin = LocalFrame.from_degrees(first["lat_deg"], first["lon_deg"], first["height_m"])
fe = GnssFrontEnd(FrontEndConfig(origin=origin, require_attitude=False,
                                 integrity=IntegrityConfig(max_correction_age=10.0)))
# first (moving, DGPS) segment only: the second segment starts 10 minutes later
moving = [r for r in received if r.t_arrival < received[0].t_arrival + 11.0]
sols = list(replay_solutions(fe, moving, rate=10.0))
east = np.array([s.east for s in sols])
north = np.array([s.north for s in sols])
states = {s.integrity.state for s in sols}
print(len(sols), "solutions,", states)
assert states == {IntegrityState.DEGRADED}  # DGPS, not RTK: the loop would not engage

# %% [markdown]
# An AB line from the first to the last published point: cross-track is then zero at both ends,
# and its sign says on which side of the chord the track bends (positive = left).

# %%
line = ABLine([east[0], north[0]], [east[-1], north[-1]])
err = line.errors(east, north, np.array([s.yaw for s in sols]))
print(f"max |xte| {np.max(np.abs(err.cross_track)):.3f} m over {err.station[-1]:.2f} m")
assert abs(err.cross_track[0]) < 1e-9 and abs(err.cross_track[-1]) < 1e-9
assert err.station[-1] > 2.0  # the tractor moved ~3 m

# %%
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
ax1.plot(east, north, ".-")
ax1.set_xlabel("east (m)")
ax1.set_ylabel("north (m)")
ax1.set_aspect("equal", adjustable="datalim")
ax2.plot(err.station, err.cross_track)
ax2.set_xlabel("station (m)")
ax2.set_ylabel("cross-track (m, + left)")
fig.tight_layout()
OUT.mkdir(exist_ok=True)
fig.savefig(OUT / "cross_track.png", dpi=100)
plt.close(fig)
display(Image(filename=str(OUT / "cross_track.png")))
