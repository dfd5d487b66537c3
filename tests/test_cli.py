"""The command line end to end: PLY in; PLY, indices and JSON out; read back with pymeshlab."""

from __future__ import annotations

import argparse
import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pymeshlab
import pytest
import shapes
from files import write_ply

import meshlab_sharp
from meshlab_sharp import sample
from meshlab_sharp.cli import PAUSE_ENV, Interrupted, _interrupted_message, main, parse_scales
from meshlab_sharp.errors import OutputError
from meshlab_sharp.io import OutputSet, mesh_arrays
from meshlab_sharp.outputs import _umask

ROOT = Path(__file__).resolve().parent.parent


def _read_back(path):
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    m = ms.current_mesh()
    out = (m.vertex_scalar_array(), m.vertex_selection_array(), m.vertex_color_matrix())
    vertices, faces = mesh_arrays(ms)
    return (vertices, faces, *out)


def test_detect_writes_ply_indices_and_report(tmp_path, capsys):
    vertices, faces = shapes.cube_grid_mesh(3)
    src = write_ply(tmp_path / "cube.ply", vertices, faces, binary=True)
    before = src.read_bytes()
    code = main(
        [
            "detect",
            str(src),
            "--indices",
            str(tmp_path / "cube.txt"),
            "--report",
            str(tmp_path / "cube.json"),
        ]
    )
    assert code == 0
    assert src.read_bytes() == before
    mode = (tmp_path / "cube_sharp.ply").stat().st_mode & 0o777
    assert mode == 0o666 & ~_umask()
    out = capsys.readouterr().out
    assert "sharp features" in out
    expected = shapes.on_cube_edges(vertices, tol=1e-6)

    v, f, quality, selection, colors = _read_back(tmp_path / "cube_sharp.ply")
    np.testing.assert_allclose(v, vertices.astype(np.float32))
    np.testing.assert_array_equal(f, faces)
    np.testing.assert_array_equal(selection, expected)
    np.testing.assert_array_equal(quality[expected], 1.0)
    assert (quality[~expected] < 1.0).all()
    assert (colors[expected, 0] > 0.8).all() and (colors[expected, 1] < 0.2).all()

    indices = np.loadtxt(tmp_path / "cube.txt", dtype=int)
    np.testing.assert_array_equal(indices, np.flatnonzero(expected))

    report = json.loads((tmp_path / "cube.json").read_text())
    assert report["kind"] == "mesh"
    assert report["n_input"] == len(vertices)
    assert report["n_features"] == int(expected.sum())
    assert [s["scale"] for s in report["scales"]] == [1, 2, 3, 4]
    assert all(0 < s["threshold"] <= 1 for s in report["scales"])
    assert report["options"] == {"scales": [1, 2, 3, 4], "weighting": "gaussian", "mode": "robust"}
    assert {"load", "clean", "save", "total"} <= set(report["timings_s"])


def test_output_is_not_overwritten_without_force(tmp_path, capsys):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(9))
    assert main(["detect", str(src), "-q"]) == 0
    first = (tmp_path / "c_sharp.ply").read_bytes()
    assert main(["detect", str(src), "-q", "--ascii"]) == 1
    assert "exists; use --force" in capsys.readouterr().err
    assert (tmp_path / "c_sharp.ply").read_bytes() == first
    assert main(["detect", str(src), "-q", "--ascii", "--force"]) == 0
    assert (tmp_path / "c_sharp.ply").read_bytes() != first


def test_refuses_to_overwrite_the_input(tmp_path, capsys):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(9))
    before = src.read_bytes()
    assert main(["detect", str(src), "-o", str(src), "--force"]) == 1
    assert "overwrite the input" in capsys.readouterr().err
    assert src.read_bytes() == before


