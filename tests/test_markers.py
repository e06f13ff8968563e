"""The ``subprocess`` marker is kept true by the suite itself (``conftest.py``): every child process a
test starts is recorded, and a test that starts one without the marker fails. These tests prove
both halves: the recording sees programs and multiprocessing's interpreters (and leaves the
package's own children out), the report of an unmarked test that started one turns into a failure
naming the command, and the wiring holds in a real pytest run."""

from __future__ import annotations

import multiprocessing.util
import os
import shutil
import subprocess
import sys

import pytest
from conftest import ROOT, STARTED, unmarked_children


def _report(item: pytest.Item, outcome: str = "passed") -> pytest.TestReport:
    return pytest.TestReport(item.nodeid, item.location, {}, outcome, None, "call")


@pytest.mark.subprocess
def test_programs_and_multiprocessing_interpreters_are_recorded():
    subprocess.run([sys.executable, "-c", "pass"], check=True)
    assert STARTED and STARTED[-1] == f"{sys.executable} -c pass"
    # as multiprocessing's spawn starts a worker: the executable's path as bytes
    exe = os.fsencode(sys.executable)
    pid = multiprocessing.util.spawnv_passfds(exe, [sys.executable, "-c", "0"], [])
    assert os.waitpid(pid, 0)[1] == 0
    assert STARTED[-1] == f"{sys.executable} -c 0"


@pytest.mark.subprocess
def test_the_packages_own_children_are_not_the_tests():
    # code whose module is in the package starts the child, as warp_critic.running.segments
    # starts the recording's merge
    package_code = compile("subprocess.run([sys.executable, '-c', 'pass'])", "<package>", "exec")
    before = list(STARTED)
    exec(package_code, {"__name__": "warp_critic.running.x", "subprocess": subprocess, "sys": sys})
    assert STARTED == before
    subprocess.run([sys.executable, "-c", "pass"], check=True)
    assert STARTED == [*before, f"{sys.executable} -c pass"]


def test_an_unmarked_test_that_started_a_child_fails_naming_it(request):
    STARTED.append("rerun rrd optimize a.rrd")  # as if this test had started it
    report = _report(request.node)
    unmarked_children(request.node, report)
    assert report.failed and not STARTED
    assert "rerun rrd optimize a.rrd" in str(report.longrepr)
    assert "not marked @pytest.mark.subprocess" in str(report.longrepr)
    assert request.node.nodeid in str(report.longrepr)


def test_a_phase_that_started_nothing_or_already_failed_keeps_its_report(request):
    passed = _report(request.node)
    unmarked_children(request.node, passed)
    assert passed.passed
    STARTED.append("true")
    failed = _report(request.node, "failed")
    unmarked_children(request.node, failed)
    assert failed.failed and failed.longrepr is None and not STARTED


@pytest.mark.subprocess
def test_a_marked_test_may_start_children(request):
    STARTED.append("true")
    report = _report(request.node)
    unmarked_children(request.node, report)
    assert report.passed and not STARTED


@pytest.mark.slow
@pytest.mark.subprocess
def test_a_real_run_fails_the_unmarked_test_only(tmp_path):
    (tmp_path / "tests").mkdir()
    shutil.copy(ROOT / "tests" / "conftest.py", tmp_path / "tests" / "conftest.py")
    (tmp_path / "tests" / "test_children.py").write_text(
        "import subprocess, sys\n"
        "import pytest\n\n"
        "def test_unmarked():\n"
        "    subprocess.run([sys.executable, '-c', 'pass'], check=True)\n\n"
        "@pytest.mark.subprocess\n"
        "def test_marked():\n"
        "    subprocess.run([sys.executable, '-c', 'pass'], check=True)\n\n"
        "def test_none():\n"
        "    pass\n"
    )
    # its own folder holds no ini file: the child runs without this suite's options
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert "1 failed, 2 passed" in run.stdout, run.stdout + run.stderr
    assert "tests/test_children.py::test_unmarked started 1 child process(es)" in run.stdout, (
        run.stdout
    )
    assert "test_marked started" not in run.stdout
