"""The documentation cannot drift: every shell and Python block of the README and the
guide pages runs, on small inputs in a temporary folder, and prints what the page says
it prints; the figures the pages quote are recomputed; the site builds with
``mkdocs build --strict``, so a broken link or API reference fails.

A block preceded by an HTML comment ``<!-- skip ... -->`` is not run (package installs,
MeshLab, a cluster). A ``text`` block right after a runnable block is its expected
output: each of its lines must appear in an output line, in order, where ``...`` stands
for anything (a line that is only ``...`` for any number of lines).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import pytest
from files import write_ply

import meshlab_sharp
from meshlab_sharp.sample import sample_part

#: In CI a skip here is a failure (conftest.py): set-up installs the docs extra there.
REQUIRED_IN_CI = True

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
#: The pages whose blocks run: the README and the guide.
PAGES = [
    ROOT / "README.md",
    *(
        DOCS / f"{name}.md"
        for name in (
            "getting-started",
            "cli",
            "python-api",
            "preprocessing",
            "large-data",
            "curves",
            "output-formats",
        )
    ),
]
RUNNABLE = ("bash", "python")
FENCE = re.compile(r"^```(\w*)\s*$")


@dataclass
class Block:
    """A fenced code block of a page."""

    page: Path
    line: int  # 1-based line of the opening fence
    end: int  # 0-based index of the closing fence
    lang: str
    code: str
    skip: bool
    expected: list[str] | None = None

    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def blocks(page: Path) -> list[Block]:
    """The page's fenced blocks, with their skip markers and expected outputs."""
    lines = page.read_text().splitlines()
    found: list[Block] = []
    i = 0
    while i < len(lines):
        opening = FENCE.match(lines[i])
        if not opening:
            i += 1
            continue
        end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
        before = [x for x in lines[:i] if x.strip()]
        skip = bool(before) and before[-1].strip().startswith("<!-- skip")
        code = "\n".join(lines[i + 1 : end]) + "\n"
        block = Block(page, i + 1, end, opening.group(1), code, skip)
        previous = found[-1] if found else None
        if (
            block.lang == "text"
            and previous is not None
            and previous.lang in RUNNABLE
            and previous.expected is None
            and all(not x.strip() for x in lines[previous.end + 1 : i])
        ):
            previous.expected = code.splitlines()
        else:
            found.append(block)
        i = end + 1
    return found


def matches(expected: list[str], output: str) -> bool:
    """Each expected line in an output line, in order; ``...`` matches anything."""
    out = output.splitlines()
    k = 0
    for want in expected:
        if not want.strip() or want.strip() == "...":
            continue
        parts = [p.strip() for p in want.split("...") if p.strip()]
        while k < len(out) and not _line_has(out[k], parts):
            k += 1
        if k == len(out):
            return False
        k += 1
    return True


def _line_has(line: str, parts: list[str]) -> bool:
    at = 0
    for part in parts:
        at = line.find(part, at)
        if at < 0:
            return False
        at += len(part)
    return True


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """The files the pages name, small: ``part.*`` the sample part as a mesh of about
    4,000 vertices, ``scan.*`` a 6,000-point cloud sampled on it."""
    folder = tmp_path_factory.mktemp("inputs")
    mesh = sample_part("mesh", n_points=4000, cache=True)
    cloud = sample_part("points", n_points=6000, cache=True)
    write_ply(folder / "part.ply", mesh.vertices, mesh.faces, binary=True)
    with (folder / "part.obj").open("w") as f:
        f.writelines(f"v {x!r} {y!r} {z!r}\n" for x, y, z in mesh.vertices.tolist())
        f.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces.tolist())
    write_ply(folder / "scan.ply", cloud.vertices, None, binary=True)
    with (folder / "scan.xyz").open("w") as f:
        f.writelines(f"{x!r} {y!r} {z!r}\n" for x, y, z in cloud.vertices.tolist())
    return folder


def _workdir(inputs: Path, tmp_path: Path) -> tuple[Path, dict[str, str]]:
    """A fresh copy of the inputs, with ``.venv`` pointing at this interpreter's
    environment (the README writes ``.venv/bin/meshlab-sharp``)."""
    work = tmp_path / "work"
    shutil.copytree(inputs, work)
    (work / ".venv").symlink_to(Path(sys.prefix), target_is_directory=True)
    bin_dir = str(Path(sys.executable).parent)
    env = dict(os.environ, PATH=f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}")
    env.pop("MESHLAB_SHARP_BACKEND", None)
    return work, env


def _check(block: Block, code: int, output: str) -> None:
    assert code == 0, f"{block.where()}: exit status {code}\n{block.code}\n{output[-3000:]}"
    if block.expected is not None:
        assert matches(block.expected, output), (
            f"{block.where()}: the output does not show what the page says\n"
            f"expected:\n{chr(10).join(block.expected)}\noutput:\n{output[-3000:]}"
        )


