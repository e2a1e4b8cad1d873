"""Every shell command of README.md and docs/ runs as written.

Each fenced ``bash`` block of README.md and of the docs pages (in the site's navigation order)
is run with ``bash -euo pipefail`` in a scratch copy of the checkout, block after block, so a
later block may use what an earlier one of its group wrote (``build/`` of the main job,
``trials/`` of ``grasprom synth``; the two groups are below). A block fails the test when it
exits non-zero. Four documented rules are the only changes made to a command (the first three
keep the run inside the suite's budget):

* ``pip install ...`` runs as ``pip install --dry-run --no-deps ...`` (it must resolve; it must
  not replace the environment under test -- the real installs are run in a fresh virtual
  environment by ``tests/test_readme.py``);
* ``python -m pytest ...`` runs with ``--collect-only`` (running the suite from inside itself
  would recurse);
* a long command may carry a trailing comment ``# quick check: ARGS``: the test appends ARGS
  (later options win in argparse), the reader sees the same quick variant next to the command;
* a command documented to fail carries ``# expect exit N``: it must exit with exactly N (the
  page explains why), so the page changes when the behaviour does.

A block that repeats an earlier block of its group verbatim and writes nothing is not run again
(getting-started.md repeats README's install-and-test command; ``is_skipped_repeat``).

The pages run in two groups, each in its own checkout (the first steps; the pages from build.md
on, which opens with the main job), so the two can run at once; the two groups' commands write
to different ``/tmp`` folders (``test_the_groups_write_to_different_tmp_folders``).

Lines ending in ``&`` (a Dask scheduler and worker) run in the background; the block's whole
process group is killed when it ends. Marked ``slow`` (a few minutes): CI runs it in its second
step.
"""

from __future__ import annotations

import os
import re
import shlex
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests.checkout import copy_checkout

ROOT = Path(__file__).resolve().parents[1]
QUICK = re.compile(r"#\s*quick check:\s*(.+)$")
EXPECT = re.compile(r"#\s*expect exit (\d+)\b.*$")


def nav_pages() -> list[Path]:
    """README.md, then the hand-written docs pages in the site's navigation order."""
    nav = yaml.safe_load((ROOT / "mkdocs.yml").read_text())["nav"]
    pages: list[str] = []

    def walk(items):
        for item in items:
            value = next(iter(item.values())) if isinstance(item, dict) else item
            if isinstance(value, list):
                walk(value)
            else:
                pages.append(value)

    walk(nav)
    found = [ROOT / "docs" / p for p in pages if (ROOT / "docs" / p).exists()]
    return [ROOT / "README.md", *found]


def bash_blocks(page: Path) -> list[str]:
    """The fenced ``bash`` blocks of a Markdown page."""
    return re.findall(r"^```bash\n(.*?)^```", page.read_text(), flags=re.S | re.M)


def as_run(line: str) -> str:
    """One command line as the test runs it (the three rules of the module docstring)."""
    expect = EXPECT.search(line)
    if expect:
        cmd = as_run(line[: expect.start()].rstrip())
        return f'{{ {cmd}; }} && rc=0 || rc=$?; test "$rc" -eq {expect.group(1)}'
    quick = QUICK.search(line)
    if quick:
        line = line[: quick.start()].rstrip() + " " + quick.group(1).strip()
    line = re.sub(r"(^|&& |; )pip install ", r"\1pip install --dry-run --no-deps ", line)
    if re.search(r"python -m pytest\b", line):
        line = line.rstrip() + " --collect-only"
    return line


def as_script(block: str) -> str:
    """A block as the test runs it: continuation lines joined, each command rewritten."""
    joined = re.sub(r"[ \t]*\\\n\s*", " ", block)
    return "\n".join(as_run(line) for line in joined.splitlines())


