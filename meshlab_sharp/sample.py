"""The built-in sample part: a fandisk-like machined block, generated on the fly.

A 100 x 60 x 40 block (units: mm) with planes, a step (concave 90-degree edge), a
45-degree chamfer, a 25-degree slope (whose plane also bevels the raised block's
right top edge), a cylindrical boss (convex rim, concave foot)
and a countersunk drilled hole (two 45-degree circles, a 90-degree rim below): strong
and weak, convex and concave sharp edges, all known exactly. It is the ``"fandisk"``
part of ``meshlab_sharp.groundtruth``; see there for how it is built and sampled.

>>> from meshlab_sharp.sample import sample_part
>>> part = sample_part()              # 50,000 Poisson-disk points   # doctest: +SKIP
>>> part.vertices.shape, part.edges.shape, part.spacing              # doctest: +SKIP
"""

from __future__ import annotations

from .groundtruth import SamplePart, make_part

__all__ = ["SAMPLE_NAME", "SamplePart", "sample_part"]

SAMPLE_NAME = "fandisk"


def sample_part(kind: str = "points", *, n_points: int | None = None, seed: int = 0) -> SamplePart:
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

    Returns
    -------
    SamplePart
        ``vertices`` (n, 3) float64 (float32-representable), ``faces`` (m, 3) int64 or
        None, ``edges`` (e, 2, 3) float64 exact sharp-edge segments, ``spacing``,
        ``normals`` (n, 3), ``name`` = "fandisk".
    """
    return make_part(SAMPLE_NAME, kind, n_points=n_points, seed=seed)
