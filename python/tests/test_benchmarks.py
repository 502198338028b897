"""The benchmark scripts of python/benchmarks run end to end at a small size.

They time the command line, found through RDLIDAR_BIN (the `rdlidar_bin` fixture of conftest.py).
"""

import os
import re
import subprocess
import sys

import pytest

BENCHMARKS = os.path.join(os.path.dirname(__file__), os.pardir, "benchmarks")


def run_ratio(rdlidar_bin, *args):
    script = os.path.join(BENCHMARKS, "numpy_ratio.py")
    return subprocess.run(
        [sys.executable, script, "--rdlidar", rdlidar_bin, "--size", "6x6x8", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )


def table_rows(text):
    """The rows of the ratio table (the first table): its cells, split."""
    rows = []
    for line in text.splitlines():
        if line.startswith("| f32 |") or line.startswith("| f64 |"):
            rows.append([c.strip() for c in line.strip("|").split("|")])
        elif rows:
            break
    return rows


@pytest.mark.parametrize("rounds", [1, 3])
def test_numpy_ratio_prints_one_row_per_precision_and_pulse_length(rdlidar_bin, rounds):
    out = run_ratio(rdlidar_bin, "--pulse-lens", "50,120", "--repeats", "2", "--rounds",
                    str(rounds))
    assert out.returncode == 0, out.stderr
    rows = table_rows(out.stdout)
    assert [(r[0], r[1]) for r in rows] == [
        ("f32", "50"), ("f32", "120"), ("f64", "50"), ("f64", "120")
    ]
    for r in rows:
        for cell in (r[5], r[8]):
            # The median of the rounds' ratios, and with several rounds their range around it.
            m = re.fullmatch(r"([0-9.]+)x(?: \(([0-9.]+)–([0-9.]+)\))?", cell)
            assert m, cell
            assert float(m.group(1)) > 0
            assert (m.group(2) is not None) == (rounds > 1), cell
            if rounds > 1:
                assert float(m.group(2)) <= float(m.group(1)) <= float(m.group(3)), cell


@pytest.mark.parametrize("flag", ["--rounds", "--repeats"])
def test_numpy_ratio_refuses_zero_rounds_or_repeats_in_one_line(rdlidar_bin, flag):
    out = run_ratio(rdlidar_bin, "--pulse-lens", "50", flag, "0")
    assert out.returncode != 0
    assert out.stderr.strip().splitlines() == ["--repeats and --rounds must be at least 1"]
