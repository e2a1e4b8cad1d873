"""README.md cannot drift from reality.

* Every ``grasprom`` line of its bash blocks and of the docs pages parses with the live parsers
  (the docs' CLI reference is generated from them: ``docs/hooks.py``).
* Its first two commands, parsed from the file, run in a clean virtual environment
  (``python -m venv``, no system site-packages; pip may reuse the machine's cache) inside a
  temporary copy of the checkout, so the repository stays clean:

  1. the main job, ``pip install -e . && grasprom build --out build``, runs as written and
     leaves the report, the FMUs and the Arduino package in the copy's ``build/``;
  2. the test command, ``pip install -e ".[dev]" && python -m pytest -q``: the install runs as
     written, but pytest is *not* run in full (that would recurse into this test and double the
     suite's time): ``python -m pytest --version`` and ``python -m pytest -q --collect-only``
     must succeed in that environment instead.

The venv test is marked ``slow`` (about 1-2 minutes, bounded by per-step timeouts); CI runs it.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.checkout import copy_checkout

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MAIN_JOB = "pip install -e . && grasprom build --out build"
TEST_CMD = 'pip install -e ".[dev]" && python -m pytest -q'


def readme_commands() -> list[str]:
    """The commands of README's first two ``bash`` code blocks (one line each)."""
    blocks = re.findall(r"```bash\n(.*?)```", README.read_text(), flags=re.S)
    assert len(blocks) >= 2, "README needs the main-job and test command blocks"
    cmds = [b.strip() for b in blocks[:2]]
    for c in cmds:
        assert "\n" not in c, f"README's first commands must be one line each: {c!r}"
    return cmds


def test_readme_first_commands_are_the_documented_ones():
    main, tests = readme_commands()
    assert main == MAIN_JOB
    assert tests == TEST_CMD  # .ci/run calls exactly this
    assert 'python -m pip install -e ".[dev]"' in (ROOT / ".ci" / "run").read_text()


def _run(cmd: str, cwd: Path, env: dict[str, str], timeout: float) -> subprocess.CompletedProcess:
    res = subprocess.run(["bash", "-c", cmd], cwd=cwd, env=env, capture_output=True, text=True,
                         timeout=timeout)  # fmt: skip
    assert res.returncode == 0, f"{cmd!r} failed ({res.returncode}):\n{res.stdout[-3000:]}\n" \
                                f"{res.stderr[-3000:]}"  # fmt: skip
    return res


@pytest.mark.slow(seconds=109)
def test_readme_commands_in_fresh_venv(tmp_path):
    main_cmd, test_cmd = readme_commands()
    repo = tmp_path / "repo"
    repo.mkdir()
    copy_checkout(repo)
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP")}  # fmt: skip
    env["VIRTUAL_ENV"] = str(venv)
    env["PATH"] = os.pathsep.join([str(venv / "bin"), env.get("PATH", "")])
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"

    # 1. the main job, exactly as written
    res = _run(main_cmd, repo, env, timeout=900)
    out = repo / "build"
    for name in ("report.html", "surrogate.json", "controller.json", "GraspController.fmu",
                 "GraspController_fmi3.fmu", "build.json"):  # fmt: skip
        assert (out / name).is_file(), (name, res.stderr[-2000:])
    assert (out / "arduino" / "grasprom_controller" / "grasprom_controller.ino").is_file()
    grasprom = shutil.which("grasprom", path=str(venv / "bin"))
    assert grasprom and Path(grasprom).parent == venv / "bin"  # the venv's, not the machine's

    # 2. the test command: install as written; pytest only reports its version and collects
    install, pytest_part = (p.strip() for p in test_cmd.split("&&"))
    assert pytest_part == "python -m pytest -q"
    _run(install, repo, env, timeout=900)
    _run("python -m pytest --version", repo, env, timeout=120)
    res = _run("python -m pytest -q --collect-only -p no:cacheprovider", repo, env, timeout=300)
    m = re.search(r"(\d+) tests? collected", res.stdout)
    assert m and int(m.group(1)) > 100, res.stdout[-2000:]


def test_every_grasprom_line_of_the_readme_and_docs_parses():
    """Issue 16: quickstart lines could not be pasted (``[--flag]``, ``...``). Every
    ``grasprom ...`` line of the bash blocks of README and the docs pages (comments stripped,
    continuations joined) parses with the live argument parsers, and no block line carries
    ``[--`` placeholders.  (``tests/test_doc_commands.py`` runs them; this is the quick check.)"""
    import shlex

    from grasprom.cli import _build_parser, _diagnose_parser, _synth_parser
    from tests.test_doc_commands import bash_blocks, nav_pages

    bad = []
    blocks = [b for page in nav_pages() for b in bash_blocks(page)]
    assert len(blocks) > 15
    for block in blocks:
        text = re.sub(r"\\\n\s*", " ", block)
        for line in text.splitlines():
            code = line.split(" #")[0].strip() if not line.lstrip().startswith("#") else ""
            if "[--" in code:
                bad.append(f"placeholder: {code}")
            for part in code.split("&&"):
                words = shlex.split(part.strip())
                if len(words) < 2 or words[0] != "grasprom" or words[1] in ("--help", "-h"):
                    continue
                parser = {"diagnose": _diagnose_parser, "synth": _synth_parser}.get(words[1])
                try:
                    if parser is not None:
                        parser().parse_args(words[2:])
                    else:
                        _build_parser().parse_args(words[1:])
                except SystemExit:
                    bad.append(f"does not parse: {part.strip()}")
    assert not bad, bad
