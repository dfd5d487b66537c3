import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

import xserver  # tests/ is on the path from here on

#: The run's own temporary folder: TMPDIR for the tests and every process they start,
#: removed at the end so that the suite leaves nothing in the system's temporary folder.
_RUN_TMP: Path | None = None


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config):
    """Point TMPDIR (and pytest's tmp_path) at a folder of this run's own."""
    global _RUN_TMP
    _RUN_TMP = Path(tempfile.mkdtemp(prefix="meshlab-sharp-tests-"))
    os.environ["TMPDIR"] = str(_RUN_TMP)
    tempfile.tempdir = str(_RUN_TMP)


def pytest_unconfigure(config):
    """End the shared Xvfb server and remove the run's temporary folder."""
    xserver.stop()
    if _RUN_TMP is not None:
        shutil.rmtree(_RUN_TMP, ignore_errors=True)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """In CI (``CI`` set, as CI services set it), a skipped test of a module that sets
    ``REQUIRED_IN_CI = True`` (the MeshLab plugin's) fails: set-up installs MeshLab
    there, so a skip means something is missing."""
    outcome = yield
    report = outcome.get_result()
    required = getattr(item.module, "REQUIRED_IN_CI", False)
    if report.skipped and required and os.environ.get("CI", "").lower() not in ("", "0", "false"):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else report.longrepr
        report.outcome = "failed"
        report.longrepr = f"skipped in CI, where it must run: {reason}"


@pytest.fixture(scope="session")
def meshlab_root(tmp_path_factory):
    """Build the plugin from scratch and install it into a private MeshLab root."""
    from meshlab_sharp import plugin
    from meshlab_sharp.cli import main

    missing = plugin.missing_packages()
    if missing:
        pytest.fail(f"missing Debian packages {missing}: run bash scripts/setup.sh --all")
    base = tmp_path_factory.mktemp("meshlab")
    root, build = base / "root", base / "build"
    code = main(["plugin", "install", "--root", str(root), "--build-dir", str(build), "--no-apt"])
    assert code == 0
    assert (build / plugin.PLUGIN_FILE).is_file()
    return root
