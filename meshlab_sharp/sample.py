"""The built-in sample part: a fandisk-like machined block, generated on the fly.

A 100 x 60 x 40 block (units: mm) with planes, a step (concave 90-degree edge), a
45-degree chamfer, a 25-degree slope (whose plane also bevels the raised block's
right top edge), a cylindrical boss (convex rim, concave foot)
and a countersunk drilled hole (two 45-degree circles, a 90-degree rim below): strong
and weak, convex and concave sharp edges, all known exactly. It is the ``"fandisk"``
part of ``meshlab_sharp.parts``; see there for how it is built and sampled.

>>> from meshlab_sharp.sample import sample_part
>>> part = sample_part()              # 50,000 Poisson-disk points   # doctest: +SKIP
>>> part.vertices.shape, part.edges.shape, part.spacing              # doctest: +SKIP
"""

from __future__ import annotations

import hashlib
import zipfile
from pathlib import Path

import numpy as np

from . import __version__, parts
from .cache import cache_dir
from .io import atomic_write
from .parts import SamplePart, make_part

__all__ = ["SAMPLE_NAME", "SamplePart", "sample_part"]

SAMPLE_NAME = "fandisk"


def sample_part(
    kind: str = "points", *, n_points: int | None = None, seed: int = 0, cache: bool = False
) -> SamplePart:
    """Generate the sample part (no file, no download; a few seconds).

    Parameters
    ----------
    kind : {"points", "mesh"}
        ``"points"``: exactly ``n_points`` Poisson-disk points on the surface (default
        50,000, spacing about 0.54), no noise. ``"mesh"``: a watertight, isotropic
        triangle mesh of about ``n_points`` vertices (default 25,000, edge length about
        1.05) whose sharp edges are mesh edges; it does not depend on ``seed``.
    n_points : int, optional
        See ``kind``.
    seed : int
        Seed of the point sampling; the same seed gives the same arrays.
    cache : bool, default False
        Keep the part in the user's cache folder (``sample/`` in
        :func:`meshlab_sharp.cache.cache_dir`), keyed by the arguments, the version and
        the generator's source, and load it from there next time (the CLI does).

    Returns
    -------
    SamplePart
        ``vertices`` (n, 3) float64 (float32-representable), ``faces`` (m, 3) int64 or
        None, ``edges`` (e, 2, 3) float64 exact sharp-edge segments, ``spacing``,
        ``normals`` (n, 3), ``name`` = "fandisk".
    """
    if not cache:
        return make_part(SAMPLE_NAME, kind, n_points=n_points, seed=seed)
    path = _cache_file(kind, n_points, seed)
    try:
        return _read_cached(path, kind, seed)
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        pass  # absent or unreadable: build it again
    part = make_part(SAMPLE_NAME, kind, n_points=n_points, seed=seed)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, lambda tmp: _write_cached(tmp, part))
    except OSError:
        pass  # a cache that cannot be written only costs time
    return part


_FIELDS = ("vertices", "edges", "normals", "outliers")


def _cache_file(kind: str, n_points: int | None, seed: int) -> Path:
    """The cache file of one part: its arguments, the version and a digest of the
    generator's source in the name."""
    source = b"".join(Path(m).read_bytes() for m in (__file__, parts.__file__))
    digest = hashlib.sha256(source).hexdigest()[:12]
    size = "default" if n_points is None else str(int(n_points))
    name = f"{SAMPLE_NAME}-{kind}-{size}-seed{seed}-{__version__}-{digest}.npz"
    return cache_dir() / "sample" / name


def _write_cached(tmp: str, part: SamplePart) -> None:
    verts, faces = part.extra["reference"]
    arrays = {f: getattr(part, f) for f in _FIELDS}
    if part.faces is not None:
        arrays["faces"] = part.faces
    with open(tmp, "wb") as fh:  # an open file: np.savez would add ".npz" to a name
        np.savez(fh, spacing=part.spacing, ref_vertices=verts, ref_faces=faces, **arrays)


def _read_cached(path: Path, kind: str, seed: int) -> SamplePart:
    with np.load(path, allow_pickle=False) as data:
        return SamplePart(
            name=SAMPLE_NAME,
            faces=data["faces"] if "faces" in data.files else None,
            spacing=float(data["spacing"]),
            kind=kind,
            seed=seed,
            extra={"reference": (data["ref_vertices"], data["ref_faces"])},
            **{f: data[f] for f in _FIELDS},
        )
