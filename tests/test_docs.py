"""The documentation: the site builds with warnings as errors, and the README's links resolve.

The build needs the ``docs`` extra (``pip install -c constraints.txt -e '.[docs]'``); without it
that test is skipped, so ``pytest -q`` with only ``.[dev]`` still passes. CI installs both.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _slug(heading: str) -> str:
    """The anchor of a Markdown heading, as Python-Markdown's toc and GitHub both make it."""
    text = re.sub(r"[^\w\s-]", "", heading.replace("`", "")).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def test_docs_build_strict(tmp_path):
    for module in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python"):
        pytest.importorskip(module, reason="the docs extra is not installed")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file",
                           str(ROOT / "mkdocs.yml"), "--site-dir", str(tmp_path / "site")],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{proc.stdout}\n{proc.stderr}"
    for page in ("index.html", "getting-started.html", "math/tube-lp.html", "howto/sweeps.html",
                 "reference/formats.html", "reference/api/abstraction.html"):
        assert (tmp_path / "site" / page).is_file(), page
    api = (tmp_path / "site" / "reference/api/abstraction.html").read_text(encoding="utf-8")
    assert "build_abstraction" in api and ":func:`" not in api


def test_readme_links_resolve():
    """Every relative link of the README names an existing file, and every anchor a heading there."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    links = re.findall(r"\]\(([^)\s]+)\)", text) + re.findall(r'src="([^"]+)"', text)
    assert links
    bad = []
    for link in links:
        if re.match(r"[a-z]+:", link):
            continue
        path, _, anchor = link.partition("#")
        target = ROOT / path if path else ROOT / "README.md"
        if not target.exists():
            bad.append(link)
        elif anchor:
            headings = re.findall(r"^#{1,6} (.+?)\s*$", target.read_text(encoding="utf-8"), re.M)
            if anchor not in {_slug(h) for h in headings}:
                bad.append(link)
    assert not bad, f"README links that do not resolve: {bad}"


def test_readme_keeps_the_two_commands():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    install = "python3 -m venv .venv && .venv/bin/pip install -q -c constraints.txt -e '.[dev]'"
    assert f"{install} && .venv/bin/python experiments/paper.py" in text
    assert f"{install} && .venv/bin/python -m pytest -q" in text


def _cited_pages():
    """``(file, line, page, anchor)`` of every ``docs/....md[#anchor]`` cited in the code and configs."""
    own = Path(__file__).resolve()
    for folder in ("tubejax", "experiments", "scripts", "notebooks", "tests", "conf"):
        for path in sorted((ROOT / folder).rglob("*")):
            if path.suffix not in (".py", ".yaml") or path.resolve() == own:
                continue
            for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                for page, anchor in re.findall(r"\b(docs/[\w./-]+\.md)(?:#([\w-]+))?", line):
                    yield path.relative_to(ROOT), i, page, anchor


def test_code_citations_resolve():
    """The code cites the mathematics as ``docs/math/<page>.md[#anchor]``: every page and anchor exists."""
    bad, n = [], 0
    for where, line, page, anchor in _cited_pages():
        n += 1
        target = ROOT / page
        if not target.is_file():
            bad.append(f"{where}:{line}: {page} does not exist")
        elif anchor:
            headings = re.findall(r"^#{1,6} (.+?)\s*$", target.read_text(encoding="utf-8"), re.M)
            if anchor not in {_slug(h) for h in headings}:
                bad.append(f"{where}:{line}: {page} has no heading #{anchor}")
    assert n > 50, "the code should cite the docs pages"
    assert not bad, "\n".join(bad)


def test_no_citations_of_the_old_specification():
    """``SPEC section N`` pointed to a file a clone does not have; cite docs/math/*.md instead."""
    own = Path(__file__).resolve()
    bad = []
    for folder in ("tubejax", "experiments", "scripts", "notebooks", "tests", "conf"):
        for path in sorted((ROOT / folder).rglob("*")):
            if path.suffix in (".py", ".yaml") and path.resolve() != own:
                for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                    if re.search(r"\bSPEC\b|SPEC\.md", line):
                        bad.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert not bad, "cite docs/math/<page>.md (see docs/math/index.md#citations):\n" + "\n".join(bad)
