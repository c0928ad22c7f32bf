"""Checkpoints: one `.npz` per agent, written atomically (temp file + fsync + rename + directory fsync),
carrying a format version and a SHA-256 over every array, so a torn or foreign file is refused with a
clear error instead of loading corrupted learned state. The previous checkpoint is kept as
`<id>.prev.npz`; `load_latest` falls back to it when the newest one is refused. The header names the learner kind
(actors/policies/registry.py) whose state the arrays are: a checkpoint of another kind is refused, not loaded into a
learner that would read the same arrays otherwise (a tabular learner's phi is shaped as a fuzzy one's)."""

from __future__ import annotations

import hashlib
import io
import json
import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np

FORMAT = "kinswarm-agent-checkpoint"
FORMAT_VERSION = 1
#: the learner kind of a checkpoint whose header names none (written before there were kinds)
UNNAMED_KIND = "fuzzy"


class CheckpointError(ValueError):
    pass


def digest(arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(name.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def save_checkpoint(path: Path, arrays: dict[str, np.ndarray], meta: dict) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = {**meta, "format": FORMAT, "version": FORMAT_VERSION, "sha256": digest(arrays)}
    buf = io.BytesIO()
    np.savez(buf, __meta__=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8), **arrays)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(buf.getvalue())
            f.flush()
            os.fsync(f.fileno())
        if path.exists():  # keep the last good one: a crash between the renames leaves only .prev
            os.replace(path, previous(path))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    dfd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dfd)
    finally:
        os.close(dfd)


def load_checkpoint(
    path: Path, *, agent: str | None = None, learner: str | None = None
) -> tuple[dict[str, np.ndarray], dict]:
    """Return (arrays, meta); raise CheckpointError naming the file and what is wrong (with `agent` and `learner`: a
    checkpoint of another agent, or of another learner kind, too)."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise CheckpointError(f"{path}: no such checkpoint") from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        raise CheckpointError(f"{path}: not a readable checkpoint (torn or foreign file): {e}") from None
    raw = arrays.pop("__meta__", None)
    if raw is None:
        raise CheckpointError(f"{path}: no kinswarm header (a foreign .npz?)")
    try:
        meta = json.loads(raw.tobytes().decode())
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise CheckpointError(f"{path}: header is not valid JSON") from None
    if meta.get("format") != FORMAT:
        raise CheckpointError(f"{path}: format {meta.get('format')!r}, expected {FORMAT!r}")
    if meta.get("version") != FORMAT_VERSION:
        raise CheckpointError(f"{path}: format version {meta.get('version')!r}, expected {FORMAT_VERSION}")
    if meta.get("sha256") != digest(arrays):
        raise CheckpointError(f"{path}: checksum mismatch: the file is corrupted")
    if agent is not None and meta.get("agent") != agent:
        raise CheckpointError(f"{path}: belongs to agent {meta.get('agent')!r}, not {agent!r}")
    theirs = meta.get("learner", UNNAMED_KIND)
    if learner is not None and theirs != learner:
        what = f"the state of a {theirs!r} learner, not of this run's {learner!r} ([learner] kind)"
        raise CheckpointError(f"{path}: {what}")
    return arrays, meta


def previous(path: Path) -> Path:
    """`agents/a1.npz` -> `agents/a1.prev.npz`: the checkpoint before the newest."""
    path = Path(path)
    return path.with_name(f"{path.stem}.prev{path.suffix}")


def load_latest(
    path: Path, *, agent: str, learner: str | None = None
) -> tuple[dict[str, np.ndarray], dict, Path, list[str]]:
    """The newest good checkpoint at `path`, else its `.prev`: (arrays, meta, file used, refusals).
    Raises CheckpointError when neither is good, naming both reasons."""
    refused: list[str] = []
    for candidate in (Path(path), previous(path)):
        try:
            arrays, meta = load_checkpoint(candidate, agent=agent, learner=learner)
        except CheckpointError as e:
            refused.append(str(e))
            continue
        return arrays, meta, candidate, refused
    raise CheckpointError("; ".join(refused))
