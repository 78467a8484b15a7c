"""Front-end emulators (tools, not back-ends): the simulator's samples sent on a CAN bus or a
serial line in the wire formats the ``can`` and ``serial`` back-ends read."""
