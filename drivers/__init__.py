"""Devices: every source of samples behind one interface (:class:`~ramdaq.drivers.base.Device`),
streaming :class:`~ramdaq.drivers.block.Block` s of int32 ADC counts with a per-channel SI scale,
chosen by name (:func:`ramdaq.drivers.registry.open_device`): ``sim`` (the physics model behind a
simulated front-end), ``mcap`` (a recording replayed), ``can``, ``serial``, and other systems'
recordings (:mod:`~ramdaq.drivers.files`: CSV, UFF 58, TDMS). :mod:`~ramdaq.drivers.emulators`
holds tools that speak the CAN and serial wire formats from the simulator. Drivers use
:mod:`ramdaq.analysis` (the rig, the simulator's model) and never import :mod:`ramdaq.daq`.
"""
