"""Preprocessing with pymeshlab's own filters, in a fixed order, mapped back to the input.

Real scans need cleaning before sharp-feature detection (the paper's Figure 13): far
outliers set the scale of the min-max normalisation and hide every edge, noise raises
the projected distance of flat points, holes leave borders. The steps, always applied
in this order (each only when asked for, and only to the kind of input it suits):

1. **remove_outliers** (point clouds): ``compute_selection_point_cloud_outliers``
   (local outlier probability over the ``outlier_neighbours`` nearest points) then
   ``meshing_remove_selected_vertices``.
2. **denoise**, unless the input looks clean (:func:`_noise_level`; smoothing clean
   edges only blurs them): meshes: ``apply_coord_taubin_smoothing`` (default) or
   ``apply_coord_two_steps_smoothing``; point clouds: MLS projection,
   ``compute_mls_projection_rimls`` (default) or ``_apss`` (the cloud with its normals
   as mesh 0, a copy as mesh 1, mesh 1 projected onto mesh 0). Normal smoothing is not
   offered: detection computes its own normals from the positions, so it would change
   nothing.
3. **fill_holes** (meshes): ``meshing_close_holes``, holes up to ``max_hole_size``
   boundary edges (the patch refined to the mesh's mean edge length on request).
4. **simplify**: meshes: ``meshing_decimation_quadric_edge_collapse`` (vertices stay
   at input positions); clouds: ``generate_sampling_poisson_disk`` with
   ``subsample=True`` (a Poisson-disk subset of the points; approximate: on a regular
   grid finer than the disk radius it keeps every point).

Every default is a count, a ratio or an angle, or is derived from the data (mean edge
length, bounding-box diagonal, local point spacing): nothing is in absolute units.
Every parameter is checked before pymeshlab sees it (some bad values, such as ``k=0``,
kill the interpreter).

Each vertex carries its input index through the filters
(:func:`meshlab_sharp.io.tag_input_indices`), so results are mapped back to the
input's order and length: removed points are not features (strength 0, ``kept``
False); vertices added by hole filling have no input index and are left out of the
mapped results (they are in the processed geometry, which can be saved).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .defaults import DENOISE_METHODS as DENOISE_METHODS  # re-exported
from .defaults import MAX_SMOOTHING_STEPS
from .errors import InputError

if TYPE_CHECKING:  # imported when a step runs: the CLI checks its options without them
    import pymeshlab

    from .io import Geometry

__all__ = [
    "DENOISE_METHODS",
    "STEP_ORDER",
    "Preprocessing",
    "PreprocessingReport",
    "as_preprocessing",
    "map_to_input",
    "preprocess",
]

#: The order the steps are applied in, whatever order they are asked for in.
STEP_ORDER = ("remove_outliers", "denoise", "fill_holes", "simplify")
_MESH_DENOISE = ("taubin", "two_steps")
_CLOUD_DENOISE = ("rimls", "apss")
#: Fewest points a point-cloud filter is given (its neighbourhoods need them).
_MIN_POINTS = 4


@dataclass(frozen=True)
class Preprocessing:
    """Which preprocessing steps to run and their parameters (all checked on creation).

    Steps run in the order of :data:`STEP_ORDER`; a step that does not suit the input
    (outlier removal on a mesh, hole filling on a cloud) is skipped and logged.

    Attributes
    ----------
    remove_outliers : bool, default False
        Point clouds: remove points whose local outlier probability exceeds
        ``outlier_probability``.
    outlier_probability : float, default 0.8
        Probability threshold in (0, 1) (pymeshlab's ``propthreshold``).
    outlier_neighbours : int, default 32
        Neighbours of the outlier probability (``knearest``), >= 2 and fewer than the
        points.
    denoise : bool, default False
        Smooth the positions (meshes) or project them on an MLS surface (clouds), unless
        the input looks clean (then the step is skipped with a warning: smoothing only
        blurs clean edges). A method that did not improve detection on the measured
        noisy inputs runs with a warning (the record's ``warning``).
    denoise_method : str, default "auto"
        ``"taubin"`` or ``"two_steps"`` for meshes, ``"rimls"`` or ``"apss"`` for
        clouds; ``"auto"``: ``taubin`` for meshes (the one measured to improve noisy
        meshes), ``rimls`` for clouds.
    smoothing_steps : int or None, default None
        Iterations of mesh smoothing, at most
        :data:`~meshlab_sharp.defaults.MAX_SMOOTHING_STEPS`; None: 10 for Taubin, 3 for
        two-step.
    taubin_lambda : float, default 0.5
        Taubin's shrinking step, in (0, 1).
    taubin_mu : float, default -0.53
        Taubin's inflating step, in (-1, 0), with ``|mu| > lambda`` (no shrinkage).
    normal_threshold : float, default 60.0
        Two-step smoothing: normals farther apart than this angle in degrees, in
        (0, 180), are not averaged (this keeps edges).
    mls_filter_scale : float, default 2.0
        MLS support radius in units of the local point spacing, > 0.
    mls_normal_neighbours : int, default 10
        Neighbours of the normals the MLS surface starts from, >= 2.
    fill_holes : bool, default False
        Meshes: close holes.
    max_hole_size : int or None, default None
        Largest hole closed, in boundary edges (>= 3); None: the bounding-box diagonal
        divided by the mean edge length (a hole about a third of the object across).
    refine_holes : bool, default False
        Refine the patch to the mesh's mean edge length (adds vertices), so the
        neighbourhoods across it look like the rest of the mesh. Off by default: on a
        10,784-vertex part with two holes it took 4.9 s against 0.27 s, for the same
        features (docs/preprocessing.md).
    simplify : float or None, default None
        Keep about this fraction of the vertices, in (0, 1]; None: no simplification.
    """

    remove_outliers: bool = False
    outlier_probability: float = 0.8
    outlier_neighbours: int = 32
    denoise: bool = False
    denoise_method: str = "auto"
    smoothing_steps: int | None = None
    taubin_lambda: float = 0.5
    taubin_mu: float = -0.53
    normal_threshold: float = 60.0
    mls_filter_scale: float = 2.0
    mls_normal_neighbours: int = 10
    fill_holes: bool = False
    max_hole_size: int | None = None
    refine_holes: bool = False
    simplify: float | None = None

    def __post_init__(self) -> None:
        for name in ("remove_outliers", "denoise", "fill_holes", "refine_holes"):
            if not isinstance(getattr(self, name), bool | np.bool_):
                raise InputError(f"preprocessing: {name} must be True or False")
        _check_number("outlier_probability", self.outlier_probability, 0.0, 1.0)
        _check_int("outlier_neighbours", self.outlier_neighbours, 2)
        if self.denoise_method not in DENOISE_METHODS:
            raise InputError(
                f"preprocessing: unknown denoise_method {self.denoise_method!r}; choose "
                f"from {', '.join(DENOISE_METHODS)}"
            )
        if self.smoothing_steps is not None:
            _check_int("smoothing_steps", self.smoothing_steps, 1, MAX_SMOOTHING_STEPS)
        _check_number("taubin_lambda", self.taubin_lambda, 0.0, 1.0)
        _check_number("taubin_mu", self.taubin_mu, -1.0, 0.0)
        if abs(self.taubin_mu) <= self.taubin_lambda:
            raise InputError("preprocessing: taubin_mu needs |mu| > lambda (else it shrinks)")
        _check_number("normal_threshold", self.normal_threshold, 0.0, 180.0)
        _check_number("mls_filter_scale", self.mls_filter_scale, 0.0, math.inf)
        _check_int("mls_normal_neighbours", self.mls_normal_neighbours, 2)
        if self.max_hole_size is not None:
            _check_int("max_hole_size", self.max_hole_size, 3)
        if self.simplify is not None:
            _check_number("simplify", self.simplify, 0.0, 1.0, closed_high=True)

    @property
    def active(self) -> bool:
        """True when at least one step is asked for."""
        return bool(
            self.remove_outliers or self.denoise or self.fill_holes or self.simplify is not None
        )

    def steps(self) -> tuple[str, ...]:
        """The steps asked for, in the order they run."""
        asked = {
            "remove_outliers": self.remove_outliers,
            "denoise": self.denoise,
            "fill_holes": self.fill_holes,
            "simplify": self.simplify is not None,
        }
        return tuple(s for s in STEP_ORDER if asked[s])


@dataclass
class PreprocessingReport:
    """What preprocessing did, and the detection on the processed geometry.

    Attributes
    ----------
    steps : list of dict
        Per step: ``step``, ``filters``, ``parameters`` (as passed to pymeshlab),
        ``vertices_before``, ``vertices_after``, ``seconds``; or ``skipped`` (why);
        denoising also ``method``, ``noise`` and, where it warned, ``warning``.
    geometry : Geometry
        The processed geometry detection ran on.
    to_input : (m,) int64
        Input index of each processed vertex; -1 for a vertex hole filling added.
    result : DetectionResult or None
        The detection in the processed geometry's order (its histograms are those
        Otsu's threshold was taken on).
    """

    steps: list[dict[str, Any]]
    geometry: Geometry
    to_input: np.ndarray
    result: Any = None
    seconds: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """JSON-ready: the steps, the processed vertex count and how many were added."""
        return {
            "steps": self.steps,
            "n_processed": len(self.geometry.vertices),
            "n_added": int((self.to_input < 0).sum()),
            "seconds": round(self.seconds, 6),
        }


def as_preprocessing(value: Preprocessing | Mapping[str, Any] | None) -> Preprocessing | None:
    """Accept a :class:`Preprocessing`, a mapping of its fields, or None."""
    if value is None or isinstance(value, Preprocessing):
        return value
    if isinstance(value, Mapping):
        unknown = sorted(set(value) - {f.name for f in dataclasses.fields(Preprocessing)})
        if unknown:
            raise InputError(f"preprocessing: unknown parameter(s) {', '.join(unknown)}")
        return Preprocessing(**value)
    raise InputError(
        f"preprocessing must be a Preprocessing, a dict or None, not {type(value).__name__}"
    )


def preprocess(
    geometry: Geometry | np.ndarray,
    steps: Preprocessing | Mapping[str, Any],
    *,
    log: list[dict[str, Any]] | None = None,
) -> tuple[Geometry, np.ndarray]:
    """Run the preprocessing steps on a mesh or point cloud.

    Parameters
    ----------
    geometry : Geometry or (n, 3) array
        The input (an array is a point cloud).
    steps : Preprocessing or mapping
        The steps and their parameters.
    log : list, optional
        Receives one dict per step asked for (see :class:`PreprocessingReport`).

    Returns
    -------
    processed : Geometry
        The processed vertices (and faces for a mesh).
    to_input : (m,) int64
        Input index of each processed vertex; -1 for vertices added by hole filling.

    Raises
    ------
    InputError
        Invalid parameters, too few points for a filter's neighbourhoods, nothing
        left after outlier removal, or a pymeshlab filter failing.
    """
    from .io import Geometry, as_geometry

    config = as_preprocessing(steps)
    if config is None:
        raise InputError("preprocess: no steps given")
    geom = geometry if isinstance(geometry, Geometry) else as_geometry(geometry)
    n = len(geom.vertices)
    state = _State(geom.vertices, geom.faces if geom.is_mesh else None, np.arange(n), n)
    records = log if log is not None else []
    for step in config.steps():
        before = state.n
        t = time.perf_counter()
        record: dict[str, Any] = {"step": step}
        skipped = _STEPS[step](state, config, record)
        if skipped:
            record["skipped"] = skipped
        else:
            record.update(
                vertices_before=before,
                vertices_after=state.n,
                seconds=round(time.perf_counter() - t, 6),
            )
        records.append(record)
    processed = Geometry(state.vertices, state.faces, f"{geom.source} (preprocessed)")
    return processed, state.to_input


def map_to_input(
    result: Any,
    to_input: np.ndarray,
    n_input: int,
    report: PreprocessingReport,
) -> Any:
    """A copy of a processed-order DetectionResult with every per-vertex array in the
    input's order and length (``n_input``).

    Input vertices removed by preprocessing get mask False, strength 0, ``kept`` False,
    NaN details; processed vertices with no input index (hole filling) are left out.
    ``result.preprocessing`` is set to ``report`` (which keeps the processed result).
    """
    valid = to_input >= 0
    from_input = np.full(n_input, -1, dtype=np.int64)
    from_input[to_input[valid]] = np.flatnonzero(valid)
    mapped = from_input >= 0
    source = from_input[mapped]

    def scatter(values: np.ndarray, fill: Any, axis: int = 0) -> np.ndarray:
        moved = np.moveaxis(values, axis, 0)
        out = np.full((n_input, *moved.shape[1:]), fill, dtype=values.dtype)
        out[mapped] = moved[source]
        return np.moveaxis(out, 0, axis)

    report.result = result
    return dataclasses.replace(
        result,
        mask=scatter(result.mask, False),
        strength=scatter(result.strength, 0.0),
        kept=scatter(result.kept, False),
        distances=None if result.distances is None else scatter(result.distances, np.nan, 1),
        normals=None if result.normals is None else scatter(result.normals, np.nan, 1),
        timings=dict(result.timings),
        preprocessing=report,
    )


# ------------------------------------------------------------------------------------
# The steps
# ------------------------------------------------------------------------------------


@dataclass
class _State:
    """The geometry between steps, with each vertex's input index (-1: added)."""

    vertices: np.ndarray
    faces: np.ndarray | None
    to_input: np.ndarray
    n_input: int

    @property
    def n(self) -> int:
        return len(self.vertices)

    @property
    def is_mesh(self) -> bool:
        return self.faces is not None

    def meshset(self) -> pymeshlab.MeshSet:
        """A fresh MeshSet holding the geometry (mesh 0) with its input indices."""
        import pymeshlab

        from .io import tag_input_indices

        kwargs: dict[str, Any] = {"vertex_matrix": np.ascontiguousarray(self.vertices)}
        if self.faces is not None:
            kwargs["face_matrix"] = np.ascontiguousarray(self.faces, dtype=np.int32)
        mesh = pymeshlab.Mesh(**kwargs)
        tag_input_indices(mesh, self.to_input)
        ms = pymeshlab.MeshSet()
        ms.add_mesh(mesh, "preprocessing")
        return ms

    def update(self, ms: pymeshlab.MeshSet, *, tagged: bool = True) -> None:
        """Take the current mesh of ``ms``: its vertices, faces and (when the filters
        carried the tags) input indices, which point into this state's input."""
        from .io import tagged_input_indices

        mesh = ms.current_mesh()
        vertices = mesh.vertex_matrix()
        faces = mesh.face_matrix().astype(np.int64) if mesh.face_number() > 0 else None
        if tagged:
            # tags hold to_input + 1, so they are indices into the original input
            self.to_input = tagged_input_indices(ms, self.n_input)
        del mesh
        self.vertices = vertices
        self.faces = faces if self.is_mesh else None


def _remove_outliers(state: _State, config: Preprocessing, record: dict[str, Any]) -> str:
    if state.is_mesh:
        return "point clouds only (a mesh's stray vertices are dropped by cleaning)"
    k = config.outlier_neighbours
    if state.n <= k:
        raise InputError(
            f"remove_outliers: {state.n} points, not more than outlier_neighbours = {k}"
        )
    params = {"propthreshold": float(config.outlier_probability), "knearest": int(k)}
    record["filters"] = [
        "compute_selection_point_cloud_outliers",
        "meshing_remove_selected_vertices",
    ]
    record["parameters"] = params
    ms = state.meshset()
    _apply(ms, "compute_selection_point_cloud_outliers", **params)
    n_selected = int(ms.current_mesh().vertex_selection_array().sum())
    if n_selected >= state.n - _MIN_POINTS:
        raise InputError(
            f"remove_outliers: {n_selected} of {state.n} points are outliers at "
            f"outlier_probability = {config.outlier_probability}; nothing would be left"
        )
    if n_selected:
        _apply(ms, "meshing_remove_selected_vertices")
        state.update(ms)
    record["removed"] = n_selected
    return ""


def _denoise(state: _State, config: Preprocessing, record: dict[str, Any]) -> str:
    method = config.denoise_method
    if method == "auto":
        method = "taubin" if state.is_mesh else "rimls"
    if state.is_mesh and method not in _MESH_DENOISE:
        raise InputError(
            f"denoise_method {method!r} is for point clouds; for meshes use "
            f"{' or '.join(_MESH_DENOISE)}"
        )
    if not state.is_mesh and method not in _CLOUD_DENOISE:
        raise InputError(
            f"denoise_method {method!r} is for meshes; for point clouds use "
            f"{' or '.join(_CLOUD_DENOISE)}"
        )
    record["method"] = method
    k = config.mls_normal_neighbours
    if method in _CLOUD_DENOISE and state.n <= k:
        raise InputError(f"denoise: {state.n} points, not more than mls_normal_neighbours = {k}")
    noise, clean = _noise_level(state)
    record["noise"] = round(noise, 6)
    if clean:
        unit = "degrees, the dihedral angles' lower quartile" if state.is_mesh else "median ratio"
        reason = (
            f"the input looks clean (noise {noise:.3g} {unit}; clean up to "
            f"{_clean_bound(state)}): smoothing would only blur its edges"
        )
        record["warning"] = f"denoise skipped: {reason}"
        return reason
    if method != "taubin":
        record["warning"] = (
            f"denoise: {method} on noisy {'meshes' if state.is_mesh else 'point clouds'} did "
            "not improve the detection in any measured case (docs/preprocessing.md)"
            + ("" if state.is_mesh else "; robust mode copes with the noise itself")
        )
    elif noise < TAUBIN_HELPS_ANGLE:
        record["warning"] = (
            f"denoise: the noise is light ({noise:.3g} degrees, the dihedral angles' lower "
            f"quartile): taubin improved the detection only from {TAUBIN_HELPS_ANGLE:g} "
            "degrees in the measured cases (docs/preprocessing.md); robust mode copes with "
            "light noise itself"
        )
    ms = state.meshset()
    if method == "taubin":
        params: dict[str, Any] = {
            "lambda_": float(config.taubin_lambda),
            "mu": float(config.taubin_mu),
            "stepsmoothnum": int(config.smoothing_steps or 10),
        }
        record.update(filters=["apply_coord_taubin_smoothing"], parameters=params)
        _apply(ms, "apply_coord_taubin_smoothing", **params)
        state.update(ms)
        return ""
    if method == "two_steps":
        params = {
            "stepsmoothnum": int(config.smoothing_steps or 3),
            "normalthr": float(config.normal_threshold),
        }
        # the filter needs a compact mesh ("Lack of Compactness" otherwise): drop the
        # unreferenced vertices first (cleaning would drop them anyway)
        record.update(
            filters=["meshing_remove_unreferenced_vertices", "apply_coord_two_steps_smoothing"],
            parameters=params,
        )
        _apply(ms, "meshing_remove_unreferenced_vertices")
        _apply(ms, "apply_coord_two_steps_smoothing", **params)
        state.update(ms)
        return ""
    # MLS projection: cloud = mesh 0, normals, copy = mesh 1, current mesh 0, project
    # mesh 1 onto the surface of mesh 0.
    name = f"compute_mls_projection_{method}"
    params = {"filterscale": float(config.mls_filter_scale)}
    record.update(
        filters=["compute_normal_for_point_clouds", name],
        parameters={"k": int(k), **params},
    )
    _apply(ms, "compute_normal_for_point_clouds", k=int(k), smoothiter=0)
    _apply(ms, "generate_copy_of_current_mesh")
    ms.set_current_mesh(0)
    _apply(ms, name, controlmesh=0, proxymesh=1, **params)
    ms.set_current_mesh(1)
    projected = ms.current_mesh().vertex_matrix()
    if len(projected) != state.n:
        raise InputError(f"denoise: MLS projection returned {len(projected)} of {state.n} points")
    # the copy does not carry custom attributes, but keeps the vertex order
    bad = ~np.isfinite(projected).all(axis=1)
    projected[bad] = state.vertices[bad]
    record["not_projected"] = int(bad.sum())
    state.vertices = projected
    return ""


#: Taubin smoothing improved the F1 score of noisy meshes whose dihedral angles' lower
#: quartile was 10-10.7 degrees (normal noise of 25 % of the edge length) and lowered
#: it at 4.5-4.8 degrees (10 %); below this bound it runs with a warning. The other
#: methods lowered it in every measured case (docs/preprocessing.md) and always warn.
TAUBIN_HELPS_ANGLE = 8.0
#: A mesh looks clean when the lower quartile of its dihedral angles is at most this many
#: degrees. Measured (evaluation parts): clean remeshes and CAD tessellations 0-1.2, with
#: normal noise of 10 % of the edge length 4.5-4.8, 25 %: 10-11.
CLEAN_MESH_ANGLE = 2.0


def _clean_bound(state: _State) -> str:
    """The bound under which the input counts as clean, for messages."""
    from .robust import NOISE_QUIET

    return f"{CLEAN_MESH_ANGLE:g}" if state.is_mesh else f"{NOISE_QUIET:g}"


def _noise_level(state: _State) -> tuple[float, bool]:
    """The input's noise and whether it looks clean (denoising would only blur it).

    Meshes: the lower quartile of the dihedral angles, in degrees (the statistic robust
    mode's crease threshold uses), clean up to :data:`CLEAN_MESH_ANGLE`. Clouds: the
    lower median of robust mode's noise ratios (:func:`meshlab_sharp.robust.
    noise_ratios`), clean up to ``NOISE_QUIET`` (0 on clean samples, 0.07-0.13 on
    simulated scans, 0.1 with normal noise of 10 % of the spacing).
    """
    from .robust import NOISE_KNN, NOISE_QUIET, noise_ratios

    if state.is_mesh:
        from .creases import dihedral_angles

        assert state.faces is not None
        _, angles = dihedral_angles(state.vertices, state.faces)
        if len(angles) == 0:
            return 0.0, True
        quartile = float(np.degrees(np.quantile(angles, 0.25)))
        return quartile, quartile <= CLEAN_MESH_ANGLE
    from scipy.spatial import cKDTree

    k = min(NOISE_KNN, state.n)
    _, nearest = cKDTree(state.vertices).query(state.vertices, k)
    ratios = noise_ratios(state.vertices, nearest.reshape(state.n, k), k)
    median = float(np.partition(ratios, (state.n - 1) // 2)[(state.n - 1) // 2])
    return median, median <= NOISE_QUIET


def _fill_holes(state: _State, config: Preprocessing, record: dict[str, Any]) -> str:
    if not state.is_mesh:
        return "meshes only"
    assert state.faces is not None
    edges = np.sort(state.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    boundary = int((counts == 1).sum())
    record["boundary_edges_before"] = boundary
    if boundary == 0:
        return "no holes (no boundary edges)"
    mean_edge = float(np.linalg.norm(np.diff(state.vertices[unique], axis=1)[:, 0], axis=1).mean())
    diagonal = float(np.linalg.norm(np.ptp(state.vertices, axis=0)))
    max_size = config.max_hole_size
    if max_size is None:
        max_size = max(3, math.ceil(diagonal / mean_edge)) if mean_edge > 0 else 3
    params: dict[str, Any] = {"maxholesize": int(max_size), "refinehole": bool(config.refine_holes)}
    record.update(filters=["meshing_close_holes"], parameters=dict(params))
    if config.refine_holes:
        import pymeshlab

        params["refineholeedgelen"] = pymeshlab.PureValue(mean_edge)
        record["parameters"]["refineholeedgelen"] = mean_edge
    ms = state.meshset()
    _apply(ms, "meshing_close_holes", **params)
    state.update(ms)
    assert state.faces is not None
    edges = np.sort(state.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    record["boundary_edges_after"] = int((counts == 1).sum())
    record["added"] = int((state.to_input < 0).sum())
    return ""


def _simplify(state: _State, config: Preprocessing, record: dict[str, Any]) -> str:
    assert config.simplify is not None
    if config.simplify >= 1.0:
        return "simplify = 1 keeps every vertex"
    ms = state.meshset()
    if state.is_mesh:
        assert state.faces is not None
        target = round(config.simplify * len(state.faces))
        if target < _MIN_POINTS:
            raise InputError(f"simplify: {config.simplify} of {len(state.faces)} faces is too few")
        params: dict[str, Any] = {
            "targetfacenum": int(target),
            "optimalplacement": False,
            "preserveboundary": True,
            "preservenormal": True,
            "preservetopology": True,
        }
        record.update(filters=["meshing_decimation_quadric_edge_collapse"], parameters=params)
        _apply(ms, "meshing_decimation_quadric_edge_collapse", **params)
        state.update(ms)
        return ""
    target = round(config.simplify * state.n)
    if target < _MIN_POINTS:
        raise InputError(f"simplify: {config.simplify} of {state.n} points is too few")
    params = {"samplenum": int(target), "subsample": True, "exactnumflag": True}
    record.update(filters=["generate_sampling_poisson_disk"], parameters=params)
    _apply(ms, "generate_sampling_poisson_disk", **params)
    subset = ms.current_mesh().vertex_matrix()
    # a new layer without our tags, made of input points: find them by position
    from scipy.spatial import cKDTree

    dist, index = cKDTree(state.vertices).query(subset)
    if len(subset) == 0 or np.any(dist > 0.0):
        raise InputError("simplify: pymeshlab returned points that are not input points")
    state.vertices = state.vertices[index]
    state.to_input = state.to_input[index]
    return ""


_STEPS = {
    "remove_outliers": _remove_outliers,
    "denoise": _denoise,
    "fill_holes": _fill_holes,
    "simplify": _simplify,
}


def _apply(ms: pymeshlab.MeshSet, name: str, **params: Any) -> None:
    """Run one pymeshlab filter; its failures become InputError."""
    from .io import quiet_stdout

    try:
        with quiet_stdout():
            getattr(ms, name)(**params)
    except Exception as exc:  # pymeshlab's exception classes share no base but Exception
        lines = str(exc).strip().splitlines()
        detail = lines[-1].strip() if lines else type(exc).__name__
        raise InputError(f"preprocessing: pymeshlab filter {name} failed: {detail}") from None


def _check_number(
    name: str, value: Any, low: float, high: float, *, closed_high: bool = False
) -> None:
    """A real number in (low, high) (or (low, high] when ``closed_high``)."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise InputError(f"preprocessing: {name} must be a number, got {value!r}")
    v = float(value)
    inside = low < v and (v <= high if closed_high else v < high)
    if not (math.isfinite(v) and inside):
        bracket = "]" if closed_high else ")"
        raise InputError(
            f"preprocessing: {name} must be a finite number in ({low:g}, {high:g}{bracket}, "
            f"got {value!r}"
        )


def _check_int(name: str, value: Any, low: int, high: int | None = None) -> None:
    """An integer in low..high (a float with an integral value is refused: it is likely
    a slip)."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise InputError(f"preprocessing: {name} must be an integer, got {value!r}")
    if value < low:
        raise InputError(f"preprocessing: {name} must be >= {low}, got {value}")
    if high is not None and value > high:
        raise InputError(f"preprocessing: {name} must be <= {high}, got {value}")
