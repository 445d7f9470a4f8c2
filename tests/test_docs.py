"""The documentation: the site builds with warnings as errors, the README's links resolve, the code
cites pages and anchors that exist, and every command shown in a shell code block of the docs
runs against the current code: its scripts and modules exist, its ``--flags`` are the scripts'
own, its Hydra overrides compose against ``conf/`` and pass the app's validation, and the pip
extras it names are declared.

The build needs the ``docs`` extra (``pip install -c constraints.txt -e '.[docs]'``); without it
that test is skipped, so ``pytest -q`` with only ``.[dev]`` still passes. CI installs both.
"""

import contextlib
import importlib
import importlib.util
import io
import os
import re
import shlex
import subprocess
import sys
import textwrap
from concurrent.futures import ThreadPoolExecutor
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


# --- every command shown in a code block of the docs runs against the current code and config ---

_SHELL_BLOCK = re.compile(r"^[ \t]*```(?:bash|sh|shell|console)[ \t]*\n(.*?)^[ \t]*```", re.M | re.S)
_SEPARATORS = {"&&", "||", ";", "|", "&"}
#: The Hydra apps: script -> its primary config (read from ``@hydra.main(config_name=...)``).
_HYDRA_FLAGS = {"-m", "--multirun"}


def _doc_pages():
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def _shell_commands(block: str):
    """The commands of a shell block: continuation lines joined, comments dropped, split at
    ``&&``, ``;`` and pipes, leading ``VAR=value`` assignments dropped."""
    text = re.sub(r"\\\n", " ", block)
    for line in text.splitlines():
        lex = shlex.shlex(line, posix=True, punctuation_chars=";&|")
        lex.whitespace_split = True
        lex.commenters = "#"
        command = []
        for token in list(lex) + [";"]:
            if token in _SEPARATORS:
                while command and re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", command[0]):
                    command.pop(0)
                if command:
                    yield command
                command = []
            else:
                command.append(token)


def _python_commands():
    """``(page, script_or_module, args)`` of every ``python ...`` command in the docs' shell blocks."""
    out = []
    for page in _doc_pages():
        for block in _SHELL_BLOCK.findall(page.read_text(encoding="utf-8")):
            for cmd in _shell_commands(block):
                if not re.search(r"(^|/)python3?$", cmd[0]) or len(cmd) < 2:
                    continue
                if cmd[1] == "-m":
                    out.append((page.relative_to(ROOT), f"-m {cmd[2]}", cmd[3:]))
                elif cmd[1].endswith(".py"):
                    out.append((page.relative_to(ROOT), cmd[1], cmd[2:]))
    return out


def _hydra_config(script: str) -> str | None:
    m = re.search(r"@hydra\.main\([^)]*config_name=\"(\w+)\"", (ROOT / script).read_text(encoding="utf-8"))
    return m.group(1) if m else None


def test_docs_show_commands():
    commands = _python_commands()
    assert len(commands) > 40, "the docs' shell blocks should hold the commands of the how-to guides"
    scripts = {s for _, s, _ in commands}
    assert {"experiments/abstract.py", "experiments/simulate.py", "-m tubejax"} <= scripts


def _help_argv(script: str, args: list[str]) -> list[str] | None:
    """The ``--help`` command line of an argparse script or module (``None``: a Hydra app, or a
    module the docs only install or test with)."""
    if script.startswith("-m "):
        module = script[3:]
        return None if module in ("pytest", "venv", "pip") else [sys.executable, "-m", module, *args[:1], "--help"]
    if _hydra_config(script) is not None:
        return None                                                          # the Hydra apps: next test
    return [sys.executable, str(ROOT / script), "--help"]


def _help_text(argv: list[str]) -> str:
    proc = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 0, f"{' '.join(argv)} failed:\n{proc.stderr[-2000:]}"
    return proc.stdout


