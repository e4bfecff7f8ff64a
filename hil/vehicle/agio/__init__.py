"""The AgOpenGPS steer module as the host sees it: protocol (layouts as data), framing, driver,
rate-to-setpoint bridge and the generated protocol document.

Modules
-------
protocol   Frame format, PGN table (layouts as data), generic encoder/decoder.
framing    Stream decoder with resynchronisation and counted, typed errors.
driver     Host driver used by the vehicle loop (rate command integrated into the angle setpoint).
spec       Bridge specifications (``agopengps:udp:HOST:PORT`` ...) and the links they open.
docgen     The protocol document generated from the table.
errors     Errors of this package.

The emulated module is :mod:`hil.devices.steer_module`; see ``docs/agopengps_protocol.md``.
"""
