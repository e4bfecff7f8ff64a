"""The steering bridge: protocol, emulated MC68HC11 firmware, host driver.

Modules
-------
protocol   Frame format, message table (layouts as data), generic encoder/decoder.
framing    Stream decoder with resynchronisation and counted, typed errors.
config     Validated firmware and driver configuration.
firmware   Emulated bridge firmware (a scheduler device) and the SteeringPlant protocol.
driver     Host driver used by the vehicle loop.
bench      Firmware + plant + driver wired on an in-memory link (lockstep) or a pty (real time).
errors     Errors of this package.

See ``docs/bridge_protocol.md`` for the byte layouts.
"""
