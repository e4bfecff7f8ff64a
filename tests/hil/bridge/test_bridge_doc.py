"""docs/bridge_protocol.md agrees with the code: generated block current, examples decode, ids listed."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from hil.bench.docgen.bridge import BEGIN, EXAMPLES, main, render, replace_block
from hil.vehicle.bridge.protocol import MESSAGE_TABLE, decode_frame, encode_frame

pytestmark = pytest.mark.timeout(20)

DOC = Path(__file__).resolve().parents[3] / "docs" / "bridge_protocol.md"


def test_generated_block_of_the_protocol_document_is_current():
    text = DOC.read_text(encoding="utf-8")
    assert replace_block(text) == text, "run: python -m hil.bench.docgen.bridge docs/bridge_protocol.md --write"
    assert render() in text
    assert main([str(DOC)]) == 0


def test_example_frames_in_the_document_are_what_the_encoder_produces_and_decode_back():
    text = DOC.read_text(encoding="utf-8")
    block = text[text.index(BEGIN):]
    hex_frames = re.findall(r"^  ((?:[0-9a-f]{2} )+[0-9a-f]{2})$", block, flags=re.M)
    assert len(hex_frames) == len(EXAMPLES)
    for line, (_, message, seq) in zip(hex_frames, EXAMPLES):
        frame = bytes.fromhex(line)
        assert frame == encode_frame(message, seq)
        back = decode_frame(frame)
        assert back.seq == seq and encode_frame(back.message, seq) == frame


def test_document_lists_every_message_id_with_its_direction():
    text = DOC.read_text(encoding="utf-8")
    for msg_id, layout in MESSAGE_TABLE.items():
        arrow = layout.direction.replace("->", " → ")
        assert f"| 0x{msg_id:02X} | {layout.cls.__name__} | {arrow} |" in text
    assert "initial value 0xFFFF" in text and "250 ms" in text and "20 Hz" in text


def test_a_stale_document_is_detected(tmp_path):
    stale = tmp_path / "doc.md"
    stale.write_text(DOC.read_text(encoding="utf-8").replace("a5 5a 01 07", "a5 5a 01 08"), encoding="utf-8")
    assert main([str(stale)]) == 1
    assert main([str(stale), "--write"]) == 0 and main([str(stale)]) == 0
