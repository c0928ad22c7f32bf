"""The docs stand on their own: a reader with a clone of this repository and nothing else can follow every link in
the README and docs/, and no page (nor a docstring or comment of the code) sends them to a file they do not have —
a design page kept beside the repository, a checkout on one machine, a scratch directory."""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SKIP_DIRS = frozenset({".git", ".venv", "runs", "__pycache__", ".pytest_cache", ".ruff_cache", ".hypothesis"})

#: a design page kept beside the repository, by its path, its name or one of its sections
DESIGN_PAGE = (re.compile(r"\.\./shared\b"), re.compile(r"\bDESIGN(\.md|\s*§)"))
#: an absolute path under a root where a checkout, a home or a scratch directory lives; a system path every Linux
#: reader has (/proc/stat, /usr/bin/time) is not one, and the code may use /tmp or /proc as data (tests' fixtures)
ABSOLUTE = re.compile(r"(?<![\w.:/~-])/(?:work|home|root|Users|tmp|mnt|srv|scratch)\b")
OUTSIDE = (*DESIGN_PAGE, ABSOLUTE)

FENCE = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)
CODE_SPAN = re.compile(r"`[^`\n]*`")
LINK = re.compile(r"!?\[[^\]\n]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
HEADING = re.compile(r"^#{1,6}\s+(.+?)\s*#*\s*$", re.M)


def _walk(top: Path, suffixes: tuple[str, ...] | None = None) -> list[Path]:
    out = []
    for path in sorted(top.rglob("*")):
        if any(part in SKIP_DIRS or part.endswith(".egg-info") for part in path.relative_to(ROOT).parts):
            continue
        if path.is_file() and (suffixes is None or path.suffix in suffixes):
            out.append(path)
    return out


def _text(path: Path) -> str | None:
    """The file's text, or None for a binary file (an image)."""
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        return None


def _doc_files() -> list[Path]:
    return [ROOT / "README.md", *_walk(ROOT / "docs")]


def _markdown() -> list[Path]:
    return [ROOT / "README.md", *_walk(ROOT / "docs", (".md",))]


def _code_files() -> list[Path]:
    """The code and the files shipped beside it (run files, plans), where a docstring or comment could point out."""
    own = Path(__file__).resolve()
    tops = ("protocol", "actors", "sim", "experiments", "benchmarks", "tests", "deploy", "examples", "scenarios")
    files = [p for top in tops if (ROOT / top).is_dir() for p in _walk(ROOT / top, (".py", ".toml", ".sh"))]
    return [p for p in files if p.resolve() != own] + [ROOT / "pyproject.toml"]


def _outside_refs(paths: list[Path], patterns: tuple[re.Pattern[str], ...] = OUTSIDE) -> list[str]:
    found = []
    for path in paths:
        text = _text(path)
        if text is None:
            continue
        for n, line in enumerate(text.splitlines(), 1):
            found += [f"{path.relative_to(ROOT)}:{n}: {m.group(0)!r}" for rx in patterns for m in rx.finditer(line)]
    return found


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, markup and punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*_]|<[^>]+>", "", heading.strip()).lower()
    text = "".join(c for c in text if c in " -" or unicodedata.category(c)[0] in "LN")
    return text.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for m in HEADING.finditer(FENCE.sub("", path.read_text(encoding="utf-8"))):
        base = slug(m.group(1))
        k = seen.get(base, 0)
        seen[base] = k + 1
        out.add(base if k == 0 else f"{base}-{k}")
    return out


def _links(path: Path) -> list[tuple[int, str]]:
    """(line, target) of every markdown link and image outside code blocks and code spans."""
    text = FENCE.sub(lambda m: "\n" * m.group(0).count("\n"), path.read_text(encoding="utf-8"))
    out = []
    for n, line in enumerate(text.splitlines(), 1):
        out += [(n, m.group(1)) for m in LINK.finditer(CODE_SPAN.sub("", line))]
    return out


def _broken(path: Path) -> list[str]:
    bad = []
    for n, target in _links(path):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # https:, mailto: — the web, not the repository
            continue
        where = f"{path.relative_to(ROOT)}:{n}: ({target})"
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path.resolve()
        if not dest.is_relative_to(ROOT):
            bad.append(f"{where} leaves the repository")
        elif not dest.exists():
            bad.append(f"{where} names no file")
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            bad.append(f"{where} names no heading of {dest.relative_to(ROOT)}")
    return bad


