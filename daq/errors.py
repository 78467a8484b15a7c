"""Errors of the acquisition side: recordings (MCAP files written by
:class:`ramdaq.daq.recorder.Recorder`) and the live view.

::

    RecordingError              a recording cannot be written, or read as a ramdaq recording
     +-- TruncatedRecording     the file ends without a footer (the recorder was killed):
     |                          ``ramdaq recover FILE`` salvages every complete chunk
     +-- NotARamdaqRecording    not an MCAP file, or an MCAP file without ramdaq's stream
     |                          metadata and ``/ramdaq/block`` topic
     +-- CorruptRecording       a record fails its CRC check or does not parse (flipped bits):
                                ``ramdaq recover FILE`` copies every intact record

    ViewError                   the Rerun view cannot start: a port is taken, the .rrd cannot
                                be created, the web viewer did not come up

The recording classes are defined in :mod:`ramdaq.drivers.mcap_format`, next to the format they
describe, because the replay device (a driver) raises them and drivers do not import ``daq``;
they are the same classes here. They are not :class:`~ramdaq.drivers.errors.DeviceError` s: a
command that opens a recording as a device should catch both. Messages are one line and name
the file (or port) and what is wrong with it.
"""

from __future__ import annotations

from ..drivers.mcap_format import (
    CorruptRecording,
    NotARamdaqRecording,
    RecordingError,
    TruncatedRecording,
)

__all__ = ["RecordingError", "TruncatedRecording", "NotARamdaqRecording", "CorruptRecording",
           "ViewError"]


class ViewError(Exception):
    """The Rerun view cannot start (a port taken, an ``.rrd`` that cannot be created)."""
