"""Paths to the real receiver captures and a decoding helper for the gnss tests."""

from __future__ import annotations

from pathlib import Path

from gnss.reader import Received, StreamDecoder, strip_comment_header

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared" / "data" / "gnss"
LOCAL = REPO / "tests" / "data" / "gnss"

TRIMBLE = SHARED / "gpsd_trimble_nmea_rtk" / "nmea-rtk.log"
SKYTRAQ = SHARED / "gpsd_skytraq_px1172rh_dual_heading" / "skytraq-PX1172RH_DS.log"
UBLOX = SHARED / "gpsd_ublox_zed_f9r_ubx_nmea_rtcm" / "ublox-zed-f9r.log"
TRIMBLE_EXCERPT = LOCAL / "trimble_rtk_excerpt.nmea"


def decode_file(path: Path) -> tuple[list[Received], StreamDecoder]:
    """Decode a whole capture (gpsd '#' header stripped)."""
    data = strip_comment_header(path.read_bytes())
    dec = StreamDecoder()
    got = dec.feed(data, 0.0) + dec.flush(0.0)
    return got, dec

# Real captures kept in tests/data/gnss (provenance in its PROVENANCE.txt)
SEPTENTRIO = LOCAL / "septentrio_polarx2.nmea"
HEMISPHERE_HDT_EMPTY = LOCAL / "hemisphere_hdt_empty_excerpt.nmea"
UBLOX_M8N = LOCAL / "ublox_neo_m8n_excerpt.nmea"
