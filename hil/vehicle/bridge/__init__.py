"""The steering bridge as the host sees it: protocol (layouts as data), framing, configuration,
driver and the generated protocol document.

Modules
-------
protocol   Frame format, message table (layouts as data), generic encoder/decoder.
framing    Stream decoder with resynchronisation and counted, typed errors.
config     Validated firmware and driver configuration.
driver     Host driver used by the vehicle loop.
docgen     The protocol document generated from the table.
errors     Errors of this package.

The emulated firmware is :mod:`hil.devices.firmware`; see ``docs/bridge_protocol.md`` for the byte
layouts.
"""
