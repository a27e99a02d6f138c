"""The paper's coverage estimation, end to end: partial points (mm) -> coverage, holes, centerline (mm).

:class:`CompletionMethod` is the one API for it: the ``estimate`` command, the benchmark harness and users'
scripts all call :meth:`CompletionMethod.estimate`. Steps and where they live:

1. grid from the partial points alone (:func:`colonbench.grid.fit_grid`) and the
   input heatmap (:func:`colonbench.heatmaps.input_from_points`), exactly as the
   training data were made;
2. the UNet predicts the target heatmap (:mod:`colonbench.completion.network`);
3. centerline (:mod:`colonbench.completion.heatmap_centerline`);
4. completed mesh, hole vertices and coverage (:mod:`colonbench.completion.surface`);
5. back to mm in the input's frame.

:meth:`CompletionMethod.from_heatmap` runs steps 3-5 on any target heatmap, e.g. the ground truth, which bounds
the error of everything after the network.
"""

from __future__ import annotations

import hashlib
import time
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from colonbench.completion import known_extent, novelty, screening
from colonbench.completion.gaps import GAP_VALLEY
from colonbench.completion.heatmap_centerline import END_LEVEL, extract_centerline
from colonbench.completion.calfile import load as load_intervals
from colonbench.completion.modelfile import DEFAULT_MODEL, model_path, shipped_model, shipped_models  # noqa: F401
from colonbench.completion.planes import line_between
from colonbench.completion.steps import STEPS_VERSION, complete, signals_of
from colonbench.completion.symmetry import averaged, check_tta
from colonbench.completion.surface import SHELL_LEVEL, cloud_density
from colonbench.errors import InputError
from colonbench.estimate import Estimate
from colonbench.grid import Grid, check_points, distinct_points, fit_grid, principal_axes
from colonbench.heatmaps import input_from_points
from colonbench.polyline import resample

#: Fewest points accepted: below this there is no segment to complete.
MIN_POINTS = 200
#: A cloud whose largest side is below this is taken to be in metres, mm.
METRES_BELOW_MM = 2.0
#: A cloud whose largest side is below this (and above :data:`METRES_BELOW_MM`) is smaller than any colon
#: segment: a lumen is 20-80 mm across, and the partial clouds of every suite span 30 mm or more. Centimetres, mm.
TINY_BELOW_MM = 10.0
#: A cloud whose largest side is above this is not one segment, mm.
MAX_SEGMENT_MM = 250.0
#: A cloud narrower than this across its second or third principal axis lies on a line or in a plane, mm
#: (a degenerate input, not a surface: refused rather than completed into a tube).
FLAT_BELOW_MM = 0.01
#: Spacing of the centerline returned, mm.
CENTERLINE_SPACING_MM = 0.5
#: A cloud denser than this (points/mm^2, :func:`colonbench.completion.surface.cloud_density`) is thinned to
#: :data:`THIN_TO` before the method runs: dense clouds came out overestimated (docs/method.md, step 0).
THIN_ABOVE = 3.0
#: The density a dense cloud is thinned to, points/mm^2: the paper's (and the held-out data's).
THIN_TO = 2.0