def test_the_docs_name_no_file_outside_the_repository() -> None:
    assert _outside_refs(_doc_files()) == []


def test_the_code_names_no_file_outside_the_repository() -> None:
    assert _outside_refs(_code_files(), DESIGN_PAGE) == []


def test_every_relative_link_in_the_docs_points_at_a_file_that_exists() -> None:
    assert len(_markdown()) > 10, "the docs were not found"
    assert [b for path in _markdown() for b in _broken(path)] == []


@pytest.mark.parametrize(
    "text",
    [
        "The twin of `../shared/DESIGN.md`: what the code does",
        "at fixed points of the lockstep step (DESIGN §3):",
        "a script in /srv/ks/benchmarks",
        "(`/tmp` script around it)",
        "see /home/me/notes.md",
    ],
)
def test_the_outside_check_sees_what_it_is_for(text: str) -> None:
    assert any(rx.search(text) for rx in OUTSIDE)


@pytest.mark.parametrize(
    "text",
    ["`/usr/bin/time python x.py`", "(/proc/stat before and after)", "https://zenoh.io/docs/x", "tcp/127.0.0.1:0"],
)
def test_the_outside_check_lets_ordinary_text_pass(text: str) -> None:
    assert not any(rx.search(text) for rx in OUTSIDE)


def test_the_link_check_sees_a_broken_link_and_a_missing_heading(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(f"{__name__}.ROOT", tmp_path)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "there.md").write_text("# A page\n\n## Its part, one (§3)\n")
    page = tmp_path / "README.md"
    page.write_text(
        "[ok](docs/there.md) [ok too](docs/there.md#its-part-one-3) ![img](docs/gone.png)\n"
        "[no heading](docs/there.md#nowhere) [out](../elsewhere.md) [web](https://rerun.io)\n"
        "```\n[in a block](not/checked.md)\n```\n`[in a span](not/checked.md)`\n"
    )
    assert _broken(page) == [
        "README.md:1: (docs/gone.png) names no file",
        "README.md:2: (docs/there.md#nowhere) names no heading of docs/there.md",
        "README.md:2: (../elsewhere.md) leaves the repository",
    ]


MAP_FOLDERS = ("protocol", "sim", "actors", "experiments", "benchmarks")


def _map_entries(text: str) -> dict[str, str]:
    """docs/architecture.md's map (the tree under "Where everything lives"): each folder's entry (its lines up to the
    next folder at its depth or above), by the folder's path."""
    section = text.split("## Where everything lives", 1)[1].split("\n## ", 1)[0]
    tree = FENCE.search(section)
    assert tree is not None, "the map's tree is gone"
    entries: dict[str, list[str]] = {}
    stack: list[tuple[int, str]] = []  # (indent, path) of the folders the current line is inside
    for line in tree.group(0).splitlines()[1:-1]:
        indent = len(line) - len(line.lstrip())
        m = re.match(r"([\w.]+)/(?:\s|$)", line.lstrip())
        if m:
            while stack and stack[-1][0] >= indent:
                stack.pop()
            path = "/".join([*(p for _, p in stack[-1:]), m.group(1)])
            stack.append((indent, path))
            entries[path] = []
        if stack:
            entries[stack[-1][1]].append(line)
    return {path: "\n".join(lines) for path, lines in entries.items()}


def _unnamed(text: str) -> list[str]:
    """The modules of the code that the map does not name in their folder's entry (or, for a folder with no entry of
    its own, in the nearest enclosing one's)."""
    entries = _map_entries(text)
    out = []
    for top in MAP_FOLDERS:
        for path in _walk(ROOT / top, (".py",)):
            if path.name == "__init__.py":
                continue  # the folder itself
            folder = path.parent.relative_to(ROOT).as_posix()
            while folder not in entries and "/" in folder:
                folder = folder.rsplit("/", 1)[0]
            entry = entries.get(folder, "")
            if not re.search(rf"(?<![\w]){re.escape(path.stem)}(?![\w])", entry):
                out.append(str(path.relative_to(ROOT)))
    return out


def test_the_architecture_map_names_every_module() -> None:
    assert _unnamed((ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")) == []


def test_the_map_check_sees_a_module_left_out() -> None:
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    assert "actors/step/passes.py" in _unnamed(text.replace("step/          the step library", "stepx/ the step"))
    assert "protocol/codec.py" in _unnamed(text.replace("  codec ", "  cadec "))