def test_as_points_keeps_the_faces_in_the_output(tmp_path):
    vertices, faces = shapes.cube_grid_mesh(3)
    src = write_ply(tmp_path / "m.ply", vertices, faces)
    report = tmp_path / "r.json"
    assert main(["detect", str(src), "--as-points", "--report", str(report), "-q"]) == 0
    assert json.loads(report.read_text())["kind"] == "points"
    _, f, *_ = _read_back(tmp_path / "m_sharp.ply")
    np.testing.assert_array_equal(f, faces)


def test_scales_option(tmp_path):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(11))
    report = tmp_path / "r.json"
    assert main(["detect", str(src), "--scales", "10:30:10", "--report", str(report), "-q"]) == 0
    assert json.loads(report.read_text())["options"]["scales"] == [10, 20, 30]


def test_parse_scales():
    assert parse_scales("12:40:4") == [12, 16, 20, 24, 28, 32, 36, 40]
    assert parse_scales("1:4") == [1, 2, 3, 4]
    assert parse_scales("12, 20,28") == [12, 20, 28]
    assert parse_scales("8 12 16") == [8, 12, 16]  # the plugin's format
    assert parse_scales(" 8\t12  16 ") == [8, 12, 16]
    assert parse_scales("12") == [12]


@pytest.mark.parametrize("text", ["8 12,16", "8,,12", "8,", "", " ", "8 1 2,3", "4:2", "1:2:0"])
def test_parse_scales_rejects_ambiguous_or_empty(text):
    with pytest.raises(argparse.ArgumentTypeError, match="invalid scales"):
        parse_scales(text)


def test_a_huge_scale_range_fails_at_once():
    start = time.perf_counter()
    with pytest.raises(argparse.ArgumentTypeError, match="99999999 scales, more than 64"):
        parse_scales("2:100000000")
    assert time.perf_counter() - start < 0.1  # the range is not built


def test_installed_script_runs(tmp_path):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(9))
    proc = subprocess.run(
        [sys.executable, "-m", "meshlab_sharp", "detect", str(src)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert "92 sharp features" in proc.stdout  # 12 * 7 + 8 edge points
    assert proc.stderr == ""  # no progress bar when stderr is not a terminal


def test_detect_meshset_writes_quality_and_selection():
    vertices, faces = shapes.cube_grid_mesh(3)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces.astype(np.int32)))
    result = meshlab_sharp.detect_meshset(ms, colorize=True)
    expected = shapes.on_cube_edges(vertices)
    np.testing.assert_array_equal(result.mask, expected)
    m = ms.current_mesh()
    np.testing.assert_array_equal(m.vertex_selection_array(), expected)
    np.testing.assert_allclose(m.vertex_scalar_array(), result.strength)
    np.testing.assert_array_equal(m.vertex_matrix(), vertices)
    red = m.vertex_color_matrix()[:, 0] > 0.85
    np.testing.assert_array_equal(red & (m.vertex_color_matrix()[:, 1] < 0.2), expected)
    # A MeshLab filter can go on from the quality.
    ms.compute_selection_by_scalar_per_vertex(minq=0.5, maxq=1.0)
    assert ms.current_mesh().vertex_selection_array().sum() >= expected.sum()
    # Running twice on the same mesh works (pymeshlab cannot overwrite attributes).
    again = meshlab_sharp.detect_meshset(ms)
    np.testing.assert_array_equal(again.mask, expected)
    np.testing.assert_array_equal(ms.current_mesh().vertex_selection_array(), expected)


def test_detect_meshset_on_an_empty_meshset():
    with pytest.raises(meshlab_sharp.InputError, match="no mesh"):
        meshlab_sharp.detect_meshset(pymeshlab.MeshSet())


def _run(args, env=None, **kwargs):
    """``python -m meshlab_sharp ARGS`` with this checkout first on the path."""
    environ = dict(os.environ, PYTHONPATH=str(ROOT), **(env or {}))
    return subprocess.Popen(
        [sys.executable, "-m", "meshlab_sharp", *map(str, args)],
        env=environ,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kwargs,
    )


