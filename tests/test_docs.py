"""The documentation holds together: every relative link and image in README.md and docs/*.md
names a file of the repository (and a `#anchor` a heading of that file, by GitHub's slug rules),
every docs page is reachable from docs/index.md, the README stays a front door (at most 300
lines), and the README's Python example runs as written."""

from __future__ import annotations

import pathlib
import re
import time
import unicodedata
from urllib.parse import unquote

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[1]
README = REPO / "README.md"
DOCS = REPO / "docs"
PAGES = [README, *sorted(DOCS.glob("*.md"))]

FENCE = re.compile(r"^\s*(```|~~~)")
# [text](target) and ![alt](target); the target ends at whitespace (an optional "title" follows).
LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
HTML_SRC = re.compile(r"<(?:img|a)\s[^>]*(?:src|href)=\"([^\"]+)\"")
CODE_SPAN = re.compile(r"`[^`]*`")


def prose_lines(path: pathlib.Path):
    """(line number, text) outside fenced code blocks, inline code spans blanked."""
    inside = False
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if FENCE.match(line):
            inside = not inside
            continue
        if not inside:
            yield n, CODE_SPAN.sub("``", line)


def links(path: pathlib.Path) -> list[tuple[int, str]]:
    out = []
    for n, line in prose_lines(path):
        out += [(n, m.group(1)) for m in LINK.finditer(line)]
        out += [(n, m.group(1)) for m in HTML_SRC.finditer(line)]
    return out


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: the rendered text (links, code and emphasis marks dropped),
    lower case, punctuation removed (letters, marks, digits, `_`, `-` and spaces kept), each
    space a hyphen."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)
    text = text.replace("`", "").replace("*", "")
    text = text.strip().lower()
    kept = "".join(
        c for c in text
        if c in " -_" or unicodedata.category(c)[0] in "LM" or unicodedata.category(c) in ("Nd", "Nl")
    )
    return kept.replace(" ", "-")


def anchors(path: pathlib.Path) -> set[str]:
    """Every heading's anchor in `path`, duplicates numbered as GitHub numbers them."""
    seen: dict[str, int] = {}
    out = set()
    inside = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if FENCE.match(line):
            inside = not inside
            continue
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if inside or not m:
            continue
        base = slug(m.group(1))
        k = seen.get(base, 0)
        seen[base] = k + 1
        out.add(base if k == 0 else f"{base}-{k}")
    return out


def resolve(page: pathlib.Path, target: str) -> tuple[pathlib.Path | None, str | None]:
    """The file and anchor a relative link names; (None, None) for an external one."""
    if re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target):
        return None, None
    file, _, anchor = target.partition("#")
    path = page if not file else (page.parent / unquote(file)).resolve()
    return path, (unquote(anchor) or None)


def test_the_slug_follows_githubs_rules():
    # Examples worked by hand from GitHub's renderer: punctuation goes, spaces become hyphens
    # one for one, case folds, `code` keeps its text, accented letters stay.
    assert slug("Cycles' random walk") == "cycles-random-walk"
    assert slug("Benchmark like Mertens' Table 3") == "benchmark-like-mertens-table-3"
    assert slug("`translucent.cycles`") == "translucentcycles"
    assert slug("Walks: the geometry a half-space cannot see") == "walks-the-geometry-a-half-space-cannot-see"
    assert slug("A  b") == "a--b"
    assert slug("Référence") == "référence"


def dead_links(page: pathlib.Path, repo: pathlib.Path = REPO) -> list[str]:
    """Every relative link or image of `page` that names no file of `repo`, or no heading of it."""
    bad = []
    for n, target in links(page):
        path, anchor = resolve(page, target)
        if path is None:
            continue
        where = f"{page.name}:{n}: {target}"
        if repo not in path.parents:
            bad.append(f"{where}: outside the repository")
        elif not path.exists():
            bad.append(f"{where}: no such file")
        elif anchor is not None:
            if path.suffix != ".md":
                bad.append(f"{where}: an anchor into a file that is not Markdown")
            elif anchor not in anchors(path):
                bad.append(f"{where}: no heading with anchor #{anchor} in {path.name}")
    return bad


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_and_image_resolves(page):
    bad = dead_links(page)
    assert not bad, "\n".join(bad)


def test_the_link_checker_finds_dead_links_and_anchors(tmp_path):
    (tmp_path / "other.md").write_text("# Other page\n\n## Its part\n")
    (tmp_path / "fig.png").write_bytes(b"")
    page = tmp_path / "page.md"
    page.write_text(
        "# Title\n\n[ok](#title) [dead](#nowhere) [gone](missing.md) `[not a link](x.md)`\n"
        "![fig](fig.png) ![lost](lost.png) [there](other.md#its-part) [not there](other.md#nope)\n"
        "[out](../../etc/passwd) [web](https://example.org/x.md)\n"
        "```\n[in a code block](y.md)\n```\n"
    )
    bad = dead_links(page, repo=tmp_path)
    assert [b.split(": ")[1] for b in bad] == [
        "#nowhere", "missing.md", "lost.png", "other.md#nope", "../../etc/passwd"
    ], bad


def test_every_docs_page_is_reachable_from_the_index():
    index = DOCS / "index.md"
    reached, todo = {index}, [index]
    while todo:
        page = todo.pop()
        for _, target in links(page):
            path, _ = resolve(page, target)
            if path is not None and path.suffix == ".md" and path.parent == DOCS and path.exists():
                if path not in reached:
                    reached.add(path)
                    todo.append(path)
    missing = sorted(p.name for p in DOCS.glob("*.md") if p not in reached)
    assert not missing, f"not reachable from docs/index.md: {missing}"


def test_the_readme_is_a_front_door():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 300, f"README.md has {len(lines)} lines; move detail into docs/"
    assert "docs/index.md" in README.read_text(encoding="utf-8")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_the_docs_cite_no_file_outside_the_repository(page):
    text = page.read_text(encoding="utf-8")
    for outside in ("DESIGN.md", "../shared", "/work/"):
        assert outside not in text, f"{page.relative_to(REPO)} names {outside!r}, which is not in the repository"


def readme_example() -> str:
    blocks = re.findall(r"^```python\n(.*?)^```", README.read_text(encoding="utf-8"), re.S | re.M)
    assert blocks, "README.md has no ```python example"
    return blocks[0]


@pytest.mark.slow
def test_the_readme_example_runs():
    pytest.importorskip("trimesh", reason="the README's example builds its ball with trimesh")
    start = time.perf_counter()
    names: dict[str, object] = {"__name__": "readme_example"}
    exec(compile(readme_example(), "README.md (example)", "exec"), names)
    seconds = time.perf_counter() - start
    bake, edit, ball = np.asarray(names["bake"]), np.asarray(names["edit"]), names["ball"]
    n = len(ball.vertices)
    assert bake.shape == edit.shape == (n, 3)
    assert np.isfinite(bake).all() and (bake >= 0).all()
    # What a sun from straight above must give, whatever the method: the upper half brighter
    # than the lower, and a redder Base Color redder (less green and blue, relative to red).
    up = ball.vertices[:, 2] > 0
    assert bake[up].mean() > 3 * bake[~up].mean()
    ratio = lambda b: b[up, 1:].mean() / b[up, 0].mean()  # noqa: E731
    assert ratio(edit) < ratio(bake)
    print(f"README example: {seconds:.1f} s")