def check_cloud(points, what: str = "point cloud") -> np.ndarray:
    """A partial segment cloud in mm, or an :class:`InputError` saying what is wrong with it.

    Returns
    -------
    (m, 3) float
        The cloud's distinct points in lexicographic order (:func:`colonbench.grid.distinct_points`): every
        method sees the set of points, whatever their order and however often a point was repeated.
    """
    pts = check_points(points, what, min_points=0)
    given = len(pts)
    pts = distinct_points(pts)
    if given > 1 and len(pts) == 1:
        raise InputError(f"{what}: all {given} points coincide; a partial colon segment is a surface")
    if len(pts) < MIN_POINTS:
        repeats = f" once repeated points are dropped ({given} given)" if given > len(pts) else ""
        raise InputError(f"{what}: only {len(pts)} point(s){repeats}; a partial colon segment needs at least "
                         f"{MIN_POINTS} (colonbench's clouds have about 2 points per mm^2)")
    # extents along the principal axes (by variance, largest first): on a line the 2nd is 0, in a plane the 3rd
    spans = np.ptp((pts - pts.mean(axis=0)) @ principal_axes(pts).T, axis=0)
    extent = float(spans.max())
    if extent < METRES_BELOW_MM:
        raise InputError(f"{what}: spans only {extent:.3g} units; colonbench works in millimetres, and this looks "
                         "like metres (multiply by 1000)")
    if extent < TINY_BELOW_MM:
        raise InputError(f"{what}: spans only {extent:.3g} mm, smaller than any colon segment (a lumen alone is "
                         "20-80 mm across); colonbench works in millimetres, and this looks like centimetres "
                         "(multiply by 10)")
    if extent > MAX_SEGMENT_MM:
        raise InputError(f"{what}: spans {extent:.0f} mm, far more than one colon segment (5-7 cm); cut the "
                         "reconstruction into segments along its centerline first")
    # a wall seen from inside a lumen of 10 mm radius or more is never a line, nor exactly flat
    if spans[1] < FLAT_BELOW_MM:
        raise InputError(f"{what}: its points lie on a line ({spans[1]:.2g} mm across it); a partial colon segment "
                         "is a surface")
    if spans[2] < FLAT_BELOW_MM:
        raise InputError(f"{what}: its points lie in one plane ({spans[2]:.2g} mm out of it); a partial colon "
                         "segment is a surface around a lumen")
    return pts


def thin_dense(points: np.ndarray, above: float | None = THIN_ABOVE, to: float = THIN_TO) -> np.ndarray:
    """A cloud denser than ``above`` points/mm^2, thinned at random to ``to``; any other cloud as it is.

    The kept points are a uniform draw without replacement of ``n * to / rho`` of the ``n`` points
    (``rho`` the measured density), so every point is kept with the same probability and the thinned
    cloud samples the surface as a sparser scan would (a Poisson sampling stays one). The draw is
    seeded by the cloud's bytes: the same cloud always gives the same points. At least
    :data:`MIN_POINTS` points are kept.

    Parameters
    ----------
    points : (n, 3) float
        A checked partial cloud (:func:`check_cloud`: its distinct points in lexicographic order, so that the
        draw does not depend on the order the points came in, nor on repeated points), mm.
    above : float or None
        Density (points/mm^2, :func:`colonbench.completion.surface.cloud_density`) above which the cloud is
        thinned; None thins nothing.
    to : float
        Density of the thinned cloud, points/mm^2.

    Returns
    -------
    (m, 3) float
        The kept points, in their order.
    """
    if above is None:
        return points
    rho = cloud_density(points)
    if not rho > above:
        return points
    from colonbench import seeding

    keep = max(MIN_POINTS, int(round(len(points) * to / rho)))
    if keep >= len(points):
        return points
    digest = int.from_bytes(hashlib.sha256(np.ascontiguousarray(points).tobytes()).digest()[:4], "little")
    chosen = seeding.rng(0, "thin", digest).choice(len(points), keep, replace=False)
    return points[np.sort(chosen)]


def method_cloud(points, thin_above: float | None = THIN_ABOVE) -> np.ndarray:
    """The cloud the completion method runs on: :func:`check_cloud`, then :func:`thin_dense`."""
    return thin_dense(check_cloud(points), thin_above)


@dataclass
class Prediction:
    """The network's view of one partial cloud, shared by every method built on it.

    Attributes
    ----------
    grid : Grid
        Fitted on the partial points alone.
    input : (S, S, S) float32
        Input heatmap.
    heatmap : (S, S, S) float32
        Predicted target heatmap, clipped to [0, 1].
    seconds : dict
        Wall time of the steps computed so far (``network``, ``centerline``), s.
    """

    grid: Grid
    input: np.ndarray
    heatmap: np.ndarray
    seconds: dict
    _centerline: np.ndarray | None = None
    _rerun: tuple | None = None              # (network, input, whether heatmap is its single pass): for spread
    _spread: float | None = None

    @property
    def spread(self) -> float:
        """The network's disagreement with itself on this cloud (:func:`colonbench.completion.novelty.spread`;
        one more network pass, on first use)."""
        if self._spread is None:
            forward, x, single = self._rerun
            self._spread = novelty.spread(forward, x, self.heatmap if single else None)
        return self._spread

    @property
    def centerline_vox(self) -> np.ndarray:
        """(m, 3) float centerline of the predicted heatmap, voxels (extracted once, on first use)."""
        if self._centerline is None:
            t = time.perf_counter()
            self._centerline = extract_centerline(self.heatmap)
            self.seconds["centerline"] = time.perf_counter() - t
        return self._centerline