def _run(argv: list[str], work: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    """Run ``argv`` in ``work``, stdout and stderr together, as a terminal shows them."""
    return subprocess.run(
        argv,
        cwd=work,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=600,
    )


PYTHON_DRIVER = """
import json, sys
ns = {"__name__": "__main__"}
for i, source in enumerate(json.load(open(sys.argv[1]))):
    print(f"\\x00block {i}", flush=True)
    exec(compile(source, f"block {i}", "exec"), ns)
    sys.stdout.flush()
"""


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_page_blocks_run_and_print_what_the_page_says(page, inputs, tmp_path):
    """Shell blocks one by one; Python blocks in order in one interpreter, sharing
    their names, as a reader would type them."""
    runnable = [b for b in blocks(page) if b.lang in RUNNABLE and not b.skip]
    assert runnable, f"{page.name}: no runnable block"
    work, env = _workdir(inputs, tmp_path)
    for block in (b for b in runnable if b.lang == "bash"):
        proc = _run(["bash", "-euo", "pipefail", "-c", block.code], work, env)
        _check(block, proc.returncode, proc.stdout)
    python = [b for b in runnable if b.lang == "python"]
    if not python:
        return
    (tmp_path / "blocks.json").write_text(json.dumps([b.code for b in python]))
    proc = _run([sys.executable, "-c", PYTHON_DRIVER, str(tmp_path / "blocks.json")], work, env)
    outputs = proc.stdout.split("\x00block ")[1:]
    for i, block in enumerate(python):
        if i >= len(outputs):
            pytest.fail(f"{block.where()}: not reached\n{proc.stdout[-3000:]}")
        ran = outputs[i].split("\n", 1)[1] if "\n" in outputs[i] else ""
        failed = i == len(outputs) - 1 and proc.returncode != 0
        _check(block, 1 if failed else 0, ran)


def test_blocks_are_found_and_skips_are_few():
    """The parser sees the pages' blocks, and the blocks that do not run stay few."""
    every = [b for page in PAGES for b in blocks(page)]
    runnable = [b for b in every if b.lang in RUNNABLE]
    skipped = [b.where() for b in runnable if b.skip]
    assert len(runnable) >= 20
    assert len(skipped) <= 8, skipped
    assert all(b.lang in RUNNABLE for b in every if b.expected is not None)


def test_matches():
    out = "sample part: 50000 points, 1981 sharp features (4.0%) -> a.ply [6.1 s]\nTrue\n"
    assert matches(["50000 points, ... 1981 sharp features", "True"], out)
    assert matches(["...", "True"], out)
    assert not matches(["True", "50000 points"], out)
    assert not matches(["1982 sharp features"], out)


@pytest.fixture(scope="module")
def sample_counts() -> dict[str, int]:
    """The built-in sample part's feature counts, as the pages quote them."""
    cloud = sample_part("points", cache=True)
    mesh = sample_part("mesh", cache=True)
    return {
        "points": len(cloud.vertices),
        "robust": meshlab_sharp.detect(cloud.vertices).n_features,
        "paper": meshlab_sharp.detect(cloud.vertices, mode="paper").n_features,
        "vertices": len(mesh.vertices),
        "mesh": meshlab_sharp.detect(mesh.vertices, mesh.faces).n_features,
    }


@pytest.mark.slow
def test_quoted_sample_figures(sample_counts):
    """The README's caption and the MeshLab page's quote the sample's counts."""
    c = sample_counts
    readme = " ".join((ROOT / "README.md").read_text().split())
    share = 100 * c["robust"] / c["points"]
    assert f"({c['points']:,} points sampled" in readme
    assert f"{c['robust']:,} points ({share:.1f}%) are features" in readme
    assert f"As a {c['vertices']:,}-vertex mesh: {c['mesh']:,} features" in readme
    assert f"(`--mode paper`) on the same points: {c['paper']:,} features" in readme
    meshlab = " ".join((DOCS / "meshlab.md").read_text().split())
    assert f"{c['vertices']:,}-vertex mesh after the filter with its defaults: " in meshlab
    assert f"{c['mesh']:,} features selected" in meshlab


def test_readme_quality_table_quotes_the_evaluation():
    """Every F1 of the README's table is one of the evaluation page's figures."""
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## How well it works", 1)[1].split("\n## ", 1)[0]
    table = "\n".join(x for x in section.splitlines() if x.startswith("|"))
    quoted = re.findall(r"\d\.\d{3}", table)
    evaluation = set(re.findall(r"\d\.\d{3}", (DOCS / "evaluation.md").read_text()))
    assert len(quoted) >= 20
    assert set(quoted) <= evaluation, sorted(set(quoted) - evaluation)


def test_readme_length_and_docs_total():
    """A README a user reads, and a guide without a diary."""
    assert len((ROOT / "README.md").read_text().splitlines()) <= 250
    assert sum(len(p.read_text().splitlines()) for p in DOCS.glob("*.md")) <= 3000


def test_every_page_is_in_the_index_and_the_site():
    """docs/index.md links every page, and mkdocs.yml's nav lists every page."""
    index = (DOCS / "index.md").read_text()
    nav = (ROOT / "mkdocs.yml").read_text()
    for page in DOCS.glob("*.md"):
        if page.name != "index.md":
            assert f"({page.name})" in index, page.name
        assert f" {page.name}" in nav, page.name


@pytest.mark.slow
def test_site_builds_strict(tmp_path):
    """``mkdocs build --strict``: a broken link, anchor or API reference fails."""
    pytest.importorskip("mkdocstrings", reason="the docs extra: pip install -e '.[docs]'")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    reference = (tmp_path / "reference" / "index.html").read_text()
    for name in ("detect", "detect_meshset", "DetectionResult", "Preprocessing"):
        assert f'id="meshlab_sharp.{name}"' in reference, name


def test_meshlab_page_script_is_the_shipped_example():
    """The filter script the MeshLab page shows names every parameter of the shipped
    example, with the same values (meshlabserver aborts on a script that leaves one out)."""
    page = blocks(DOCS / "meshlab.md")
    shown = [b for b in page if b.lang == "xml"]
    assert len(shown) == 1

    def params(text: str) -> dict[str, str]:
        return {p.get("name"): p.get("value") for p in ET.fromstring(text).iter("Param")}

    text = shown[0].code.split("\n", 1)[1]  # after the <!DOCTYPE> line
    example = ROOT / "meshlab_plugin_cpp" / "examples" / "sharp_features_default.mlx"
    expected = params(example.read_text().split("\n", 1)[1])
    assert params(text) == expected
    assert len(expected) == 6
