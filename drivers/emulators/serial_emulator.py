"""Serial front-end emulator: the physics simulator's samples, framed, on a pty or a TCP bridge.

::

    python -m ramdaq.drivers.emulators.serial_emulator --pty --rig recordings/rigs/albacore.toml \\
        --duration 10 --impacts 1,4 --seed 0
    python -m ramdaq.drivers.emulators.serial_emulator --tcp 127.0.0.1:0 --rig ... \\
        --unplug-at 2 --unplug-for 1

The first stdout line is the address to give ``SerialDevice`` (a path, or ``socket://...``);
the last is a JSON summary of what was sent, dropped, corrupted and lost. Notes go to stderr.

* ``--pty`` opens a pseudo-terminal pair in raw mode and publishes the slave under a **stable
  symlink** (``--link``, default in a fresh temporary folder), as udev's ``/dev/serial/by-id``
  names a USB adapter: a replugged pty is a new pair with a new ``/dev/pts/N``, and the symlink
  lets the reader reopen the same name, as it would after a real unplug.
* ``--tcp HOST:PORT`` listens on 127.0.0.1 only (port 0 picks a free one) and serves one client
  at a time, as an Ethernet-serial bridge does. Unplugged, it stops listening, so reconnecting
  is refused until it comes back on the same port.

The sample clock starts when the first reader connects (pyserial flushes a port's input when it
opens it, so earlier bytes would be lost). ``--pace realtime`` sends each frame when its last
sample is due; frames nobody is reading then are lost, as a live device's would be.
``--pace fast`` sends as fast as the reader takes them and waits while nobody reads.

Faults, by frame sequence number ``k`` (0-based): ``--drop-every K`` never sends frames with
``(k + 1) % K == 0``; ``--corrupt-every K`` flips one payload byte of those frames;
``--garbage-every K`` sends 1-199 random bytes before them. ``--unplug-at S --unplug-for D``
sends half of the first frame starting at or after S s (a torn frame), closes the port, loses
every frame starting before S + D s, stays away at least D s of wall time, and comes back.
The end of the stream is an end-of-stream frame; then the emulator waits for the reader to
close (at most ``--linger`` s) and exits.
"""

from __future__ import annotations

import argparse
import json
import os
import select
import shutil
import signal
import socket
import sys
import tempfile
import time
import tty
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from ..serial_frames import FLAG_END, HEADER_BYTES, encode_frame, width_for_bits

_SETTLE_S = 0.2  # after a reader connects: pyserial flushes a port's input as it opens it


