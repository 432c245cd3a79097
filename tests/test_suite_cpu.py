"""benchmarks/suite_cpu.py, the plugin that charges each test with the machine's CPU."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import suite_cpu  # noqa: E402

pytestmark = pytest.mark.skipif(not Path("/proc/stat").exists(), reason="needs Linux /proc/stat")


def test_the_summary_adds_up_per_file_and_ranks_the_tests():
    rows = [("a.py::t1", 3.0, 2.0), ("a.py::t2", 1.0, 4.0), ("b.ipynb::Cell 1", 5.0, 5.0)]
    lines = suite_cpu.summary(rows, top=2)
    cores = os.cpu_count()
    assert lines[0] == (f"3 tests: 9 CPU s in 11 s of wall time; on {cores} cores no schedule "
                        f"takes less than {9 / cores:.0f} s")
    assert lines[2].split() == ["5.0", "5.0", "1", "b.ipynb"]
    assert lines[3].split() == ["4.0", "6.0", "2", "a.py"]
    assert [line.split()[-1] for line in lines[5:]] == ["1", "a.py::t1"]   # top 2 tests


def test_a_busy_test_is_charged_its_cpu(tmp_path):
    (tmp_path / "test_two.py").write_text(
        "import time\n"
        "def test_busy():\n"
        "    t = time.process_time()\n"
        "    while time.process_time() - t < 0.6:\n"
        "        pass\n"
        "def test_idle():\n"
        "    time.sleep(0.3)\n")
    out = tmp_path / "cpu.json"
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "suite_cpu", "-p", "no:xdist",
                          "-p", "no:cacheprovider", "-o", "addopts=", "--suite-cpu-json", str(out),
                          "test_two.py"], cwd=tmp_path, capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(ROOT / "benchmarks")})
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert "CPU per test (whole machine, /proc/stat)" in run.stdout
    rows = {n.split("::")[1]: (cpu, wall) for n, cpu, wall in json.loads(out.read_text())}
    assert set(rows) == {"test_busy", "test_idle"}
    assert rows["test_busy"][0] >= 0.55             # its own spin, at least
    assert 0.3 <= rows["test_idle"][1] < 5.0
