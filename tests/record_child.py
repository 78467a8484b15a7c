"""Child process of the SIGKILL test: records a steady real-time stream until it is killed.

``python -m tests.record_child PATH SEED N_BLOCKS``: 16 channels at 25.6 kHz in 50 ms blocks,
each block handed to the recorder when its last sample would have been acquired. After every
``put`` it prints ``put SEQ FIRST_SAMPLE N_SAMPLES ACCEPTED`` and flushes, so the parent knows
exactly what the recorder was given before the kill.
"""

from __future__ import annotations

import sys
import time

from ramdaq.daq.recorder import Recorder
from tests.recording_helpers import BLOCK_SAMPLES, FS_HZ, block, stream_info


def main(path: str, seed: int, n_blocks: int) -> None:
    blocks = [block(k, seed, full_range=False) for k in range(n_blocks)]  # made before the clock
    with Recorder(path, stream_info(), overwrite=True) as rec:
        print("ready", flush=True)
        t_start = time.monotonic()
        for k, b in enumerate(blocks):
            delay = t_start + (k + 1) * BLOCK_SAMPLES / FS_HZ - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            ok = rec.put(b)
            print(f"put {b.seq} {b.first_sample} {b.n_samples} {int(ok)}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]))