def _hidden(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def _with_old_outputs(tmp_path):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(9))
    old = {tmp_path / n: f"old {n}\n".encode() for n in ("c_sharp.ply", "c.txt", "c.json")}
    for path, content in old.items():
        path.write_bytes(content)
    args = ["detect", src, "--indices", tmp_path / "c.txt", "--report", tmp_path / "c.json"]
    return args + ["--force", "-q"], old


def _wait_for(path: Path, proc: subprocess.Popen, timeout: float = 60.0) -> None:
    end = time.monotonic() + timeout
    while not path.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < end, "the command never reached the renames"
        time.sleep(0.02)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_a_signal_before_the_renames_leaves_the_old_outputs(tmp_path, sig):
    args, old = _with_old_outputs(tmp_path)
    flag = tmp_path / "flag" / "paused"
    flag.parent.mkdir()
    proc = _run(args, env={PAUSE_ENV: str(flag)})
    _wait_for(flag, proc)
    assert len(_hidden(tmp_path)) == 3  # the three outputs, staged
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + sig
    assert err == f"meshlab-sharp: interrupted by {sig.name}; no output was written\n"
    assert out == ""
    assert _hidden(tmp_path) == []
    for path, content in old.items():
        assert path.read_bytes() == content


def test_a_failing_rename_says_which_outputs_were_written(tmp_path):
    args, _ = _with_old_outputs(tmp_path)
    (tmp_path / "c.txt").unlink()
    flag = tmp_path / "flag" / "paused"
    flag.parent.mkdir()
    proc = _run(args, env={PAUSE_ENV: str(flag)})
    _wait_for(flag, proc)
    (tmp_path / "c.txt").mkdir()  # appears after the checks: the second rename fails
    flag.unlink()
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 1
    assert out == ""
    ply = tmp_path / "c_sharp.ply"
    assert err == (
        f"meshlab-sharp: error: cannot write {tmp_path / 'c.txt'}: Is a directory "
        f"(written: {ply}; the others were not)\n"
    )
    assert _hidden(tmp_path) == []
    assert ply.read_bytes().startswith(b"ply\n")
    assert (tmp_path / "c.json").read_bytes() == b"old c.json\n"


@pytest.mark.parametrize("option", ["--indices", "--report", "--plot", "-o", "--save-processed"])
def test_outputs_are_checked_before_anything_is_read(tmp_path, capsys, option):
    missing = tmp_path / "missing"
    name = {"--plot": "x.png", "-o": "x.ply", "--save-processed": "x.ply"}.get(option, "x.txt")
    extra = ["--fill-holes"] if option == "--save-processed" else []
    # the input does not exist either: the output's folder is what fails
    code = main(["detect", str(tmp_path / "absent.ply"), option, str(missing / name), *extra])
    assert code == 1
    err = capsys.readouterr().err
    assert err == (
        f"meshlab-sharp: error: cannot write {missing / name}: the folder {missing} "
        "does not exist\n"
    )
    assert list(tmp_path.iterdir()) == []


def test_an_output_that_is_a_folder_or_exists_is_refused_first(tmp_path, capsys):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(9))
    (tmp_path / "r.json").mkdir()
    assert main(["detect", str(src), "--report", str(tmp_path / "r.json")]) == 1
    assert capsys.readouterr().err.endswith("r.json: it is a folder\n")
    (tmp_path / "c.txt").write_text("old\n")
    assert main(["detect", str(src), "--indices", str(tmp_path / "c.txt")]) == 1
    assert "c.txt exists; use --force" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.ply", "c.txt", "r.json"]


def _mount_tmpfs(folder: Path, options: str) -> None:
    """Mount a 64 KiB tmpfs on ``folder`` (root only; skips the test otherwise)."""
    folder.mkdir()
    proc = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size=64k,{options}", "tmpfs", str(folder)],
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs: {proc.stderr.strip()}")


