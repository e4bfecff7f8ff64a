"""ISO 11783 (ISOBUS) guidance: steering a steering-ready tractor through its valve controller.

Modules
-------
protocol
    Guidance System Command (PGN 44288) and Guidance Machine Info (PGN 44032): layout
    table on :mod:`hil.vehicle.wire`, bit fields, strict codec.
network
    ISO 11783-5 NAME, address claim and one node's guidance traffic on a python-can bus.
driver
    The host driver the vehicle loop steers through: rate commands integrated into a
    curvature command (bumpless, limited, anti-windup), the reset handshake, health.
bus, link
    Opening the CAN bus a ``--bridge isobus...`` names (python-can), and the guidance node and driver on it.
errors
    The package's exceptions.
"""
