"""Links and clocks of the bench: byte links (pseudo-terminal, in-memory), clocks, schedulers.

Modules
-------
clock      Clock protocol, RealClock, VirtualClock.
link       ByteLink protocol (the part of ``serial.Serial`` the bench uses).
memory     In-memory link pairs on a clock.
pty        Pseudo-terminal pairs (pyserial on the host side, raw fd on the device side).
uart       Line timing of a UART (byte time at a baud rate and frame format).
scheduler  Lockstep scheduler on a virtual clock.
realtime   Real-time runner thread.
errors     Errors of this package.
"""