class Predictor:
    """A loaded model and a small cache of its predictions, keyed by the cloud's bytes.

    The benchmark runs several methods on the same cloud (the full method,
    thresholding, unwrapping around the learned centerline); they share one
    :class:`Predictor` (:func:`shared_predictor`), so the UNet and the
    centerline run once per cloud.

    Parameters
    ----------
    model : path, optional
        A ``.safetensors`` model from ``colonbench train`` (an earlier shipped model's file, CHANGELOG.md), or
        ``small``, the shipped model (the default).
    device : str
        ``cpu``, ``cuda``, ``auto``.
    tta : int
        Average the prediction over this many symmetries of the grid (:mod:`colonbench.completion.symmetry`);
        1, the default, runs the network once.
    """

    CACHE = 4

    def __init__(self, model=None, device: str = "cpu", tta: int = 1):
        from colonbench.completion.network import load_model, resolve_device

        self.tta = check_tta(tta)

        path = model_path(model)
        if not path.is_file():
            raise InputError("no model ships with this installation; train one (colonbench train) and pass it"
                             if model is None else f"{path}: no such model file (shipped models: "
                             f"{', '.join(shipped_models()) or 'none'})")
        self.device = resolve_device(device)
        self.net, self.config, self.meta = load_model(path, self.device)
        self._forward: dict = {}     # grid size -> the network made fast for inputs of that size
        self.path = path
        self.pool = screening.pool_of(self.meta)        # a screening model runs on the grid pooled (0326)
        self.version = f"{path.stem}@{self.meta.get('steps', '?')}" + (f",tta={self.tta}" if self.tta > 1 else "") \
            + (f",pool={self.pool}" if self.pool > 1 else "")
        self.grid_options = self.meta.get("grid_options", {})
        self._cache: OrderedDict[bytes, Prediction] = OrderedDict()

    @property
    def in_context(self) -> bool:
        """Whether the model is an in-context model (a second input channel: the segment's slab)."""
        return self.config.in_channels > 1

    def __call__(self, points, slab=None) -> Prediction:
        """The :class:`Prediction` of a checked partial cloud (mm); cached.

        ``slab`` (:class:`colonbench.slab.Slab`): the segment's stretch of centerline, which an in-context
        model needs (its grid and second input channel); a segment model does without it.
        """
        pts = np.ascontiguousarray(points, dtype=float)
        if not self.in_context:
            slab = None
        elif slab is None:
            raise InputError(f"{self.path.name} is an in-context model: it needs the segment's stretch of "
                             "centerline and its planes, which colonbench map gives it (--context-mm); estimate "
                             "single segments with a segment model (the default)")
        key = hashlib.sha1(pts.tobytes() + (slab.key() if slab is not None else b"")).digest() \
            + str(pts.shape).encode()
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        import torch

        t = time.perf_counter()
        if slab is None:
            grid = fit_grid(pts, **self.grid_options)
            h_in, _ = input_from_points(grid, pts)
            x_np = (h_in if self.pool == 1 else screening.pooled_input(grid, pts, self.pool))[None, None]
        else:
            from colonbench.slab import context_grid, slab_occupancy

            grid = context_grid(pts, slab, **self.grid_options)
            h_in, _ = input_from_points(grid, pts)
            x_np = np.stack([h_in, slab_occupancy(grid, slab).astype(np.float32)])[None]
        # every cloud runs the network made fast for inference (set up once per grid size, about 1 s): its sums
        # differ from the eager network's in the last bits, which the steps after it can turn into a whole vertex
        # or voxel, so a cloud's estimate must not depend on whether it came first in its process
        size = x_np.shape[-1]
        if size not in self._forward:
            from colonbench.completion.network import for_inference

            self._forward[size] = for_inference(self.net, size, self.device)
        with torch.inference_mode():
            x = torch.from_numpy(x_np).to(self.device)
            pred = averaged(self._forward.get(size, self.net), x, self.tta)
            pred = screening.upsampled(pred, self.pool, grid.size)[0, 0].float().cpu().numpy()
        out = Prediction(grid, h_in, np.clip(pred, 0.0, 1.0), {"network": time.perf_counter() - t},
                         _rerun=(self._forward.get(size, self.net), x, self.pool == 1 and self.tta == 1))
        self._cache[key] = out
        while len(self._cache) > self.CACHE:
            self._cache.popitem(last=False)
        return out


