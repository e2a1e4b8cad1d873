"""The docs site and README stay true to the code (quick checks; the strict site build itself is
the ``mkdocs build --strict`` command of README, run by ``tests/test_doc_commands.py``).

* README is at most 150 lines and every relative link in it resolves to a file;
* the one apt line of README and docs/getting-started.md installs exactly the Debian packages
  ``.ci/run`` installs;
* the generated CLI page documents every command the live parser has;
* the generated API pages cover every public module of the package (listed from the files on
  disk, independently of the hook's own walk);
* every hand-written page in ``docs/`` is in the navigation.
"""

from __future__ import annotations

import importlib.util
import itertools
import re
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def _hooks():
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "hooks.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _apt_packages(text: str) -> set[str]:
    m = re.search(r"apt-get install -y (?:--no-install-recommends )?\\?\s*(.+?)(?:\n\S|\n\n|$)",
                  text, flags=re.S)  # fmt: skip
    assert m, "no apt-get install line"
    words = re.sub(r"\\\n", " ", m.group(1)).split()
    return {w for w in words if re.fullmatch(r"[a-z0-9][a-z0-9.+-]+", w)}


def test_readme_is_short_and_its_links_resolve():
    text = README.read_text()
    assert len(text.splitlines()) <= 150
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text)
    assert any(link.startswith("docs/") for link in links)
    missing = [link for link in links if "://" not in link and not (ROOT / link).exists()]
    assert not missing, missing


def test_apt_line_is_the_ci_one():
    ci = _apt_packages((ROOT / ".ci" / "run").read_text())
    assert {"gcc", "gcc-avr", "simavr", "arduino-mk", "libtbb12"} <= ci
    for page in (README, ROOT / "docs" / "getting-started.md"):
        assert _apt_packages(page.read_text()) == ci, page.name


def test_cli_page_documents_every_command():
    page = _hooks().cli_page()
    names = re.findall(r"^## `(grasprom[^`]*)`", page, flags=re.M)
    assert names[0] == "grasprom" and len(names) == len(set(names))
    top = set(re.findall(r"^\s{4}(\w+)\s{2,}", page.split("## `grasprom build`")[0], re.M))
    assert top >= {"build", "sweep", "surrogate", "simulate", "tune", "export", "diagnose"}
    for cmd in top:
        assert any(n.split()[1:2] == [cmd] for n in names[1:]), cmd
    assert "--contact {stick,frictionless,coulomb}" in page


def test_api_pages_cover_every_public_module():
    hooks = _hooks()
    on_disk = set()
    for path in (ROOT / "grasprom").rglob("*.py"):
        rel = path.relative_to(ROOT).with_suffix("")
        parts = rel.parts if rel.name != "__init__" else rel.parts[:-1]
        if len(parts) > 2 and not any(p.startswith("_") for p in parts):
            on_disk.add(".".join(parts))
    documented = set()
    for stage, _ in hooks.STAGES:
        page = hooks.api_page(stage, "t")
        documented |= set(re.findall(r"^::: (grasprom\.[\w.]+)$", page, flags=re.M))
    stages = {f"grasprom.{s}" for s, _ in hooks.STAGES}
    expected = {m for m in on_disk if ".".join(m.split(".")[:2]) in stages}
    assert expected and expected <= documented, sorted(expected - documented)
    pkg = ROOT / "grasprom"
    top = {p.stem for p in pkg.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert {f"grasprom.{t}" for t in top if not t.startswith("_")} == stages


def test_every_docs_page_is_in_the_navigation():
    nav = yaml.safe_load((ROOT / "mkdocs.yml").read_text())["nav"]
    flat = re.findall(r"[\w/-]+\.md", str(nav))
    pages = {p.relative_to(ROOT / "docs").as_posix() for p in (ROOT / "docs").rglob("*.md")}
    assert pages <= set(flat), sorted(pages - set(flat))
    generated = {"cli.md", "examples.md", "api/index.md"}
    assert generated <= set(flat) and not generated & pages  # generated, never written by hand


def _inline_commands(prefix: str) -> list[tuple[str, str]]:
    """``(page, span)`` of every inline code span starting with ``prefix`` (e.g. ``"grasprom
    "``; returned without it) in README and the hand-written docs pages (fenced blocks
    excluded: tests/test_doc_commands.py runs those)."""
    out = []
    for page in [README, *sorted((ROOT / "docs").glob("*.md"))]:
        text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
        pattern = rf"`{re.escape(prefix)}([^`]+)`"
        out += [(page.name, m.group(1)) for m in re.finditer(pattern, text)]
    return out


def test_inline_commands_name_real_options_and_paste():
    """Inline ``grasprom ...`` spans are names of commands and options, or commands that paste:
    no usage notation (``[...]``, a literal ``...``) and every ``--option`` they show exists in
    the live parser of the command they name (``a|b`` alternatives each checked)."""
    from grasprom.cli import cli_help_pages

    helps = dict(cli_help_pages())
    spans = _inline_commands("grasprom ")
    assert len(spans) > 40  # the docs do name commands inline
    bad = []
    for page, span in spans:
        if "[" in span or "..." in span:
            bad.append((page, span, "usage notation"))
            continue
        words = span.split()
        head = ["grasprom"] + [w for w in words if not w.startswith("-")][:2]
        for cmd_words in itertools.product(*(w.split("|") for w in head)):  # a|b: each
            joined = " ".join(cmd_words)
            cmd = max((c for c in helps if joined.startswith(c)), key=len)
            for w in words:
                opt = w.split("=")[0]
                if opt.startswith("--") and not re.search(rf"{re.escape(opt)}\b", helps[cmd]):
                    bad.append((page, span, f"{cmd} has no {opt}"))
    assert not bad, bad


def test_inline_python_commands_name_real_files_and_options():
    """Inline ``python ...`` spans (the "reproduce" commands of README and the docs): the
    script or test file exists, no usage notation, every ``--option`` is one the script
    defines (checked in its source: these are long runs; the benchmarks' own runs are in
    ``benchmarks/``), and a ``tests/...::name`` test exists."""
    bad = []
    spans = _inline_commands("python ")
    assert len(spans) > 20
    for page, span in spans:
        if "[" in span or "..." in span:
            bad.append((page, span, "usage notation"))
            continue
        words = span.split()
        pytest_run = words[:2] == ["-m", "pytest"]
        files = [w for w in words[2:] if "/" in w] if pytest_run else words[:1]
        if not files:
            continue  # `python -m pytest -q`: the whole suite
        path, _, test = files[0].partition("::")
        src = ROOT / path
        if not src.exists():
            bad.append((page, span, f"no file {path}"))
            continue
        code = src.read_text()
        if test and f"def {test}(" not in code:
            bad.append((page, span, f"no test {test}"))
        if not pytest_run:
            bad += [(page, span, f"{path} has no {w}") for w in words[1:]
                    if w.startswith("--") and f'"{w.split("=")[0]}"' not in code]  # fmt: skip
    assert not bad, bad
