"""Run files of planar robots of any size, written as a user writes them: N `[[robot.agent]]` tables.

Two shapes, both with the reach of the tip kept at chain4's (12), so that the generalisation experiment's goals
(experiments/goals.py: the square of half 8) and its tolerance (0.5) mean the same on every size:

- chain: N joints in a row, links of 12 / N, home bent like chain4's (joint i at 120 i / (N (N - 1)) degrees: the
  headings along the arm run from 0 to 60 degrees as chain4's 0, 10, 30, 60 do);
- tree: a wide tree, each joint carrying up to BRANCHING joints (a palm with three fingers, each finger splitting
  into three, ...), filled breadth first, so its depth grows as log N, its fingers splayed by SPLAY_DEG. The reach
  task's tip is the centroid of the end effectors; links of 12 / (the leaves' mean number of links from the base)
  put that centroid 12 from the base when every link points one way.

The fan-out is bounded on purpose: an agent's Q is over the joint action of itself and its children, 3^(1 + children)
entries a rule (actors/learning/learner.py), so a palm holding N - 1 fingers at once is no robot the paper's learner
can run beyond a handful of fingers.
"""

from __future__ import annotations

from pathlib import Path

REACH = 12.0  # chain4's: 4 links of 3
BRANCHING = 3  # a tree's joints carry up to this many children
SPLAY_DEG = 20.0  # a tree's outermost children are splayed by this much either side of their parent's link
SHAPES = ("chain", "tree")


def parents(shape: str, n: int, branching: int = BRANCHING) -> list[int | None]:
    """The parent's index of joint i (0-based; the root's: None)."""
    if shape not in SHAPES:
        raise ValueError(f"shape: {shape!r} is not one of {', '.join(SHAPES)}")
    if n < 1:
        raise ValueError(f"n: a robot needs at least one joint, got {n}")
    if shape == "chain":
        return [None, *range(n - 1)]
    if branching < 1:
        raise ValueError(f"branching: at least 1, got {branching}")
    return [None, *((i - 1) // branching for i in range(1, n))]


def depth(shape: str, n: int, branching: int = BRANCHING) -> int:
    """Joints on the longest path from the root to a leaf: the hops a step's down pass (and its up pass) crosses."""
    par = parents(shape, n, branching)
    d = [1] * n
    for i in range(1, n):
        d[i] = d[par[i]] + 1  # type: ignore[index]  # parents come first
    return max(d)


def link_length(shape: str, n: int, branching: int = BRANCHING) -> float:
    """Links that put the tip (the leaves' centroid) REACH from the base, every link pointing one way."""
    par = parents(shape, n, branching)
    d = [1] * n
    for i in range(1, n):
        d[i] = d[par[i]] + 1  # type: ignore[index]
    leaves = [i for i in range(n) if i not in set(par[1:])]
    return REACH * len(leaves) / sum(d[i] for i in leaves)


def run_file(
    shape: str, n: int, path: Path, branching: int = BRANCHING, goal: tuple[float, float] = (4.16, 6.18)
) -> Path:
    """Write the run file of an n-joint robot of `shape` to `path` (joints a1 ... aN, a1 the root) and return it."""
    par = parents(shape, n, branching)
    length = link_length(shape, n, branching)
    lines = [
        f"# A planar {shape} of {n} joints" + (f", up to {branching} children a joint" if shape == "tree" else ""),
        f"# (depth {depth(shape, n, branching)}), links of {length:.4g}: its tip reaches {REACH:g} from the base.",
        "[robot]",
        f'name = "{shape}{n}"',
        "base = [0.0, 0.0, 0.0]",
        "",
        "[robot.defaults]",
        f"link_length = {length!r}",
        "limits_deg = [-180.0, 180.0]",
    ]
    children: dict[int, list[int]] = {}
    for i in range(1, n):
        children.setdefault(par[i], []).append(i)  # type: ignore[arg-type]
    for i in range(n):
        lines += ["", "[[robot.agent]]", f'id = "a{i + 1}"']
        if par[i] is not None:
            lines.append(f'parent = "a{par[i] + 1}"')  # type: ignore[operator]
        if shape == "chain":
            lines.append(f"initial_deg = {round(120.0 * i / (n * (n - 1)), 6) if n > 1 else 0.0!r}")
        else:
            siblings = children[par[i]] if par[i] is not None else [i]
            k = siblings.index(i)
            splay = 0.0 if len(siblings) == 1 else -SPLAY_DEG + 2 * SPLAY_DEG * k / (len(siblings) - 1)
            if splay:
                lines.append(f"offset = [0.0, 0.0, {round(splay, 6)!r}]")
            lines.append("initial_deg = 0.0")
    lines += ["", "[task]", 'kind = "reach"', f"goal = [{goal[0]!r}, {goal[1]!r}]"]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path
