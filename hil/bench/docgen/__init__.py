"""The bench's room for the generated parts of the protocol documents (not shipped with :mod:`hil.vehicle`,
what runs on the tractor).

Modules
-------
block
    A generated block between two markers inside a hand-written document, and the command
    that checks or rewrites it (``python -m MODULE PATH [--write]``).
tables
    Layout tables and example frames of any frame grammar of :mod:`hil.vehicle.wire`.
bridge
    ``docs/bridge_protocol.md`` from the HC11 bridge's message table.
agio
    ``docs/agopengps_protocol.md`` from the AgOpenGPS PGN table.
isobus
    ``docs/isobus_protocol.md`` from the ISO 11783 guidance messages' table.

Each document is checked or rewritten by its module, for example::

    python -m hil.bench.docgen.bridge docs/bridge_protocol.md           # check (exit 1 if stale)
    python -m hil.bench.docgen.bridge docs/bridge_protocol.md --write   # rewrite the block
"""
