"""Named random streams derived from the config's seed.

Every random draw of a run comes from ``rng(seed, name)``: the same config
gives the same draws, and streams with different names are independent
(``numpy.random.SeedSequence`` with the name hashed into its entropy), so
adding a new use of randomness does not shift the existing ones.
"""

from __future__ import annotations

import zlib

import numpy as np


def seed_for(seed: int, name: str) -> int:
    """A 63-bit integer seed for the stream ``name`` of the run seed ``seed``."""
    ss = np.random.SeedSequence([int(seed), zlib.crc32(name.encode())])
    return int(ss.generate_state(2, dtype=np.uint32).astype(np.uint64) @ np.array([1, 2**31], dtype=np.uint64))


def rng(seed: int, name: str) -> np.random.Generator:
    """The generator of stream ``name`` for the run seed ``seed``."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), zlib.crc32(name.encode())]))
