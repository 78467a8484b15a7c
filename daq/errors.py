"""Errors about recordings (MCAP files written by :class:`ramdaq.daq.recorder.Recorder`).

::

    RecordingError              a recording cannot be written, or read as a ramdaq recording
     +-- TruncatedRecording     the file ends without a footer (the recorder was killed):
     |                          ``ramdaq recover FILE`` salvages every complete chunk
     +-- NotARamdaqRecording    not an MCAP file, or an MCAP file without ramdaq's stream
                                metadata and ``/ramdaq/block`` topic

The classes are defined in :mod:`ramdaq.drivers.mcap_format`, next to the format they describe, because
the replay device (a driver) raises them and drivers do not import ``daq``; they are the same
classes here. They are not :class:`~ramdaq.drivers.errors.DeviceError` s: a command that opens a
recording as a device should catch both. Messages are one line and name the file and what is
wrong with it.
"""

from __future__ import annotations

from ramdaq.drivers.mcap_format import NotARamdaqRecording, RecordingError, TruncatedRecording

__all__ = ["RecordingError", "TruncatedRecording", "NotARamdaqRecording"]
