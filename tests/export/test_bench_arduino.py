"""``benchmarks/bench_arduino.py`` -- the command README.md and the docs quote for the Arduino
figures -- runs to the end (its ``--quick`` form, about 10 s), so it cannot break silently.

Benchmarks print figures, never assert them: this only checks that every block ran and that the
default export's flash, RAM and cycles it prints lie in a sane range (within the budget).  Like
``test_arduino.py``: with ``CI=true`` a missing tool is a failure, never a skip.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from grasprom.export import arduino as ar
from tests.export.test_arduino import need_simavr
from tests.tools import need

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_LINE = re.compile(
    r"^default export \(clipped, tol 0\.5 %\): flash (\d+) B, RAM (\d+) B, (\d+) cycles/step max",
    flags=re.M,
)


def test_bench_arduino_quick_runs_to_the_end():
    need("avr-gcc", "gcc-avr avr-libc")
    need("avr-size", "binutils-avr")
    need_simavr()
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    res = subprocess.run(
        [sys.executable, "benchmarks/bench_arduino.py", "--quick"],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-3000:]
    out = res.stdout
    print("\n" + out)
    rows = re.findall(r"^(clip|coup) fixed\s+0\.50\s", out, flags=re.M)
    assert rows == ["clip", "coup"], out  # one block per rendering, labelled by its rendering
    m = DEFAULT_LINE.search(out)
    assert m, out
    flash_B, ram_B, cycles = map(int, m.groups())
    assert 2000 <= flash_B <= ar.FLASH_BUDGET_B
    assert 50 <= ram_B <= ar.RAM_BUDGET_B
    assert 500 <= cycles <= ar.CYCLE_BUDGET
    rt = re.search(r"run-time float .*handle error (\S+) % FS, flag mismatches (\d+)", out)
    assert rt, out
    assert 0.0 < float(rt.group(1)) < 1e-3 and rt.group(2) == "0"  # float32 rounding, not 0/NaN
    assert re.search(r"^  all of these \+ scale 1\.3 +flash +\d+ B", out, flags=re.M), out