_PREDICTORS: dict = {}


def shared_predictor(model=None, device: str = "cpu", tta: int = 1) -> Predictor:
    """The process's one :class:`Predictor` for ``(model, device, tta)``: loaded once, shared by methods."""
    key = (str(Path(model).resolve()) if model is not None else None, str(device), check_tta(tta))
    if key not in _PREDICTORS:
        _PREDICTORS[key] = Predictor(model, device, key[2])
    return _PREDICTORS[key]


def on_prediction(predictor: Predictor, points, step: str, fn) -> Estimate:
    """A method built on the shared prediction: ``fn(points, prediction)`` timed as ``step``.

    The cloud is checked, the (cached) prediction and its centerline are taken from ``predictor``, and the
    result's ``seconds`` count those shared steps in full, then ``step``. The prediction is made on the
    completion method's own cloud (:func:`method_cloud`: a dense cloud thinned), so that the methods built on the
    network share its prediction and its line on every cloud; ``fn`` gets the checked cloud (not thinned).

    Parameters
    ----------
    predictor : Predictor
    points : (n, 3) float
        Partial cloud, mm.
    step : str
        Name of the method's own step in ``seconds``.
    fn : callable
        ``fn(points, prediction) -> Estimate``; ``prediction.centerline_vox`` is ready.
    """
    pts = check_cloud(points)
    p = predictor(thin_dense(pts))
    p.centerline_vox  # noqa: B018 - extracted (and timed) before the method's own step
    t = time.perf_counter()
    est = fn(pts, p)
    est.seconds = {**p.seconds, step: time.perf_counter() - t}
    return est


