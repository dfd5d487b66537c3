"""The CAD parts: files shipped in public packages, loaded into gmsh's OpenCASCADE kernel.

Sources (all install offline, from the Debian archive or PyPI):

- ``freecad-common`` (Debian): STEP models of electronic packages
  (``/usr/share/freecad/Mod/Idf/Idflibs/*.stp``) and FreeCAD documents whose
  ``PartShape*.brp`` entries are OpenCASCADE B-reps (tool bits, test parts);
- the ``gmsh`` wheel: its STEP demos and OpenCASCADE ``.geo`` scripts (fillets,
  chamfers) under ``share/doc/gmsh`` in the environment.
"""

from __future__ import annotations

import shutil
import sys
import zipfile
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "FREECAD_DIR",
    "GMSH_DOC_DIR",
    "PARTS",
    "QUICK_PARTS",
    "CadSource",
    "load",
    "missing_sources",
]

#: Where ``freecad-common`` installs its data.
FREECAD_DIR = Path("/usr/share/freecad/Mod")
#: Where the gmsh wheel installs its tutorials and demos.
GMSH_DOC_DIR = Path(sys.prefix) / "share" / "doc" / "gmsh"


@dataclass(frozen=True)
class CadSource:
    """One part: a file (or a ``.brp`` entry of a FreeCAD document) and where it comes from.

    Attributes
    ----------
    name : str
        Short name used in tables.
    path : Path
        STEP, BREP or gmsh ``.geo`` file, or a FreeCAD ``.FCStd`` document.
    member : str or None
        The ``.brp`` entry of a FreeCAD document.
    package : str
        The package that ships it.
    """

    name: str
    path: Path
    member: str | None
    package: str


def _idf(name: str) -> CadSource:
    return CadSource(name, FREECAD_DIR / "Idf" / "Idflibs" / f"{name}.stp", None, "freecad-common")


def _fcstd(name: str, rel: str, member: str = "PartShape.brp") -> CadSource:
    return CadSource(name, FREECAD_DIR / rel, member, "freecad-common")


def _gmsh(name: str, rel: str) -> CadSource:
    return CadSource(name, GMSH_DOC_DIR / rel, None, "gmsh")


#: The evaluation's parts, in table order.
PARTS: tuple[CadSource, ...] = (
    _gmsh("t20_bracket", "tutorials/t20_data.step"),
    _gmsh("chamfer_box", "examples/boolean/chamfer.geo"),
    _gmsh("fillet_chamfer", "examples/boolean/fillet_chamfer.geo"),
    _gmsh("fillet_box", "examples/boolean/fillet.geo"),
    _gmsh("fillet_cross", "examples/boolean/fillet2.geo"),
    _idf("EPL22_6_16"),
    _idf("CAP_50SGV_8_10"),
    _idf("SMB_DO_214AA"),
    _idf("SOT428_DPAK"),
    _idf("TCMT1107_4"),
    _idf("RLF_7030"),
    _idf("SOT_323_3"),
    _idf("MSOP_10"),
    _fcstd("holes_plate", "Path/PathTests/test_holes00.fcstd"),
    _fcstd("drilling_block", "Path/PathTests/Drilling_1.FCStd"),
    _fcstd("endmill", "Path/Tools/Shape/endmill.fcstd"),
    _fcstd("v_bit", "Path/Tools/Shape/v-bit.fcstd"),
)

#: ``--quick``: a few parts, one of each family.
QUICK_PARTS = ("chamfer_box", "fillet_box", "SOT428_DPAK")


def missing_sources(parts: tuple[CadSource, ...] = PARTS) -> list[CadSource]:
    """The parts whose file is not installed."""
    return [p for p in parts if not p.path.is_file()]


def load(source: CadSource, workdir: Path) -> None:
    """Load a part into gmsh (initialized) as the only model, OpenCASCADE, synchronized.

    A ``.brp`` entry is extracted into ``workdir`` (gmsh reads B-reps by their
    ``.brep`` suffix). STEP and BREP files are read with ``occ.importShapes``;
    ``.geo`` scripts are run by ``gmsh.open``.
    """
    import gmsh

    gmsh.clear()
    gmsh.model.add(source.name)
    if source.path.suffix == ".geo":
        gmsh.open(str(source.path))
        gmsh.model.occ.synchronize()
        return
    path = source.path
    if source.member is not None:
        path = workdir / f"{source.name}.brep"
        with (
            zipfile.ZipFile(source.path) as z,
            z.open(source.member) as src,
            path.open("wb") as dst,
        ):
            shutil.copyfileobj(src, dst)
    gmsh.model.occ.importShapes(str(path))
    gmsh.model.occ.synchronize()
