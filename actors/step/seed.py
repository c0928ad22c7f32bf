"""The one seed of an agent's learner: every placement, the env faces and the tests build learners with it, so the
same run seed draws the same numbers wherever an agent lives."""

from __future__ import annotations

import zlib


def agent_seed(seed: int, agent: str) -> list[int]:
    """Per-agent RNG seed: the same in every placement, independent of spawn order."""
    return [seed, zlib.crc32(agent.encode())]
