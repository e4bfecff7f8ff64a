"""Test helper: read the emulated receivers' ports when the command under test does not (the valve test), so the
emulator's writes never block."""

from __future__ import annotations

import threading

import serial


def drain(devices, stop: threading.Event) -> list[threading.Thread]:
    """Start one daemon thread per device that reads it until ``stop`` is set; returns the threads to join."""
    def run(dev):
        with serial.Serial(dev, timeout=0.1) as port:
            while not stop.is_set():
                port.read(4096)
    threads = [threading.Thread(target=run, args=(d,), daemon=True) for d in devices]
    for t in threads:
        t.start()
    return threads