class CompletionMethod:
    """The learned completion method of the paper.

    Parameters
    ----------
    model : path, optional
        A ``.safetensors`` model from ``colonbench train`` (an earlier shipped model's file, CHANGELOG.md), or
        ``small``, the shipped model (the default).
    device : str
        ``cpu``, ``cuda``, ``auto``.
    hole_distance : float, optional
        Vertices farther than this from the partial cloud are holes, voxels (default: the paper's sqrt(2)/2).
    cut_rims : bool
        Clip the mesh at the cloud's cut rims where found (docs/method.md step 5).
    shell_level : float or None
        Drop the mesh's faces where the predicted heatmap is above this (docs/method.md step 4);
        None keeps them, as the steps did before their version 4.
    gaps : bool
        Add hole patches where the completed tube has no wall (docs/method.md step 6); off: as before steps 5.
    end_level : float or None
        The centerline's ends move to the far ends of the predicted heatmap's voxels at or above this
        (docs/method.md step 3, from steps version 6); None keeps the ends of its ridge.
    thin_above : float or None
        A cloud denser than this (points/mm^2) is thinned to :data:`THIN_TO` first (:func:`thin_dense`,
        docs/method.md step 0, from steps version 9); None takes every cloud as it is.
    context_model : path, optional
        An in-context model (``colonbench train`` on a context pack, docs/mapping.md): it estimates the
        segments given with their slab (``colonbench map`` with a context margin); ``model`` estimates the rest.
    tta : int
        Average the network's heatmap over this many symmetries of the grid (1, 2, 4, 8 or 16;
        :mod:`colonbench.completion.symmetry`); 1, the default, runs it once.

    The model is loaded once (and shared with the other methods built on the same model in this process);
    call :meth:`estimate` on as many clouds as needed.
    """

    name = "completion"

    def __init__(self, model=None, device: str = "cpu", hole_distance: float | None = None, cut_rims: bool = True,
                 shell_level: float | None = SHELL_LEVEL, gaps: bool = True, end_level: float | None = END_LEVEL,
                 thin_above: float | None = THIN_ABOVE, context_model=None, tta: int = 1):
        self.predictor = shared_predictor(model, device, tta)
        self.context_predictor = shared_predictor(context_model, device, tta) if context_model is not None else None
        if self.context_predictor is not None and not self.context_predictor.in_context:
            raise InputError(f"--context-model {context_model}: a segment model (one input channel), not an "
                             "in-context model (colonbench train on a context pack, docs/mapping.md)")
        self.hole_distance = hole_distance
        self.cut_rims = cut_rims
        self.shell_level = shell_level
        self.gaps = gaps
        self.end_level = end_level
        self.thin_above = thin_above
        self.version = f"{self.predictor.version},{steps_version(shell_level, gaps, end_level, thin_above)}" + (
            f",context={self.context_predictor.version}" if self.context_predictor is not None else "")
        self.intervals = load_intervals(self.predictor.path, steps_version(shell_level, gaps, end_level, thin_above)
                                        if self.context_predictor is None else "context")
        self.version += f",intervals={self.intervals.source['id']}" if self.intervals is not None else ""
        used = set() if self.intervals is None else {
            f for g in [*self.intervals.groups.values(), self.intervals.known, self.intervals.review_odds,
                        self.intervals.like] for f in g.get("features", ())}
        # the signals that cost a network pass (spread) or a search (hole depth, wall misfit): only where used
        self.spread, self.hole_depth, self.misfit = "spread" in used, "depth" in used, "misfit" in used
        self.meta = self.predictor.meta

    def predict(self, points) -> tuple[Grid, np.ndarray, np.ndarray]:
        """Grid, input heatmap and predicted target heatmap of a partial cloud (mm)."""
        p = self.predictor(method_cloud(points, self.thin_above))
        return p.grid, p.input, p.heatmap

    @property
    def takes_slab(self) -> bool:
        """Whether :meth:`estimate` uses a segment's slab when given one (an in-context model)."""
        return self.predictor.in_context or self.context_predictor is not None

    @property
    def needs_slab(self) -> bool:
        """Whether :meth:`estimate` needs a slab for every segment (its model is an in-context model)."""
        return self.predictor.in_context

    def estimate(self, points, slab=None, length_mm: float | None = None) -> Estimate:
        """Coverage, holes and centerline of one partial segment (points in mm).

        ``slab`` (:class:`colonbench.slab.Slab`): the segment's stretch of the map's centerline. Given one,
        the in-context model estimates (``context_model``, or ``model`` when that is one); a segment model
        ignores it. ``length_mm``: the segment's arc length where known (``known_extent.known_length``).
        """
        t0 = time.perf_counter()
        pts = method_cloud(points, self.thin_above)
        t1 = time.perf_counter()
        predictor = self.context_predictor if slab is not None and self.context_predictor is not None \
            else self.predictor
        p = predictor(pts, slab)
        if self.end_level == END_LEVEL:
            cl = p.centerline_vox        # shared with the other methods on this prediction
            shared = p.seconds
        else:                            # its own line; the shared prediction's timings are left as they are
            t = time.perf_counter()
            cl = extract_centerline(p.heatmap, end_level=self.end_level)
            shared = {**p.seconds, "centerline": time.perf_counter() - t}
        est = from_heatmap(p.heatmap, p.grid, pts, self.name, self.hole_distance, centerline_vox=cl,
                           cut_rims=self.cut_rims, shell_level=self.shell_level, gaps=self.gaps)
        est.seconds = {"check": t1 - t0, **shared, **{k: v for k, v in est.seconds.items() if k != "centerline"}}
        t = time.perf_counter()
        est.signals.update(novelty.signals(pts, est.centerline, est.holes, p if self.spread else None, self.hole_depth,
                                           est.mesh_vertices if self.misfit else None))
        est.seconds["novelty"] = time.perf_counter() - t
        if length_mm is not None:
            known_extent.known_length(est, length_mm)
        if self.intervals is not None:
            self.intervals.apply(est)
        return est


