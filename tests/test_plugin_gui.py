"""Debian's MeshLab GUI under Xvfb: open the sample part, apply the filters from the
Filters menu, and check on screen that the features show up in red and the feature
curves are drawn (the screenshots stay in the test's temporary folder)."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest
from files import write_ply

import meshlab_sharp
from meshlab_sharp.sample import sample_part

#: In CI a skip here is a failure (conftest.py): set-up installs MeshLab there.
REQUIRED_IN_CI = True
pytestmark = [
    pytest.mark.slow,  # builds and runs the MeshLab plugin
    pytest.mark.skipif(
        shutil.which("dpkg-query") is None, reason="the plugin targets Debian's MeshLab 2020.09"
    ),
]

# Screen positions of MeshLab 2020.09's default window at (0, 0) on a 1280x1024 screen.
FILTERS_MENU = (120, 10)
SELECTION_SUBMENU = (160, 87)
SHARP_FEATURES_ITEM = (678, 611)
REMESHING_SUBMENU = (275, 161)
CURVES_ITEM = (449, 237)
LAYER_0_EYE = (472, 114)  # hides the first layer in the layer dialog
# The filter dialog's Close and Apply buttons: its bottom row, at a quarter and three
# quarters of its width (its height grows with the parameter list).
BUTTON_ROW_FROM_BOTTOM = 23
VIEWPORT = (slice(70, 600), slice(0, 430))  # rows, columns of the 3D view


def _wait_for(predicate, timeout: float = 30.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.25)
    return False


def _windows(env: dict[str, str], name: str) -> list[str]:
    proc = subprocess.run(
        ["xdotool", "search", "--name", name], capture_output=True, text=True, env=env, check=False
    )
    return proc.stdout.split()


def _geometry(env: dict[str, str], window: str) -> tuple[int, int, int, int]:
    """x, y, width, height of an X window."""
    out = subprocess.run(
        ["xdotool", "getwindowgeometry", "--shell", window],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    ).stdout
    values = dict(line.split("=", 1) for line in out.split())
    return tuple(int(values[k]) for k in ("X", "Y", "WIDTH", "HEIGHT"))  # type: ignore[return-value]


def _pixels(png: Path, kind: str) -> int:
    """Pixels of the 3D view coloured like the features ("red": 230, 13, 13) or like the
    curves' vertices and edges as MeshLab lights them ("dark red": about 75, 4, 4)."""
    import matplotlib.image as mpimg

    rgb = mpimg.imread(png)[..., :3][VIEWPORT]
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    if kind == "red":
        return int(((r > 0.7) & (g < 0.3) & (b < 0.3)).sum())
    return int(((r > 0.2) & (r > 2 * g) & (r > 2 * b)).sum())


def _shot(env: dict[str, str], path: Path) -> Path:
    subprocess.run(["import", "-window", "root", str(path)], env=env, check=True, timeout=60)
    return path


def _click(env: dict[str, str], xy: tuple[int, int]) -> None:
    subprocess.run(
        ["xdotool", "mousemove", str(xy[0]), str(xy[1]), "click", "1"], env=env, check=True
    )
    time.sleep(1.0)


