"""MkDocs hooks: the pages of the docs site that are generated, never written by hand.

* ``cli.md``: the full ``--help`` of every command, from the live parsers
  (:func:`grasprom.cli.cli_help_pages`);
* ``api/<stage>.md``: one page per pipeline stage, every public module of it rendered by
  mkdocstrings from the numpydoc docstrings;
* ``figures/*.png``: the figures of the main job, ``grasprom build`` on the shipped data, run
  when the site is built (the stage pages show them);
* ``examples.md``: the gallery -- every script in ``examples/`` is *run* with the command shown
  (fast mode where it has one), its printed output and its figures are put on the page.  A
  failing example fails the build (``mkdocs build --strict`` in CI).

Nothing is written into ``docs/``: the pages and figures are handed to MkDocs as generated files.
``GRASPROM_DOCS_GALLERY=0 mkdocs serve`` skips running the examples (a quick local preview: the
gallery page then only lists the commands); CI always builds the full gallery.
"""

from __future__ import annotations

import ast
import os
import pkgutil
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[1]

STAGES = [
    ("fe", "Stage 1: FE sweeps"),
    ("surrogate", "Stage 2: surrogate"),
    ("chain", "Stage 3: kinematic chain"),
    ("control", "Stage 4: controller, simulation, tuning"),
    ("export", "Stage 5: C core, FMU, Arduino"),
    ("gap", "Stage 6: sim-to-real gap"),
    ("pipeline", "The main job (grasprom build)"),
]

# (script, arguments after --out DIR, what the page says about the mode)
EXAMPLES = [
    ("kinematics_fg_fi.py", [], "full run"),
    ("fmu_cosim.py", ["--fast"], "fast mode: a shorter rest after the release, same figures"),
    ("tune_controller.py", [], "full run, about 10 s"),
    ("arduino_export.py", ["--fast"], "fast mode: the package without the budget measurement"),
    ("diagnose_gap.py", [], "full run, synthetic trials with mechanism friction withheld"),
    ("tube3d_vtu.py", ["--fast"], "fast mode: coarse mesh, short stroke"),
]
MAX_OUTPUT_LINES = 60


def cli_page() -> str:
    """Markdown of the CLI reference page."""
    from grasprom.cli import cli_help_pages

    parts = [
        "# CLI reference",
        "",
        "Generated from the live parsers when the site is built (`grasprom <command> --help` "
        "prints the same text). Units: mm, N, MPa, s, degrees; see "
        "[Units and conventions](units.md). Exit codes of every command: 0 ok, 1 a case or "
        "stage failed, 2 bad input (the option or file is named), 130 interrupted.",
        "",
    ]
    for name, text in cli_help_pages():
        parts += [f"## `{name}`", "", "```text", text, "```", ""]
    return "\n".join(parts)


def public_modules(stage: str) -> list[str]:
    """Dotted names of the public modules of ``grasprom.<stage>`` (recursively)."""
    pkg = ROOT / "grasprom" / stage
    names = []
    for info in pkgutil.walk_packages([str(pkg)], prefix=f"grasprom.{stage}."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return sorted(names)


def api_page(stage: str, title: str) -> str:
    """Markdown of the API page of one stage: the package docstring, then each module."""
    parts = [
        f"# `grasprom.{stage}`: {title}",
        "",
        f"::: grasprom.{stage}",
        "    options:",
        "      members: false",
        "      show_root_heading: false",
        "",
    ]
    for mod in public_modules(stage):
        parts += [f"::: {mod}", ""]
    return "\n".join(parts)


def api_index() -> str:
    """Markdown of the API reference's landing page."""
    rows = "\n".join(f"| [`grasprom.{s}`]({s}.md) | {t} |" for s, t in STAGES)
    return (
        "# API reference\n\n"
        "Rendered from the numpydoc docstrings of the package (every public function states "
        "its units). Each stage is a subpackage whose `__init__` lists its entry points in "
        "`__all__`; the pages below document every public module.\n\n"
        "| package | stage |\n|---|---|\n" + rows + "\n"
    )


def example_doc(script: Path) -> str:
    """The module docstring of an example script (its description)."""
    return ast.get_docstring(ast.parse(script.read_text())) or ""


def run_checked(cmd: list[str], what: str) -> str:
    """Run ``cmd`` in the checkout (Agg backend); its stdout; RuntimeError naming ``what``."""
    env = dict(os.environ, MPLBACKEND="Agg")
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=env, timeout=900)
    if res.returncode != 0:
        raise RuntimeError(f"{what} failed ({res.returncode}):\n{res.stderr[-2000:]}")
    return res.stdout


def run_example(script: str, extra: list[str], out: Path) -> str:
    """Run one example as the page shows it; return its output; raise when it fails."""
    cmd = [sys.executable, f"examples/{script}", "--out", str(out), *extra]
    lines = run_checked(cmd, f"example {script}").rstrip().splitlines()
    if len(lines) > MAX_OUTPUT_LINES:
        cut = len(lines) - MAX_OUTPUT_LINES
        lines = lines[:MAX_OUTPUT_LINES] + [f"... ({cut} more lines)"]
    return "\n".join(lines)


def gallery(config, files: Files) -> str:
    """Run every example, add its figures to ``files``, return the gallery page."""
    parts = [
        "# Examples",
        "",
        "One script per use, in `examples/`. This page is built by running each of them with "
        "the command shown (the test suite runs them too, so they cannot rot); the output and "
        "the figures below are from that run.",
        "",
    ]
    run = os.environ.get("GRASPROM_DOCS_GALLERY", "1") != "0"
    with tempfile.TemporaryDirectory(prefix="grasprom-gallery-") as tmp:
        for script, extra, mode in EXAMPLES:
            name = script.removesuffix(".py")
            out = Path(tmp) / name
            shown = shlex.join(["python", f"examples/{script}", "--out", f"/tmp/{name}", *extra])
            printed = run_example(script, extra, out) if run else "(not run)"
            doc = example_doc(ROOT / "examples" / script).split("\n\n")
            parts += [f"## `{script}`", "", doc[0], "", "```bash", shown, "```", ""]
            parts += [f"({mode}) Output:", "", "```text", printed, "```", ""]
            for png in sorted(out.rglob("*.png")):
                uri = f"examples/{name}/{png.name}"
                files.append(File.generated(config, uri, content=png.read_bytes()))
                parts += [f"![{png.stem}]({uri})", ""]
    return "\n".join(parts)


def build_figures(config, files: Files) -> None:
    """Run the main job on the shipped data; add its figures as ``figures/<name>.png``."""
    with tempfile.TemporaryDirectory(prefix="grasprom-docs-build-") as tmp:
        run_checked([sys.executable, "-m", "grasprom", "build", "--out", tmp, "--quiet"],
                    "grasprom build")  # fmt: skip
        for png in sorted((Path(tmp) / "figures").glob("*.png")):
            files.append(File.generated(config, f"figures/{png.name}", content=png.read_bytes()))


def on_files(files: Files, config) -> Files:
    """Add the generated pages (CLI, API, gallery) to the site."""
    if str(ROOT) not in sys.path:  # `mkdocs serve` calls this on every rebuild
        sys.path.insert(0, str(ROOT))
    files.append(File.generated(config, "cli.md", content=cli_page()))
    build_figures(config, files)
    files.append(File.generated(config, "api/index.md", content=api_index()))
    for stage, title in STAGES:
        files.append(File.generated(config, f"api/{stage}.md", content=api_page(stage, title)))
    files.append(File.generated(config, "examples.md", content=gallery(config, files)))
    return files
