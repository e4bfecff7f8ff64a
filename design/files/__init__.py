"""Controller files: one self-describing, checksummed JSON envelope and the kinds it carries.

=======================  ==================================================================
module                   what it holds
=======================  ==================================================================
``atomic``               atomic writing of a file or a directory of files
``envelope``             the schema, the checksum, reading with size and nesting limits,
                         writing a file, the shared top-level checks
``signature``            optional Ed25519 signatures (key pairs, signing, checking)
``header``               the check every kind starts with: envelope, signature, sample time
``binding``              the certificate's digests of every law field, recorded and checked
``certificate``          the certificate a file must carry, re-computed on every load
``law_schedule``         window laws by speed in a linear file
``linear``               kind ``"linear"``: a compensator and its limits (the law that runs it:
                         :class:`design.laws.linear.LinearController`)
``prediction_schedule``  an MPC file's prediction models by speed band, each band's law
                         certified on its band's models
``mpc``                  kind ``"mpc"``: the MPC's model, weights, limits and solver
``nmpc``                 kind ``"nmpc"``: the nonlinear MPC's settings
``schedule``             setting a file's speed schedules
``recheck``              ``design verify``: the certificate re-computed on model files
``load``                 :func:`load_controller`: any file for the vehicle loop (imports a
                         kind's module only when a file of that kind is read)
=======================  ==================================================================

Imports flow ``atomic`` -> ``envelope`` -> ``signature`` -> ``header``, ``binding``,
``certificate`` -> ``law_schedule``, ``prediction_schedule`` -> ``linear``, ``mpc``, ``nmpc`` ->
``schedule``, ``recheck``; ``load`` imports ``linear``, ``mpc`` or ``nmpc`` when it reads a file of
that kind.
"""