@pytest.mark.slow
def test_docs_commands_name_real_scripts_and_flags():
    """Every script and module a docs command runs exists, and every ``--flag`` it passes to an
    argparse script is one that script's ``--help`` lists."""
    bad, todo = [], []
    for page, script, args in _python_commands():
        if script.startswith("-m ") and importlib.util.find_spec(script[3:]) is None:
            bad.append(f"{page}: python {script}: no such module")
        elif not script.startswith("-m ") and not (ROOT / script).is_file():
            bad.append(f"{page}: {script} does not exist")
        elif (argv := _help_argv(script, args)) is not None:
            todo.append((page, script, args, tuple(argv)))
    with ThreadPoolExecutor(max_workers=4) as pool:                          # each --help imports the package
        distinct = sorted({argv for *_, argv in todo})
        helps = dict(zip(distinct, pool.map(_help_text, distinct)))
    for page, script, args, argv in todo:
        for a in args:
            flag = a.split("=", 1)[0]
            if flag.startswith("--") and not re.search(rf"(?<![\w-]){re.escape(flag)}(?![\w-])", helps[argv]):
                bad.append(f"{page}: {script} has no option {flag}")
    assert not bad, "\n".join(bad)


def _expanded(overrides: list[str]) -> list[list[str]]:
    """Every value of every sweep, one sweep at a time (the others at their first value)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parsed = [OverridesParser.create().parse_overrides([o])[0] for o in overrides]
    values = []
    for o in parsed:
        if not o.is_sweep_override():
            values.append([o.input_line])
            continue
        vs = [f"{o.get_key_element()}={v}" for v in o.sweep_string_iterator()]
        values.append(vs if o.is_discrete_sweep() else vs[:1] + vs[-1:])     # range(64): its ends
    first = [v[0] for v in values]
    out = [first]
    for k, vs in enumerate(values):
        out += [first[:k] + [v] + first[k + 1:] for v in vs[1:]]
    return out


#: Paths the docs show as placeholders for the user's own files (checked to exist elsewhere).
_PLACEHOLDERS = {"workspace.map_file": "conf/workspace/maps/paper.txt"}


@pytest.mark.slow
def test_docs_hydra_overrides_compose_and_validate():
    """Every Hydra command line in the docs composes against the current config (every key and
    every group option exists: Hydra's compose API, sweeps expanded value by value, ``hydra.*``
    included), names only keys its app reads, and its values pass the app's own validation
    (:func:`sweep_jobs.check_job`: the input model, the cells, the app's settings). A user's own
    file (``workspace.map_file=big.txt``, a learned ``zshape.file``, an ``abstraction_dir``) is
    replaced by a real one or left out, since the docs cannot ship it."""
    pytest.importorskip("hydra")
    from hydra import compose, initialize_config_dir
    from hydra.core.hydra_config import HydraConfig
    from omegaconf import OmegaConf

    sys.path.insert(0, str(ROOT / "experiments"))
    try:
        from common import check_keys
        from sweep_jobs import check_job
    finally:
        sys.path.remove(str(ROOT / "experiments"))
    has_submitit = importlib.util.find_spec("hydra_plugins.hydra_submitit_launcher") is not None
    bad, n, cache = [], 0, {}
    for page, script, args in _python_commands():
        config = None if script.startswith("-m ") else _hydra_config(script)
        if config is None:
            continue
        unknown = [a for a in args if a.startswith("-") and a not in _HYDRA_FLAGS]
        if unknown:
            bad.append(f"{page}: {script} {unknown}: not a Hydra flag")
            continue
        overrides = [re.sub(r"\$\{?[A-Z_][A-Z0-9_]*\}?", "0", a)                  # $SLURM_ARRAY_TASK_ID
                     for a in args if not a.startswith("-")]
        if not has_submitit and "hydra/launcher=slurm" in overrides:
            assert (ROOT / "conf/hydra/launcher/slurm.yaml").is_file()
            overrides = [o for o in overrides                                # needs hydra-submitit-launcher
                         if o != "hydra/launcher=slurm" and not o.startswith("hydra.launcher.")]
        for ovs in _expanded(overrides):
            n += 1
            where = f"{page}: {script} {' '.join(ovs)}"
            try:
                with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base=None):
                    cfg = compose(config_name=config, overrides=ovs, return_hydra_config=True)
                c = OmegaConf.to_container(cfg, resolve=False)
                c.pop("hydra")
                c = OmegaConf.to_container(OmegaConf.create(c), resolve=True)
                check_keys(c, config)
                for dotted, real in _PLACEHOLDERS.items():
                    section, key = dotted.split(".")
                    if key in c[section] and not (ROOT / str(c[section][key])).exists():
                        c[section][key] = real
                if c.get("zshape", {}).get("file"):
                    c["zshape"]["file"] = None
                if c.get("abstraction_dir"):
                    c["abstraction_dir"] = None
                HydraConfig.instance().set_config(cfg)                       # the app's own name, as when it runs
                check_job(c, cache)
            except Exception as exc:                 # noqa: BLE001 -- every failure is a finding
                bad.append(f"{where}: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}")
            finally:
                HydraConfig.instance().cfg = None
    assert n > 30
    assert not bad, "\n".join(bad)


def test_docs_pip_extras_exist():
    """``pip install ... -e '.[extra]'`` in the docs names extras that pyproject.toml declares."""
    import tomllib

    extras = set(tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
                 ["optional-dependencies"])
    shown = set()
    for page in _doc_pages():
        for block in _SHELL_BLOCK.findall(page.read_text(encoding="utf-8")):
            for m in re.finditer(r"\.\[([\w,-]+)\]", block):
                shown |= set(m.group(1).split(","))
    assert shown and shown <= extras, f"extras shown but not declared: {shown - extras}"


_PYTHON_BLOCK = re.compile(r"^[ \t]*```python[ \t]*\n(.*?)^[ \t]*```", re.M | re.S)


def _python_blocks():
    for page in _doc_pages():
        for block in _PYTHON_BLOCK.findall(page.read_text(encoding="utf-8")):
            yield page.relative_to(ROOT), textwrap.dedent(block)


def test_docs_python_blocks_name_real_code():
    """Every Python block in the docs parses, every ``from tubejax... import name`` in it imports,
    and every ``tj.name`` it uses is part of the public API (``import tubejax as tj``)."""
    import ast

    import tubejax as tj

    bad, n = [], 0
    for page, code in _python_blocks():
        n += 1
        try:
            tree = ast.parse(code)
        except SyntaxError as exc:
            bad.append(f"{page}: a Python block does not parse ({exc.msg}, line {exc.lineno})")
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "tubejax":
                module = importlib.import_module(node.module)
                bad += [f"{page}: from {node.module} import {a.name}: no such name"
                        for a in node.names if not hasattr(module, a.name)]
            elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "tj":
                if not hasattr(tj, node.attr):
                    bad.append(f"{page}: tj.{node.attr} is not in the public API")
    assert n >= 8
    assert not bad, "\n".join(bad)


def test_troubleshooting_recipe_prints_what_the_page_shows():
    """The recipe of docs/howto/troubleshooting.md#why-is-this-pair-not-an-edge runs and prints the
    output shown under it (the binding rows of the worked pair one step short of its horizon)."""
    text = (ROOT / "docs" / "howto" / "troubleshooting.md").read_text(encoding="utf-8")
    section = text.split("## Why is this pair not an edge?")[1].split("\n## ")[0]
    code = _PYTHON_BLOCK.findall(section)[0]
    shown = re.search(r"```text\n(.*?)```", section, re.S).group(1)
    out = io.StringIO()
    cwd = os.getcwd()
    try:
        os.chdir(ROOT)
        with contextlib.redirect_stdout(out):
            exec(compile(code, "troubleshooting.md", "exec"), {})
    finally:
        os.chdir(cwd)
    assert out.getvalue() == shown
