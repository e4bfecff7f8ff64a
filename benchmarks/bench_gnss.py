#!/usr/bin/env python3
"""GNSS front-end throughput, compared in the same run against the libraries called directly.

1. Decoding the real u-blox ZED-F9R capture (mixed NMEA / UBX / RTCM 3) with ``gnss.reader``
   versus ``pyubx2.UBXReader`` alone on the same bytes: with protfilter NMEA|UBX|RTCM3 (pyubx2
   then decodes RTCM payloads with pyrtcm, which gnss.reader passes through after the CRC), and
   with protfilter NMEA|UBX (RTCM frames skipped, the fairer comparison).
2. Decoding the Trimble NMEA capture with ``gnss.reader`` versus ``pynmeagps.NMEAReader`` alone.
3. Cross-track of N points: vectorised ``ABLine.errors`` / ``CurvedLine.errors`` versus a scalar
   Python loop over the points.
4. Hostile input: streams made of one repeated unit (``$``, ``$``-lines, UBX and RTCM 3 headers
   that announce long frames) decoded by ``gnss.reader``, against the clean Trimble capture repeated to
   the same size: the ratio is what line noise or a hostile file costs over a real receiver's bytes.
5. One point from ENU to geodetic and back (what the emulated receiver and the front-end do at 5 Hz):
   ``gnss.geodesy_scalar.ScalarFrame`` (math on floats) versus ``gnss.geodesy.LocalFrame`` (pymap3d on
   arrays): why the scalar path is kept.
6. Arc fit of a recorded contour (``gnss.arcfit.fit_arcs``, 5 mm of noise, points 0.4 m apart, 2 cm):
   5,000 points (2 km, the most a field file holds) against 1,250 points times 4, so the ratio is the
   cost per point of the long fit over the short one (1 = linear in the points).

Prints a table with times and ratios (ours / baseline).  ``--quick`` runs fewer repetitions.
"""

from __future__ import annotations

import io
import math
import sys
import time
from pathlib import Path

import numpy as np
from pynmeagps import NMEAReader
from pyubx2 import NMEA_PROTOCOL, RTCM3_PROTOCOL, UBX_PROTOCOL, UBXReader

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gnss.arcfit import fit_arcs  # noqa: E402
from gnss.curve import ArcPath  # noqa: E402
from gnss.geodesy import LocalFrame  # noqa: E402
from gnss.geodesy_scalar import ScalarFrame  # noqa: E402
from gnss.guidance import ABLine, CurvedLine  # noqa: E402
from gnss.reader import GnssReader, strip_comment_header  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "gnss"
UBLOX = DATA / "gpsd_ublox_zed_f9r_ubx_nmea_rtcm" / "ublox-zed-f9r.log"
TRIMBLE = DATA / "gpsd_trimble_nmea_rtk" / "nmea-rtk.log"


HOSTILE = {
    "'$'": b"$",
    "'$'*80 CRLF": b"$" * 80 + b"\r\n",
    "UBX hdr 8 kB": b"\xb5\x62\x01\x01\x00\x20",
    "RTCM hdr 1 kB": b"\xd3\x03\xff",
}
"""Repeated units of hostile streams: '$' floods, and headers announcing frames that fail their checksum."""


def best_of(fn, reps: int) -> tuple[float, object]:
    best, out = math.inf, None
    for _ in range(reps):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def ours(data: bytes) -> int:
    return sum(1 for _ in GnssReader(io.BytesIO(data), clock=lambda: 0.0))


def pyubx2_alone(data: bytes) -> int:
    rdr = UBXReader(io.BytesIO(data), protfilter=NMEA_PROTOCOL | UBX_PROTOCOL | RTCM3_PROTOCOL, quitonerror=0)
    return sum(1 for _ in rdr)


def pyubx2_no_rtcm_decode(data: bytes) -> int:
    rdr = UBXReader(io.BytesIO(data), protfilter=NMEA_PROTOCOL | UBX_PROTOCOL, quitonerror=0)
    return sum(1 for _ in rdr)


def pynmeagps_alone(data: bytes) -> int:
    rdr = NMEAReader(io.BytesIO(data), quitonerror=0)
    return sum(1 for _ in rdr)


def xtrack_loop(line: ABLine, e: np.ndarray, n: np.ndarray) -> list[float]:
    d = line.direction
    ax, ay = float(line.a[0]), float(line.a[1])
    dx, dy = float(d[0]), float(d[1])
    return [(y - ay) * dx - (x - ax) * dy for x, y in zip(e.tolist(), n.tolist())]


def curved_loop(v: np.ndarray, e: np.ndarray, n: np.ndarray) -> list[float]:
    out = []
    segs = [(v[i, 0], v[i, 1], v[i + 1, 0], v[i + 1, 1]) for i in range(len(v) - 1)]
    for x, y in zip(e.tolist(), n.tolist()):
        best, xte = math.inf, 0.0
        for k, (x0, y0, x1, y1) in enumerate(segs):
            ux, uy = x1 - x0, y1 - y0
            L = math.hypot(ux, uy)
            ux, uy = ux / L, uy / L
            t = (x - x0) * ux + (y - y0) * uy
            t = t if k == 0 and t < 0 else (t if k == len(segs) - 1 and t > L else min(max(t, 0.0), L))
            de, dn = x - x0 - t * ux, y - y0 - t * uy
            dd = de * de + dn * dn
            if dd < best:
                best, xte = dd, (y - y0) * ux - (x - x0) * uy
        out.append(xte)
    return out


