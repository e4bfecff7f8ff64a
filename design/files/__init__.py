"""Controller files: one self-describing, checksummed JSON envelope and the kinds it carries.

=================  ==================================================================
module             what it holds
=================  ==================================================================
``envelope``       the schema, the checksum, reading with size and nesting limits,
                   atomic writing, the shared top-level checks
``signature``      optional Ed25519 signatures (key pairs, signing, checking)
``certificate``    the certificate a file must carry, re-computed on every load
``linear``         kind ``"linear"``: a compensator and :class:`LinearController`
``mpc``            kind ``"mpc"``: the MPC's model, weights, limits and solver
``load``           :func:`load_controller`: any file for the vehicle loop
=================  ==================================================================

Imports flow ``envelope``, ``signature``, ``certificate`` -> ``linear``, ``mpc`` -> ``load``.
"""
