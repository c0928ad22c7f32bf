"""Saving a figure: what the disk refuses (full, read-only, forbidden) names the file, so the line a user reads says
which file and why."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def save_figure(fig: Any, path: Path, **kw: Any) -> None:
    """`fig.savefig(path)`; an OSError names `path` (matplotlib's own may name none)."""
    try:
        fig.savefig(path, **kw)
    except OSError as e:
        raise OSError(e.errno, e.strerror or str(e), str(path)) from None
