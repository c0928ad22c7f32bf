"""Goal sets of the generalisation experiment (paper §5.2): quad-tree training goals and Halton test goals.

The task space is the square [-HALF, HALF]^2 around the base: the largest centred square whose corners
(radius 11.3) stay within 95 % of the 4R chain's reach (12), so every goal is reachable and the paper's
counts hold exactly (Level-L: 4^L cell centres).
"""

from __future__ import annotations

import numpy as np

HALF = 8.0
TEST_SIZE = 100


def quadtree(level: int, half: float = HALF) -> list[tuple[float, float]]:
    """Centres of the 2^level x 2^level cells of the task space (Level-1: 4 goals ... Level-4: 256)."""
    if level < 1:
        raise ValueError(f"level must be >= 1, got {level}")
    n = 2**level
    c = -half + (np.arange(n) + 0.5) * (2 * half / n)
    return [(round(float(x), 6), round(float(y), 6)) for y in c for x in c]


def radical_inverse(i: int, base: int) -> float:
    f, r = 1.0, 0.0
    while i > 0:
        f /= base
        r += f * (i % base)
        i //= base
    return r


def halton(block: int, size: int = TEST_SIZE, half: float = HALF) -> list[tuple[float, float]]:
    """Test set `block`: points 1 + block*size ... (block+1)*size of the Halton sequence in bases 2 and 3
    (point 0 is the corner), scaled to the task space. Blocks never overlap, so block 1 is unseen by 0."""
    if block < 0:
        raise ValueError(f"the test set index must be >= 0, got {block}")
    pts = []
    for i in range(1 + block * size, 1 + (block + 1) * size):
        pts.append(
            (
                round(-half + 2 * half * radical_inverse(i, 2), 6),
                round(-half + 2 * half * radical_inverse(i, 3), 6),
            )
        )
    return pts


def training_order(goals: list[tuple[float, float]], reps: int, seed: int) -> tuple[tuple[float, float], ...]:
    """The training goal per epoch: `reps` passes over the goals, each pass in a seeded random order
    (so no goal is always trained last)."""
    rng = np.random.default_rng([seed, 5_2])
    order: list[tuple[float, float]] = []
    for _ in range(reps):
        order += [goals[i] for i in rng.permutation(len(goals))]
    return tuple(order)