@pytest.fixture
def tiny_disk(tmp_path):
    """A 64 KiB file system."""
    folder = tmp_path / "disk"
    _mount_tmpfs(folder, "rw")
    yield folder
    subprocess.run(["umount", str(folder)], check=True)


@pytest.fixture
def read_only_folder(tmp_path):
    """A folder nobody may write in, root included (a read-only file system)."""
    folder = tmp_path / "locked"
    _mount_tmpfs(folder, "ro")
    yield folder
    subprocess.run(["umount", str(folder)], check=True)


def test_an_unwritable_output_folder_is_refused_first(tmp_path, capsys, read_only_folder):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(9))
    assert main(["detect", str(src), "--indices", str(read_only_folder / "c.txt")]) == 1
    assert capsys.readouterr().err == (
        f"meshlab-sharp: error: cannot write {read_only_folder / 'c.txt'}: the folder "
        f"{read_only_folder} is not writable\n"
    )
    assert not (tmp_path / "c_sharp.ply").exists()


def test_a_full_disk_is_one_line_naming_the_output(tmp_path, tiny_disk):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(30))  # 5,402 points: 250 KB
    out = tiny_disk / "c_sharp.ply"
    proc = _run(["detect", src, "-o", out, "-q"])
    out_, err = proc.communicate(timeout=120)
    assert proc.returncode == 1
    assert out_ == ""
    assert err == f"meshlab-sharp: error: cannot write {out}: No space left on device\n"
    assert list(tiny_disk.iterdir()) == []


def test_a_write_error_names_the_destination_not_the_temporary_file(tmp_path):
    def no_space(tmp: str) -> None:
        Path(tmp).write_bytes(b"ply\n")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), tmp)

    dest = tmp_path / "out.txt"
    with OutputSet() as outputs, pytest.raises(OutputError) as exc:
        outputs.stage(dest, no_space)
    assert str(exc.value) == f"cannot write {dest}: No space left on device"
    assert list(tmp_path.iterdir()) == []


def test_an_unknown_backend_in_the_environment_is_an_error(tmp_path, monkeypatch):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(9))
    proc = _run(["detect", src], env={"MESHLAB_SHARP_BACKEND": "cuda"})
    out, err = proc.communicate(timeout=60)
    assert (proc.returncode, out) == (1, "")
    assert err == (
        "meshlab-sharp: error: MESHLAB_SHARP_BACKEND='cuda' is not a backend; "
        "choose from compiled, numpy\n"
    )
    assert not (tmp_path / "c_sharp.ply").exists()
    monkeypatch.setenv("MESHLAB_SHARP_BACKEND", "cuda")
    with pytest.raises(meshlab_sharp.InputError, match="MESHLAB_SHARP_BACKEND='cuda'"):
        meshlab_sharp.detect(shapes.cube_grid_points(9))