def prediction_version(predictor: Predictor) -> str:
    """Version of the prediction the methods built on the network share: the model, the steps around it (the
    cloud it is made from, the planes the baselines clip at) and the density above which a cloud is thinned
    before it (:func:`on_prediction`)."""
    return f"{predictor.version},steps={STEPS_VERSION},thin_above={THIN_ABOVE:g}"


def steps_version(shell_level: float | None = SHELL_LEVEL, gaps: bool = True,
                  end_level: float | None = END_LEVEL, thin_above: float | None = THIN_ABOVE) -> str:
    """``steps=N`` of the steps around the network (:data:`~colonbench.completion.steps.STEPS_VERSION`),
    with the shell level, the wall gaps, the centerline's end level and the thinning density where they are
    not the default: part of the methods' versions in run folders."""
    return (f"steps={STEPS_VERSION}" + ("" if shell_level == SHELL_LEVEL else f",shell_level={shell_level}")
            + ("" if gaps else ",gaps=off") + ("" if end_level == END_LEVEL else f",end_level={end_level}")
            + ("" if thin_above == THIN_ABOVE else f",thin_above={thin_above}"))


def from_heatmap(heatmap: np.ndarray, grid: Grid, points, method: str = "completion",
                 hole_distance: float | None = None, centerline_vox: np.ndarray | None = None,
                 cut_rims: bool = True, shell_level: float | None = SHELL_LEVEL, gaps: bool = True,
                 valley: float = GAP_VALLEY) -> Estimate:
    """Steps after the network: centerline, completed mesh, holes and coverage of a target heatmap.

    Parameters
    ----------
    heatmap : (S, S, S) float
        A target heatmap (predicted, or the ground truth) on ``grid``.
    grid : Grid
    points : (n, 3) float
        The partial cloud, mm.
    centerline_vox : (m, 3) float, optional
        Its centerline in voxels, if already extracted.
    cut_rims : bool
        Clip the mesh at the cloud's cut rims where found (docs/method.md step 5); off where the caller knows them.
    shell_level : float or None
        :func:`colonbench.completion.surface.clip_to_shell`'s level; None keeps every face.
    gaps : bool
        Add hole patches where the tube has no wall (:func:`colonbench.completion.gaps.wall_gaps`) ...
    valley : float
        ... along rays where the heatmap falls below this (:func:`colonbench.completion.steps.complete`).
    """
    t0 = time.perf_counter()
    cl_vox = extract_centerline(heatmap) if centerline_vox is None else centerline_vox
    t1 = time.perf_counter()
    pts = np.asarray(points, dtype=float)
    comp = complete(heatmap, cl_vox, grid.to_voxel(pts), hole_distance, cut_rims, shell_level, gaps, valley,
                    voxel_mm=grid.voxel_size)
    t2 = time.perf_counter()
    verts = grid.to_mm(comp.vertices) if len(comp.vertices) else np.zeros((0, 3))
    inside = line_between(cl_vox, comp.planes)
    cl = resample(grid.to_mm(inside), CENTERLINE_SPACING_MM) if len(inside) else np.zeros((0, 3))
    signals = signals_of(comp, cl, inside, grid.voxel_size, cut_rims)
    return Estimate(coverage=comp.coverage, holes=verts[comp.hole], centerline=cl, method=method,
                    mesh_vertices=verts, mesh_faces=comp.faces, hole_vertices=comp.hole,
                    seconds={"centerline": t1 - t0, "mesh_holes": t2 - t1}, signals=signals)