def _apply_filter(env: dict[str, str], menu: list[tuple[int, int]], title: str) -> None:
    """Open the filter's dialog through the menu clicks, apply it with its defaults, and
    close the dialog (it covers part of the 3D view)."""
    for xy in [FILTERS_MENU, *menu]:
        _click(env, xy)
    assert _wait_for(lambda: bool(_windows(env, title)), 20), "the filter dialog did not open"
    x, y, width, height = _geometry(env, _windows(env, title)[-1])
    row = y + height - BUTTON_ROW_FROM_BOTTOM
    _click(env, (x + width * 3 // 4, row))  # Apply
    time.sleep(2)
    _click(env, (x + width // 4, row))  # Close
    time.sleep(2)


@contextlib.contextmanager
def meshlab_gui(root: Path, env: dict[str, str], src: Path, log: Path):
    """MeshLab's GUI with ``src`` open, its log (which it also prints) going to ``log``;
    ended afterwards, which must find it alive and leave no crash."""
    with log.open("w") as sink:
        gui = subprocess.Popen(
            [str(root / "bin" / "meshlab"), str(src)],
            env=env,
            stdout=sink,
            stderr=subprocess.STDOUT,
        )
    ours = signal.SIGTERM
    try:
        assert _wait_for(lambda: bool(_windows(env, "MeshLab")), 60), "no MeshLab window"
        time.sleep(3)  # the mesh is drawn
        yield gui
        assert gui.poll() is None, "MeshLab died"
    finally:
        if gui.poll() is None:
            gui.terminate()
            try:
                gui.wait(10)
            except subprocess.TimeoutExpired:
                ours = signal.SIGKILL
                gui.kill()
                gui.wait(10)
    # MeshLab ended by itself (0) or by the signal we sent; any other signal is a crash
    assert gui.returncode in (0, -ours), f"MeshLab ended with {gui.returncode}"


@pytest.fixture
def display(tmp_path):
    """A private Xvfb server."""
    for tool in ("Xvfb", "xdotool", "import"):
        if shutil.which(tool) is None:
            pytest.fail(f"{tool} is missing: run bash scripts/setup.sh --all")
    number = 90 + os.getpid() % 500
    server = subprocess.Popen(
        ["Xvfb", f":{number}", "-screen", "0", "1280x1024x24", "-nolisten", "tcp"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    env = dict(os.environ, DISPLAY=f":{number}", XDG_CONFIG_HOME=str(tmp_path / "config"))
    assert _wait_for(lambda: Path(f"/tmp/.X11-unix/X{number}").exists(), 10)
    yield env
    server.terminate()
    server.wait(10)


def _sample_mesh(tmp_path: Path) -> Path:
    part = sample_part("mesh")
    return write_ply(tmp_path / "sample_part.ply", part.vertices, part.faces, binary=True)


def test_gui_applies_the_filter_and_shows_red_features(meshlab_root, display, tmp_path):
    """With the dialog's defaults (a fresh settings folder): robust mode."""
    log = tmp_path / "meshlab.log"
    with meshlab_gui(meshlab_root, display, _sample_mesh(tmp_path), log):
        before = _pixels(_shot(display, tmp_path / "before.png"), "red")
        _apply_filter(display, [SELECTION_SUBMENU, SHARP_FEATURES_ITEM], "Select Sharp Features")
        after = _pixels(_shot(display, tmp_path / "after.png"), "red")
        assert before == 0
        assert after > 1000, f"only {after} red pixels after applying the filter"
    text = log.read_text(errors="replace")
    assert "Sharp features: mesh (k-rings), robust mode" in text, text[-2000:]


def test_gui_draws_the_feature_curves(meshlab_root, display, tmp_path):
    """Filters > Remeshing > Extract Sharp Feature Curves adds the layer of curves, drawn
    over the part and, with the part hidden, alone (curves.png: the screenshot)."""
    log, src = tmp_path / "meshlab.log", _sample_mesh(tmp_path)
    with meshlab_gui(meshlab_root, display, src, log):
        before = _pixels(_shot(display, tmp_path / "before.png"), "dark red")
        _apply_filter(display, [REMESHING_SUBMENU, CURVES_ITEM], "Extract Sharp Feature Curves")
        over = _pixels(_shot(display, tmp_path / "over_the_part.png"), "dark red")
        _click(display, LAYER_0_EYE)
        time.sleep(1)
        alone = _pixels(_shot(display, tmp_path / "curves.png"), "dark red")
        assert before == 0
        assert over > 1000, f"only {over} curve pixels over the part"
        assert alone > 2 * over, f"{alone} curve pixels alone, {over} over the part"
    curves = meshlab_sharp.detect(src, curves=True).curves
    n_vertices = sum(len(c.points) for c in curves)
    summary = f"Sharp feature curves: {len(curves)} curves ({sum(c.closed for c in curves)} closed)"
    assert f"{summary}, {n_vertices} vertices" in log.read_text(errors="replace")