def contour(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points 0.4 m apart along straights and arcs of radius 45-60 m, with 5 mm of noise."""
    pieces = [(20.0, (0.0, 1 / 60, -1 / 45)[i % 3]) for i in range(int(n * 0.4 / 20.0) + 2)]
    e, nn, _ = ArcPath((0.0, 0.0), 0.3, pieces).pose(np.arange(n) * 0.4)
    return np.column_stack([e, nn]) + rng.normal(0.0, 0.005, (n, 2))


def main(argv: list[str]) -> int:
    quick = "--quick" in argv
    reps = 3 if quick else 7
    rows = []
    ublox = strip_comment_header(UBLOX.read_bytes())
    trimble = strip_comment_header(TRIMBLE.read_bytes())
    for name, data, base_name, base in (
        ("mixed UBX/NMEA/RTCM (158 kB)", ublox, "pyubx2 alone", pyubx2_alone),
        ("mixed, RTCM not decoded by pyubx2", ublox, "pyubx2 NMEA|UBX", pyubx2_no_rtcm_decode),
        ("NMEA Trimble RTK (22 kB)", trimble, "pynmeagps alone", pynmeagps_alone),
    ):
        t_ours, n_ours = best_of(lambda: ours(data), reps)
        t_base, n_base = best_of(lambda: base(data), reps)
        rows.append((f"decode {name}", f"gnss.reader ({n_ours} msgs)", t_ours, f"{base_name} ({n_base} msgs)", t_base))
    n_hostile = 40_000 if quick else 150_000
    clean = (trimble * (n_hostile // len(trimble) + 1))[:n_hostile]
    t_clean, n_clean = best_of(lambda: ours(clean), reps)
    for unit_name, unit in HOSTILE.items():
        hostile = (unit * (n_hostile // len(unit) + 1))[:n_hostile]
        t_h, n_h = best_of(lambda: ours(hostile), reps)
        rows.append((f"hostile {unit_name} ({n_hostile // 1000} kB)", f"gnss.reader ({n_h} msgs)", t_h,
                     f"same size clean ({n_clean} msgs)", t_clean))
    frame = LocalFrame.from_degrees(37.4275, -122.1697, 30.0)
    scalar = ScalarFrame(frame)
    n_geo = 500 if quick else 3000
    lat, lon, h = scalar.to_geodetic(12.0, 34.0, 2.0)
    t_s, _ = best_of(lambda: [scalar.to_enu(*scalar.to_geodetic(12.0, 34.0, 2.0)) for _ in range(n_geo)], reps)
    t_l, _ = best_of(lambda: [frame.to_enu(*(float(v) for v in frame.to_geodetic([12.0, 34.0, 2.0])))
                              for _ in range(n_geo)], reps)
    rows.append((f"ENU -> geodetic -> ENU, {n_geo} points", "ScalarFrame (math)", t_s, "LocalFrame (pymap3d)", t_l))
    rng = np.random.default_rng(0)
    n_pts = 20_000 if quick else 100_000
    e, n = rng.uniform(-200, 200, (2, n_pts))
    line = ABLine([0.0, 0.0], [30.0, 40.0])
    t_vec, _ = best_of(lambda: line.errors(e, n, 0.3), reps)
    t_loop, _ = best_of(lambda: xtrack_loop(line, e, n), reps)
    rows.append((f"AB cross-track, {n_pts} points", "ABLine.errors (vectorised)", t_vec, "scalar Python loop", t_loop))
    arc = CurvedLine.arc([0.0, 0.0], 50.0, 0.0, math.pi, spacing=1.0)
    m = 2000
    t_cv, _ = best_of(lambda: arc.errors(e[:m], n[:m]), reps)
    t_cl, _ = best_of(lambda: curved_loop(arc.vertices, e[:m], n[:m]), max(1, reps // 3))
    rows.append((f"curved cross-track, {m} pts x {len(arc.vertices) - 1} segs", "CurvedLine.errors", t_cv,
                 "scalar Python loop", t_cl))
    rng = np.random.default_rng(7)
    short, long = contour(1250, rng), contour(5000, rng)
    t_short, _ = best_of(lambda: fit_arcs(short, 0.02), reps)
    t_long, fit = best_of(lambda: fit_arcs(long, 0.02), reps)
    rows.append((f"arc fit, noisy contour, {len(fit.segments)} arcs", "fit_arcs 5000 points", t_long,
                 "fit_arcs 1250 points x 4", 4 * t_short))
    print(f"{'case':<46}{'ours':<36}{'time':>10}  {'baseline':<28}{'time':>10}  {'ours/base':>9}")
    for case, a, ta, b, tb in rows:
        print(f"{case:<46}{a:<36}{ta * 1e3:>8.2f}ms  {b:<28}{tb * 1e3:>8.2f}ms  {ta / tb:>9.3f}")
    print(f"\nper point: AB vectorised {t_vec / n_pts * 1e9:.1f} ns, scalar loop {t_loop / n_pts * 1e9:.1f} ns; "
          f"curved vectorised {t_cv / m * 1e6:.2f} us")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
