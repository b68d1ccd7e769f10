"""How fast the framing decoders get through garbage and through good frames.

    python bench/framing_bench.py [--megabytes 20]

Feeds each decoder (request direction, as the emulator decodes) `--megabytes` MB in 4 KiB
chunks, as a TCP connection hands them over, draining its events after every chunk, and
prints MB/s for:

- **garbage without start codes**: random bytes with the framing's start code replaced
  (the emulator service test's garbage, without its bad frames);
- **random garbage**: random bytes, start codes included, so false frames start and are
  read to their length (crc16) or to the next 7Eh (stx) before they fail their check;
- **good frames**: back-to-back 20-byte write requests.
"""

from __future__ import annotations

import argparse
import random
import time

from prc3cfg.core.framing import NEED_DATA, Direction, get_framing
from prc3cfg.core.line import LineSettings

CHUNK = 4096
START_CODES = {"crc16": b"\xa5", "stx": b"\x7e"}


def throughput(name: str, data: bytes) -> float:
    """MB/s of one request decoder fed `data` in CHUNK pieces (events drained after each)."""
    decoder = get_framing(name).decoder(Direction.REQUEST, LineSettings(), zvz=0.020)
    start = time.perf_counter()
    for i in range(0, len(data), CHUNK):
        decoder.receive_data(data[i : i + CHUNK], 0.0)
        while decoder.next_event() is not NEED_DATA:
            pass
    return len(data) / 1e6 / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--megabytes", type=float, default=20)
    args = parser.parse_args()
    size = int(args.megabytes * 1e6)
    noise = random.Random(1).randbytes(size)
    for name, start in START_CODES.items():
        framing = get_framing(name)
        frame = framing.encode(Direction.REQUEST, 5, bytes.fromhex("210A041A012C0035001403F200320500"))
        good = frame * (size // len(frame))
        clean = noise.replace(start, bytes(1))
        print(f"{name:6} garbage without start codes {throughput(name, clean):7.1f} MB/s   "
              f"random garbage {throughput(name, noise):7.1f} MB/s   good frames "
              f"{throughput(name, good):6.1f} MB/s")


if __name__ == "__main__":
    main()