def _run_block(script: str, cwd: Path, log: Path) -> tuple[int, str]:
    """Run one block; return its exit code and output.  The output goes to a file, not a pipe:
    a background process of the block (``dask scheduler &``) would hold a pipe open."""
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONPATH=str(cwd))
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    with open(log, "w") as out:
        cmd = ["bash", "-euo", "pipefail", "-c", script]
        proc = subprocess.Popen(
            cmd, cwd=cwd, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
        )
        try:
            code = proc.wait(timeout=900)
        except subprocess.TimeoutExpired:
            code = -1
        finally:
            try:
                os.killpg(proc.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
    return code, log.read_text()


def test_the_rules_rewrite_only_what_they_say():
    assert as_run("pip install -e . && grasprom build --out build") == (
        "pip install --dry-run --no-deps -e . && grasprom build --out build"
    )
    assert as_run('pip install -e ".[dev]" && python -m pytest -q').endswith(
        "python -m pytest -q --collect-only"
    )
    assert as_run("grasprom sweep --out x   # quick check: --n-circ 8") == (
        "grasprom sweep --out x --n-circ 8"
    )
    assert as_run("grasprom surrogate check s.json   # expect exit 1") == (
        '{ grasprom surrogate check s.json; } && rc=0 || rc=$?; test "$rc" -eq 1'
    )
    plain = "grasprom build --out build  # a comment"
    assert as_run(plain) == plain
    assert as_script("a \\\n    b\nc") == "a b\nc"


def test_every_page_with_commands_is_found():
    pages = {p.name for p in nav_pages() if bash_blocks(p)}
    assert {"README.md", "getting-started.md", "fe-sweeps.md", "fmu.md"} <= pages


#: The pages are run in two groups, each in its own checkout, so the two halves can run on the
#: two workers at once: the first steps (README, getting-started.md) and the pages from
#: build.md on, which opens with the main job and so writes the ``build/`` its later pages read.
SECOND_GROUP_OPENS = "build.md"


def page_groups() -> dict[str, list[Path]]:
    """:func:`nav_pages` split in two at :data:`SECOND_GROUP_OPENS`."""
    pages = nav_pages()
    cut = [p.name for p in pages].index(SECOND_GROUP_OPENS)
    return {"first steps": pages[:cut], "from the main job on": pages[cut:]}


def test_the_second_group_opens_with_the_main_job():
    groups = page_groups()
    with_commands = [p.name for p in groups["first steps"] if bash_blocks(p)]
    assert with_commands == ["README.md", "getting-started.md"]
    first = bash_blocks(groups["from the main job on"][0])[0]
    assert shlex.split(first.splitlines()[0], comments=True) == [
        "grasprom",
        "build",
        "--out",
        "build",
    ]
    assert sum(map(len, groups.values())) == len(nav_pages())


def test_the_groups_write_to_different_tmp_folders():
    """The two groups run at once: no ``/tmp/...`` folder may be named in both."""
    named = {
        group: {m for p in pages for b in bash_blocks(p) for m in re.findall(r"/tmp/[\w.-]+", b)}
        for group, pages in page_groups().items()
    }
    assert named["first steps"] and named["from the main job on"]
    assert not named["first steps"] & named["from the main job on"], named


def writes(block: str) -> set[str]:
    """The folders and files a block names as outputs: ``--out`` / ``--out-dir`` / ``--site-dir``
    targets (normalised: ``./build/`` is ``build``), and ``build`` for a ``grasprom build``
    without ``--out`` (its default)."""
    found = {os.path.normpath(p) for p in re.findall(r"--(?:out|out-dir|site-dir)[ =](\S+)", block)}
    for cmd in re.split(r"&&|;|\n", block):
        words = cmd.split("#")[0].split()
        if words[:2] == ["grasprom", "build"] and "--out" not in words:
            found.add("build")
    return found


def is_skipped_repeat(block: str, earlier: list[str]) -> bool:
    """A block that repeats an earlier block of its group verbatim and writes nothing is not run
    again: it ran, and nothing it reads is different. A repeat that writes runs again (the
    getting-started page's ``grasprom build --out build`` rebuilds README's ``build/``: the
    one documented rebuild into a full output folder)."""
    return block in earlier and not writes(block)


def test_only_a_repeat_that_writes_nothing_is_skipped():
    skipped = []
    for pages in page_groups().values():
        blocks = [b for p in pages for b in bash_blocks(p)]
        skipped += [b for j, b in enumerate(blocks) if is_skipped_repeat(b, blocks[:j])]
    assert [b.strip() for b in skipped] == ['pip install -e ".[dev]" && python -m pytest -q']
    assert writes("grasprom build --out ./build-le/ --x 1\nmkdocs build --site-dir /tmp/s") == {
        "build-le",
        "/tmp/s",
    }
    assert writes("pip install -e . && grasprom build --material le  # no --out") == {"build"}
    assert writes("pip install -e . && python -m pytest -q") == set()


@pytest.mark.parametrize(
    "group",
    [
        pytest.param("first steps", marks=pytest.mark.slow(seconds=207)),
        pytest.param("from the main job on", marks=pytest.mark.slow(seconds=134)),
    ],
)
def test_every_documented_command_runs_as_written(tmp_path, group):
    work = tmp_path / "checkout"
    work.mkdir()
    copy_checkout(work)
    failures = []
    done: list[str] = []
    for page in page_groups()[group]:
        for i, block in enumerate(bash_blocks(page), 1):
            if is_skipped_repeat(block, done):
                continue
            done.append(block)
            code, out = _run_block(as_script(block), work, tmp_path / f"{page.stem}_{i}.log")
            if code != 0:
                failures.append(f"{page.name} block {i} (exit {code}):\n{block}\n{out[-3000:]}")
    assert not failures, "\n\n".join(failures)
