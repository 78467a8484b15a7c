"""Back-ends by name, as python-can's ``can.Bus(interface=...)`` picks them.

The registry is plain data: name -> (module, class). Modules are imported only when chosen, so a
back-end whose vendor library is missing fails only when it is asked for. A new back-end is one
module plus one line here.
"""

from __future__ import annotations

import importlib
from typing import Any

from .base import Device
from .errors import DeviceNotFound

BACKENDS: dict[str, tuple[str, str]] = {
    "sim": ("ramdaq.drivers.sim", "SimDevice"),
    "mcap": ("ramdaq.drivers.mcap_replay", "McapReplayDevice"),
    "can": ("ramdaq.drivers.can_device", "CanDevice"),
    "serial": ("ramdaq.drivers.serial_device", "SerialDevice"),
    "csv": ("ramdaq.drivers.files.import_csv", "CsvImportDevice"),
    "uff": ("ramdaq.drivers.files.import_uff", "UffImportDevice"),
    "tdms": ("ramdaq.drivers.files.import_tdms", "TdmsImportDevice"),
}


def parse_device_spec(spec: str) -> tuple[str, str]:
    """Split a device spec into ``(backend, address)``.

    ``"sim"`` -> ``("sim", "")``; ``"mcap://trial.mcap"`` or ``"trial.mcap"`` ->
    ``("mcap", "trial.mcap")``; ``"can://virtual/0"`` -> ``("can", "virtual/0")``.
    """
    if "://" in spec:
        kind, address = spec.split("://", 1)
        return kind, address
    for suffix, kind in ((".mcap", "mcap"), (".csv", "csv"), (".uff", "uff"), (".unv", "uff"),
                         (".tdms", "tdms")):
        if spec.lower().endswith(suffix):
            return kind, spec
    return spec, ""


def device_class(kind: str) -> type[Device]:
    """The class registered under ``kind``."""
    try:
        module_name, class_name = BACKENDS[kind]
    except KeyError:
        known = ", ".join(sorted(BACKENDS))
        raise DeviceNotFound(f"no device back-end named {kind!r} (known: {known})") from None
    return getattr(importlib.import_module(module_name), class_name)


def open_device(spec: str, **options: Any) -> Device:
    """Create the device named by ``spec`` and open it.

    Parameters
    ----------
    spec : str
        Back-end name, optionally with an address (``"sim"``, ``"trial.mcap"``,
        ``"can://virtual/0"``, ``"serial:///dev/ttyUSB0"``).
    **options
        Passed to the back-end's constructor.
    """
    kind, address = parse_device_spec(spec)
    cls = device_class(kind)
    device = cls(address, **options) if address else cls(**options)
    device.open()
    return device
