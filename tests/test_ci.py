"""CI cannot pass by accident: .ci/check_report.py fails a run that collected nothing, ended early or
skipped a test for a reason the README does not list, and pytest keeps the checkout's parent folder
off the import path (importlib import mode).

Real pytest runs (subprocesses, in temporary folders with this suite's conftest.py) make the reports.
"""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CHECK = ROOT / ".ci" / "check_report.py"

README = """# x

Tests are skipped only for these reasons:
- `POSIX permission bits` (on Windows)
- `needs the moon`

Text after.
"""


def _suite(tmp_path, body: str) -> Path:
    """A folder with this suite's conftest.py and one test file ``body``; returns the folder."""
    d = tmp_path / "suite"
    d.mkdir()
    shutil.copy(ROOT / "tests" / "conftest.py", d / "conftest.py")
    (d / "test_it.py").write_text(body)
    (tmp_path / "README.md").write_text(README)
    return d


def _run(tmp_path, body: str, *args):
    """(pytest's exit status, the checker's exit status, the checker's output) for a run of ``body``."""
    d = _suite(tmp_path, body)
    report = tmp_path / "report.xml"
    env = {k: v for k, v in os.environ.items() if k != "PYTEST_ADDOPTS"}
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--junitxml={report}",
                        "--rootdir", str(d), "-c", os.devnull, str(d), *args],
                       cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env)
    c = subprocess.run([sys.executable, str(CHECK), str(report), str(tmp_path / "README.md")],
                       capture_output=True, text=True, timeout=60)
    return r.returncode, c.returncode, c.stdout + c.stderr


GOOD = """
import os, pytest

def test_a():
    assert 1 + 1 == 2

@pytest.mark.skipif(True, reason="needs the moon")
def test_b():
    pass
"""


def test_a_complete_green_run_passes(tmp_path):
    rc, check, out = _run(tmp_path, GOOD)
    assert rc == 0 and check == 0, out


def test_a_suite_that_collects_nothing_fails(tmp_path):
    rc, check, out = _run(tmp_path, "x = 1\n")
    assert check == 1 and "no test ran" in out, out


def test_a_run_that_exits_in_the_middle_fails_even_with_status_0(tmp_path):
    body = GOOD + "\ndef test_c():\n    os._exit(0)\n\ndef test_d():\n    pass\n"
    rc, check, out = _run(tmp_path, body)
    assert rc == 0  # what fooled CI before: the process ended with status 0
    assert check == 1 and "did not finish" in out, out


def test_a_run_that_stops_early_fails(tmp_path):
    body = GOOD + "\ndef test_c():\n    assert False\n\ndef test_d():\n    pass\n"
    rc, check, out = _run(tmp_path, body, "-x")
    assert rc == 1 and check == 1 and "4 tests were collected but 3 reported" in out, out
    assert "test_c: failure" in out


def test_a_skip_for_an_unlisted_reason_fails(tmp_path):
    body = "import pytest\n\ndef test_a():\n    pytest.skip('flaky today')\n"
    rc, check, out = _run(tmp_path, body)
    assert rc == 0 and check == 1 and "'flaky today'" in out, out


def test_a_report_without_the_collected_count_fails(tmp_path):
    report = tmp_path / "r.xml"
    report.write_text('<testsuites><testsuite name="pytest" tests="1"><testcase classname="t" name="a"/>'
                      '</testsuite></testsuites>')
    (tmp_path / "README.md").write_text(README)
    c = subprocess.run([sys.executable, str(CHECK), str(report), str(tmp_path / "README.md")],
                       capture_output=True, text=True, timeout=60)
    assert c.returncode == 1 and "collected" in c.stderr


def test_the_readme_lists_the_reasons_and_ci_runs_the_check():
    sys.path.insert(0, str(CHECK.parent))
    try:
        import check_report
    finally:
        sys.path.remove(str(CHECK.parent))
    assert check_report.allowed_skip_reasons(README) == ["POSIX permission bits", "needs the moon"]
    reasons = check_report.allowed_skip_reasons((ROOT / "README.md").read_text())
    assert "POSIX permission bits" in reasons
    run = (ROOT / ".ci" / "run").read_text()
    assert "--junitxml=" in run and ".ci/check_report.py" in run and "./dev test" in run
    assert "scripts/build_extension.py --output-dir dist" in run  # the zips users install


def test_the_checkout_s_parent_folder_is_not_on_the_import_path():
    parent = os.path.realpath(ROOT.parent)
    assert not [p for p in sys.path if p and os.path.realpath(p) == parent], sys.path


@pytest.mark.parametrize("mode", ["ours", "prepend"])
def test_a_stray_module_beside_a_checkout_is_not_imported(tmp_path, mode):
    """A checkout with the root __init__.py and this pyproject.toml, and a stray module in its parent
    folder: the checkout's tests cannot import it (they could in pytest's former default mode)."""
    checkout = tmp_path / "parent" / "checkout"
    (checkout / "tests").mkdir(parents=True)
    shutil.copy(ROOT / "pyproject.toml", checkout / "pyproject.toml")
    shutil.copy(ROOT / "__init__.py", checkout / "__init__.py")
    (checkout / "grlens_addon").mkdir()
    shutil.copy(ROOT / "grlens_addon" / "__init__.py", checkout / "grlens_addon" / "__init__.py")
    (tmp_path / "parent" / "stray_beside.py").write_text("X = 1\n")
    (checkout / "tests" / "test_x.py").write_text(
        "import importlib.util\n\ndef test_x():\n    assert importlib.util.find_spec('stray_beside') is None\n")
    args = [] if mode == "ours" else ["--import-mode=prepend"]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTEST_ADDOPTS", "PYTHONPATH")}
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", *args], cwd=checkout, capture_output=True, text=True,
                       timeout=120, env=env)
    assert r.returncode == (0 if mode == "ours" else 1), r.stdout + r.stderr


def test_ci_run_fails_when_the_suite_collects_nothing():
    """.ci/run itself, on this repository, with a selection that matches no test: it fails (pytest's
    own status 5 would do too; the check says why) and builds nothing."""
    env = {k: v for k, v in os.environ.items() if k != "PYTEST_ADDOPTS"}
    r = subprocess.run([str(ROOT / ".ci" / "run"), "-k", "no_test_is_called_this"], cwd=ROOT, capture_output=True,
                       text=True, timeout=600, env=env)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "ci: no test ran" in r.stderr, r.stdout + r.stderr
    assert "build_extension" not in r.stdout
