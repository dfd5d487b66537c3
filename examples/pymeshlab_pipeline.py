"""A pymeshlab pipeline around meshlab-sharp: load a scan, clean it with MeshLab's own
filters, detect sharp features on the MeshSet, select them by quality, save.

    python examples/pymeshlab_pipeline.py SCAN.ply [-o OUT_DIR]
    python examples/pymeshlab_pipeline.py            # makes a stand-in scan first

Without SCAN it writes a stand-in scan to OUT_DIR: the built-in sample part as a point
cloud with scanner-like noise (10 % of the point spacing along the normal) and 1 % far
outliers. Outputs in OUT_DIR (default: the current folder):

- ``STEM_annotated.ply``: the cleaned cloud or mesh, vertex quality = feature strength,
  the vertices whose strength is at least ``--min-strength`` selected, features red
  (MeshLab shows all three);
- ``STEM_features.ply``: only the vertices whose strength is at least ``--min-strength``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pymeshlab

import meshlab_sharp


def make_scan(path: Path, n_points: int) -> Path:
    """Write the sample part with noise and outliers to ``path`` (a stand-in scan).

    Noise: each point moves along its true normal by N(0, (0.1 spacing)^2), a scanner's
    depth error. Outliers: 1 % more points, uniform in the bounding box grown by 20 % of
    its diagonal, at least 2 spacings from the surface.
    """
    import numpy as np
    from scipy.spatial import cKDTree

    from meshlab_sharp.sample import sample_part

    part = sample_part("points", n_points=n_points)
    rng = np.random.default_rng(0)
    points = part.vertices + part.normals * rng.normal(0.0, 0.1 * part.spacing, part.n)[:, None]
    points = points.astype(np.float32).astype(np.float64)
    rng, k = np.random.default_rng(0), round(0.01 * part.n)
    lo, hi = points.min(0), points.max(0)
    pad = 0.2 * float(np.linalg.norm(hi - lo))
    tree, strays = cKDTree(points), np.empty((0, 3))
    while len(strays) < k:
        c = rng.uniform(lo - pad, hi + pad, size=(2 * (k - len(strays)) + 8, 3))
        strays = np.vstack([strays, c[tree.query(c)[0] > 2 * part.spacing]])
    points = np.vstack([points, strays[:k].astype(np.float32)])
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.asarray(points, np.float64)))
    ms.save_current_mesh(str(path), binary=True)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scan", nargs="?", help="a point cloud or mesh (default: stand-in)")
    parser.add_argument("-o", "--out-dir", default=".", help="output folder")
    parser.add_argument("--points", type=int, default=20_000, help="stand-in scan size")
    parser.add_argument(
        "--min-strength", type=float, default=1.0, help="select strength >= this (0..1]"
    )
    args = parser.parse_args(argv)
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    scan = Path(args.scan) if args.scan else make_scan(out / "scan.ply", args.points)

    # 1. Load.
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(scan))
    n_loaded = ms.current_mesh().vertex_number()
    is_mesh = ms.current_mesh().face_number() > 0

    # 2. Clean with MeshLab filters.
    ms.meshing_remove_duplicate_vertices()
    if is_mesh:
        ms.meshing_remove_unreferenced_vertices()
        ms.meshing_remove_null_faces()
        ms.meshing_close_holes(maxholesize=30)
        ms.apply_coord_taubin_smoothing(stepsmoothnum=5)
    else:
        # Stray points: robust mode (the default) leaves isolated ones out by itself;
        # MeshLab's filter removes them before, as a scan pipeline would.
        ms.compute_selection_point_cloud_outliers(propthreshold=0.8, knearest=32)
        ms.meshing_remove_selected_vertices()
    n_clean = ms.current_mesh().vertex_number()

    # 3. Detect on the MeshSet's current mesh: quality = strength, selection = features.
    result = meshlab_sharp.detect_meshset(ms, colorize=True)

    # 4. Select by quality (strength = fraction of scales at which a point was a candidate).
    ms.compute_selection_by_scalar_per_vertex(minq=args.min_strength, maxq=1.0)
    n_selected = int(ms.current_mesh().vertex_selection_array().sum())

    # 5. Save the annotated geometry, then only the selected vertices.
    stem = scan.stem
    flags = {"save_vertex_quality": True, "save_vertex_flag": True, "save_vertex_color": True}
    ms.save_current_mesh(str(out / f"{stem}_annotated.ply"), binary=True, **flags)
    ms.generate_copy_of_current_mesh()
    ms.apply_selection_inverse(invverts=True)
    ms.meshing_remove_selected_vertices()
    ms.save_current_mesh(str(out / f"{stem}_features.ply"), binary=True, **flags)

    print(
        f"{scan}: {n_loaded} vertices loaded, {n_clean} after cleaning, "
        f"{result.n_features} sharp features, {n_selected} selected with strength >= "
        f"{args.min_strength} -> {out / f'{stem}_features.ply'}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
