"""One module per `rig` subcommand; each exposes ``register(subparsers)``.

A command's ``run(args) -> int`` returns the exit status; user errors are raised as
:class:`rig.errors.RigError` or :class:`drivers.errors.DeviceError` and printed by the CLI as one line.
"""