def test_the_sample_checks_its_outputs_before_it_is_built(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))

    def no_build(*args, **kwargs):
        raise AssertionError("the sample was built before the outputs were checked")

    monkeypatch.setattr(sample, "make_part", no_build)
    (tmp_path / "ids.txt").write_text("old\n")
    assert main(["detect", "--sample", "mesh", "--indices", "ids.txt"]) == 1
    assert capsys.readouterr().err == (
        "meshlab-sharp: error: ids.txt exists; use --force to overwrite it\n"
    )
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_sample_reruns_replace_their_own_outputs_and_kinds_do_not_collide(tmp_path, monkeypatch):
    """The README's first command runs twice; the cloud and the mesh have files of
    their own; the sample's outputs in out/ are replaced, an output elsewhere still
    needs --force."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    make_part = sample.make_part
    monkeypatch.setattr(
        sample, "make_part", lambda *a, **k: make_part(*a, **{**k, "n_points": 3_000})
    )
    out = tmp_path / "out"
    assert main(["detect", "--sample", "-q"]) == 0
    (out / "sample_part_sharp.ply").write_bytes(b"stale")
    assert main(["detect", "--sample", "-q"]) == 0
    assert (out / "sample_part_sharp.ply").read_bytes().startswith(b"ply\n")
    assert main(["detect", "--sample", "mesh", "-q"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "sample_part_mesh_sharp.ply",
        "sample_part_sharp.ply",
    ]
    assert _read_back(out / "sample_part_sharp.ply")[1] is None
    assert _read_back(out / "sample_part_mesh_sharp.ply")[1] is not None
    # the README's first command (with --plot out/...) runs twice: every output the
    # sample writes in out/ is its own
    (out / "ids.txt").write_bytes(b"stale")
    assert main(["detect", "--sample", "-q", "--indices", "out/ids.txt"]) == 0
    assert (out / "ids.txt").read_text().split()[0].isdigit()
    # an output elsewhere still needs --force
    (tmp_path / "mine.ply").write_bytes(b"mine")
    assert main(["detect", "--sample", "-q", "-o", "mine.ply"]) == 1
    assert (tmp_path / "mine.ply").read_bytes() == b"mine"


def test_the_sample_writes_into_out(tmp_path, monkeypatch):
    """Default sample outputs go to out/ (created; git ignores it), not the checkout."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    make_part = sample.make_part
    monkeypatch.setattr(
        sample, "make_part", lambda *a, **k: make_part(*a, **{**k, "n_points": 3_000})
    )
    assert main(["detect", "--sample", "-q"]) == 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["sample_part_sharp.ply"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache", "out"]
    ignored = subprocess.run(
        ["git", "check-ignore", "-q", "out/sample_part_sharp.ply"], cwd=ROOT, check=False
    )
    assert ignored.returncode == 0


def test_the_interruption_message_says_what_was_written():
    exc = Interrupted(signal.SIGHUP)
    assert _interrupted_message(exc) == "interrupted by SIGHUP"  # a command with no outputs
    exc.written = []
    assert _interrupted_message(exc) == "interrupted by SIGHUP; no output was written"
    exc.written = [Path("a.ply"), Path("a.txt")]  # the signal came after the renames
    assert _interrupted_message(exc) == "interrupted by SIGHUP after writing a.ply, a.txt"


@pytest.mark.slow
def test_sample_plot_without_matplotlib_leaves_no_out_folder(tmp_path):
    """The missing extra is found before out/ is made (matplotlib hidden by a package
    of the same name that cannot be imported)."""
    blocker = tmp_path / "site" / "matplotlib"
    blocker.mkdir(parents=True)
    (blocker / "__init__.py").write_text("raise ImportError('hidden for the test')\n")
    work = tmp_path / "work"
    work.mkdir()
    env = {"PYTHONPATH": f"{tmp_path / 'site'}{os.pathsep}{ROOT}"}
    proc = subprocess.run(
        [sys.executable, "-m", "meshlab_sharp", "detect", "--sample", "--plot", "out/r.png"],
        env=dict(os.environ, **env),
        cwd=work,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 1
    assert proc.stderr == (
        "meshlab-sharp: error: the report picture needs matplotlib: "
        "pip install 'meshlab-sharp[plot]'\n"
    )
    assert list(work.iterdir()) == []


def test_the_report_names_the_version_and_curves_twice_is_an_error(tmp_path):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(9))
    report = tmp_path / "r.json"
    assert main(["detect", str(src), "-q", "--report", str(report)]) == 0
    assert json.loads(report.read_text())["version"] == meshlab_sharp.__version__
    proc = _run(["detect", src, "--curves", tmp_path / "a.ply", "--curves", tmp_path / "b.obj"])
    out, err = proc.communicate(timeout=60)
    assert (proc.returncode, out) == (1, "")
    assert err == ("meshlab-sharp: error: --curves given twice (see meshlab-sharp detect --help)\n")
    assert not (tmp_path / "a.ply").exists() and not (tmp_path / "b.obj").exists()
