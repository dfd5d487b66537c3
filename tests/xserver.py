"""One Xvfb server for the whole test run, for meshlabserver (which needs an X display
even for batch work).

:func:`display` starts it on first use and returns its ``DISPLAY`` value; :func:`stop`
ends it (``conftest.pytest_unconfigure`` calls it), so no server outlives the run.
Starting one server instead of one ``xvfb-run`` per call also leaves no orphaned Xvfb
behind when a call is killed at its time-out.
"""

from __future__ import annotations

import os
import shutil
import subprocess

_server: subprocess.Popen | None = None
_display: str | None = None


def display() -> str:
    """The ``DISPLAY`` of the run's Xvfb server (started on first call)."""
    global _server, _display
    if _display is not None and _server is not None and _server.poll() is None:
        return _display
    if shutil.which("Xvfb") is None:
        raise RuntimeError("Xvfb is missing: run bash scripts/setup.sh --all")
    read, write = os.pipe()
    _server = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write), "-screen", "0", "1280x1024x24", "-nolisten", "tcp"],
        pass_fds=(write,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    os.close(write)
    with os.fdopen(read) as pipe:
        number = pipe.readline().strip()
    if not number:
        stop()
        raise RuntimeError("Xvfb did not start")
    _display = f":{number}"
    return _display


def env() -> dict[str, str]:
    """The environment with ``DISPLAY`` set to the run's server."""
    return dict(os.environ, DISPLAY=display())


def stop() -> None:
    """End the server, if one was started."""
    global _server, _display
    if _server is not None and _server.poll() is None:
        _server.terminate()
        try:
            _server.wait(10)
        except subprocess.TimeoutExpired:
            _server.kill()
            _server.wait(10)
    _server, _display = None, None