class PtyPort:
    """A raw pseudo-terminal whose slave is published under a stable symlink ``link``."""

    def __init__(self, link: Path) -> None:
        self.link = link
        self.master: int | None = None
        self._seen = False
        self.plug()

    @property
    def address(self) -> str:
        return str(self.link)

    def plug(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # 8-bit clean, no echo, no CR/LF mapping, even before a reader opens
        name = os.ttyname(slave)
        os.close(slave)  # with no slave open the master polls POLLHUP: that is how readers show
        os.set_blocking(master, False)
        self.master, self._seen = master, False
        tmp = self.link.with_name(self.link.name + ".new")
        tmp.unlink(missing_ok=True)
        os.symlink(name, tmp)
        os.replace(tmp, self.link)

    def unplug(self) -> None:
        self.link.unlink(missing_ok=True)
        if self.master is not None:
            os.close(self.master)
            self.master = None

    def _hup(self, timeout_ms: int, out: bool = True) -> tuple[bool, bool]:
        p = select.poll()
        p.register(self.master, select.POLLOUT if out else 0)  # POLLHUP is always reported
        events = dict(p.poll(timeout_ms)).get(self.master, 0)
        return bool(events & select.POLLHUP), bool(events & select.POLLOUT)

    def wait_reader(self, timeout_s: float | None) -> bool:
        end = None if timeout_s is None else time.monotonic() + timeout_s
        while self._hup(0)[0]:
            self._seen = False
            if end is not None and time.monotonic() >= end:
                return False
            time.sleep(0.01)
        if not self._seen:
            time.sleep(_SETTLE_S)
            self._seen = True
        return True

    def send(self, data: bytes) -> bool:
        view = memoryview(data)
        while view:
            hup, writable = self._hup(100)
            if hup:
                self._seen = False
                return False
            if writable:
                try:
                    view = view[os.write(self.master, view):]
                except BlockingIOError:
                    continue
                except OSError:
                    return False
        return True

    def finish(self, linger_s: float) -> None:
        end = time.monotonic() + linger_s
        while time.monotonic() < end and not self._hup(50, out=False)[0]:
            pass
        self.unplug()


class TcpBridge:
    """A one-client TCP server on ``host`` (127.0.0.1), like an Ethernet-serial bridge."""

    def __init__(self, host: str, port: int) -> None:
        if host not in ("127.0.0.1", "localhost"):
            raise SystemExit(f"serial_emulator: --tcp {host}: only 127.0.0.1 is served")
        self.host, self.port = "127.0.0.1", port
        self.conn: socket.socket | None = None
        self.listener: socket.socket | None = None
        self.plug()

    @property
    def address(self) -> str:
        return f"socket://{self.host}:{self.port}"

    def plug(self) -> None:
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind((self.host, self.port))
        s.listen(1)
        self.port = s.getsockname()[1]
        self.listener = s

    def unplug(self) -> None:
        for s in (self.conn, self.listener):
            if s is not None:
                s.close()  # graceful: bytes already sent still reach the reader, then EOF
        self.conn = self.listener = None

    def wait_reader(self, timeout_s: float | None) -> bool:
        if self.conn is not None:
            return True
        self.listener.settimeout(timeout_s)
        try:
            self.conn, _ = self.listener.accept()
        except (TimeoutError, BlockingIOError):
            return False
        self.conn.settimeout(None)
        self.conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        time.sleep(_SETTLE_S)  # pyserial's socket:// drains whatever is readable when it opens
        return True

    def send(self, data: bytes) -> bool:
        try:
            self.conn.sendall(data)
            return True
        except OSError:
            self.conn.close()
            self.conn = None
            return False

    def finish(self, linger_s: float) -> None:
        if self.conn is not None:
            try:
                self.conn.shutdown(socket.SHUT_WR)
                self.conn.settimeout(linger_s)
                while self.conn.recv(4096):
                    pass
            except OSError:
                pass
        self.unplug()


def frames_of(sim: Iterable, samples: int) -> Iterator[tuple[int, np.ndarray]]:
    """``(first_sample, counts)`` of consecutive frames of ``samples`` samples (the last may be
    shorter) cut from the simulator's blocks."""
    held: list[np.ndarray] = []
    have, first = 0, 0
    for block in sim:
        held.append(block.counts)
        have += block.n_samples
        if have < samples:
            continue
        counts = np.concatenate(held, axis=1)
        n_full = have // samples * samples
        for i in range(0, n_full, samples):
            yield first + i, counts[:, i:i + samples]
        first += n_full
        held, have = [counts[:, n_full:]], have - n_full
    if have:
        yield first, np.concatenate(held, axis=1)


def run(args: argparse.Namespace, port: PtyPort | TcpBridge) -> dict:
    """Stream the simulated trial through ``port``; return the summary."""
    from ..sim import SimDevice  # after the address is out: scipy takes a while to import

    sim = SimDevice(args.rig, seed=args.seed, duration_s=args.duration, impacts=args.impacts,
                    fs_hz=args.fs, pace="fast")
    info = sim.open()
    fs = info.fs_hz
    width = args.width or width_for_bits(sim.rig.daq.adc_bits)
    rng = np.random.default_rng(args.seed)
    realtime = args.pace == "realtime"
    unplug = (None if args.unplug_at is None else
              (round(args.unplug_at * fs), round((args.unplug_at + args.unplug_for) * fs)))
    out = {"address": port.address, "frames_sent": 0, "samples_sent": 0, "dropped": [],
           "corrupted": [], "garbage": [], "torn": [], "lost": [], "unplugged": [],
           "width": width, "frame_samples": args.frame_samples, "channels": info.n_channels}
    port.wait_reader(None)
    t0, unplugged_at, k, total = time.monotonic(), None, 0, 0
    for k, (first, counts) in enumerate(frames_of(sim, args.frame_samples)):
        n = counts.shape[1]
        total = first + n
        if realtime:
            time.sleep(max(0.0, t0 + total / fs - time.monotonic()))
        if unplugged_at is not None:
            if first < unplug[1]:
                out["lost"].append(k)
                continue
            time.sleep(max(0.0, unplugged_at + args.unplug_for - time.monotonic()))
            port.plug()
            print(f"serial_emulator: back at sample {first} on {port.address}", file=sys.stderr)
            unplugged_at = None
        frame = encode_frame(k, first, counts, width=width)
        if unplug is not None and first >= unplug[0] and not out["unplugged"]:
            port.send(frame[: len(frame) // 2])
            port.unplug()
            unplugged_at = time.monotonic()
            out["torn"].append(k)
            out["unplugged"].append(first)
            print(f"serial_emulator: unplugged at sample {first}", file=sys.stderr)
            continue
        if not port.wait_reader(0.0 if realtime else None):
            out["lost"].append(k)
            continue
        if args.drop_every and (k + 1) % args.drop_every == 0:
            out["dropped"].append(k)
            continue
        if args.garbage_every and (k + 1) % args.garbage_every == 0:
            junk = rng.integers(0, 256, int(rng.integers(1, 200)), dtype=np.uint8).tobytes()
            if not port.send(junk):
                out["lost"].append(k)
                continue
            out["garbage"].append(k)
        corrupt = bool(args.corrupt_every) and (k + 1) % args.corrupt_every == 0
        if corrupt:
            buf = bytearray(frame)
            buf[int(rng.integers(HEADER_BYTES, len(buf)))] ^= int(rng.integers(1, 256))
            frame = bytes(buf)
            out["corrupted"].append(k)
        if port.send(frame):
            out["frames_sent"] += 1
            out["samples_sent"] += 0 if corrupt else n
        else:
            out["lost"].append(k)
    if unplugged_at is not None:  # the stream ended while unplugged
        port.plug()
    if port.wait_reader(args.linger):
        end = encode_frame(k + 1, total, np.zeros((info.n_channels, 0), np.int32), width=width,
                           flags=FLAG_END)
        port.send(end)
    port.finish(args.linger)
    return out


def _floats(text: str) -> list[float]:
    return [float(t) for t in text.split(",") if t.strip()]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m ramdaq.drivers.emulators.serial_emulator",
                                description=__doc__.split("\n")[0])
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--pty", action="store_true", help="serve on a pseudo-terminal")
    where.add_argument("--tcp", metavar="127.0.0.1:PORT", help="serve as a TCP bridge")
    p.add_argument("--link", help="pty: the stable symlink to publish (default: a temp folder)")
    p.add_argument("--rig", required=True, help="rig file (TOML)")
    p.add_argument("--duration", type=float, default=10.0, help="stream seconds")
    p.add_argument("--impacts", type=_floats, default=[], help="ram blows at these s, e.g. 1,4")
    p.add_argument("--seed", type=int, default=0, help="noise seed")
    p.add_argument("--fs", type=float, help="override the rig's sample rate, Hz")
    p.add_argument("--pace", choices=("realtime", "fast"), default="realtime")
    p.add_argument("--frame-samples", type=int, default=32, help="samples per channel per frame")
    p.add_argument("--width", type=int, choices=(2, 3, 4), help="bytes per sample (default: "
                   "the least that holds the rig's ADC)")
    for name in ("drop", "corrupt", "garbage"):
        p.add_argument(f"--{name}-every", type=int, default=0, metavar="K")
    p.add_argument("--unplug-at", type=float, help="stream seconds of the unplug")
    p.add_argument("--unplug-for", type=float, default=1.0, help="seconds unplugged")
    p.add_argument("--linger", type=float, default=5.0, help="s to wait for the reader at the end")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # clean up the link on terminate
    tmp = None
    if args.pty:
        if args.link:
            link = Path(args.link)
        else:
            tmp = tempfile.mkdtemp(prefix="ramdaq-serial-")
            link = Path(tmp) / "tty"
        port: PtyPort | TcpBridge = PtyPort(link)
    else:
        host, _, number = args.tcp.rpartition(":")
        port = TcpBridge(host, int(number))
    print(port.address, flush=True)
    try:
        summary = run(args, port)
        print(json.dumps(summary), flush=True)
    except KeyboardInterrupt:
        return 130
    finally:
        port.unplug()
        if tmp:
            shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
