"""The chaos soak as one picture (`chaos.png` beside the two runs): what each run reached epoch by epoch, the
fault-free run's and the chaos run's, over the faults as they went in, one row a kind, the crashes across both.

Read from what the runs left behind (metrics.jsonl, events.jsonl), as the invariants are.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

WINDOW = 20  # epochs in the rolling share within 0.5


def rolling_share(errors: list[float], window: int = WINDOW) -> list[float]:
    """The share of the last `window` epochs (fewer at the start) that ended within 0.5."""
    out, hits = [], []
    for e in errors:
        hits.append(e <= 0.5)
        last = hits[-window:]
        out.append(sum(last) / len(last))
    return out


def faults_by_kind(events: list[dict[str, Any]], kinds: list[str]) -> dict[str, list[int]]:
    """Epochs at which each kind went in: the supervisor's `fault` events (the request), a crash by its `resume`."""
    at: dict[str, list[int]] = {k: [] for k in kinds}
    for e in events:
        if e["event"] == "fault":
            kind = e["detail"].split(" ", 1)[0]
            if kind in at:
                at[kind].append(e["epoch"])
        elif e["event"] == "resume" and "crash" in at:
            at["crash"].append(e["epoch"])
    return at


def write(
    path: Path,
    free: list[dict[str, Any]],
    chaos: list[dict[str, Any]],
    events: list[dict[str, Any]],
    kinds: list[str],
    title: str,
) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, mid, low) = plt.subplots(
        3, 1, figsize=(11, 8), sharex=True, gridspec_kw={"height_ratios": [2, 1.2, 2.2]}, constrained_layout=True
    )
    for rows, label, style in ((free, "fault-free", dict(color="0.55")), (chaos, "chaos", dict(color="tab:red"))):
        epochs = [r["epoch"] for r in rows]
        errors = [r["final_error"] for r in rows]
        top.plot(epochs, errors, ".", ms=2, label=label, **style)
        mid.plot(epochs, rolling_share(errors), lw=1.4, label=label, **style)
    top.axhline(0.5, color="k", lw=0.6, ls="--")
    top.set_yscale("log")
    top.set_ylabel("final error")
    top.legend(loc="upper right", markerscale=5)
    top.set_title(title, fontsize=10)
    mid.set_ylim(-0.05, 1.05)
    mid.set_ylabel(f"within 0.5,\nlast {WINDOW} epochs")
    at = faults_by_kind(events, kinds)
    for row, kind in enumerate(kinds):
        low.plot(at[kind], [row] * len(at[kind]), "|", ms=7, color="tab:blue" if kind != "crash" else "tab:red")
    for epoch in at.get("crash", []):
        for ax in (top, mid):
            ax.axvline(epoch, color="tab:red", lw=0.4, alpha=0.5)
    low.set_yticks(range(len(kinds)), [f"{k} ({len(at[k])})" for k in kinds], fontsize=8)
    low.set_ylim(-0.7, len(kinds) - 0.3)
    low.invert_yaxis()
    low.set_xlabel("epoch")
    low.set_ylabel("faults sent")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
