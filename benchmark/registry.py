"""Finding coverage-estimation methods by name: built-ins and users' methods alike.

A method is any object with

* ``name`` (str): its row in the tables;
* ``version`` (str, optional): recorded with every result (default ``"unversioned"``);
* ``estimate(points)``: ``points`` is one partial segment, ``(n, 3)`` float,
  mm, in the segment's own frame; it returns a
  :class:`colonbench.estimate.Estimate`, or a dict with at least
  ``coverage`` (fraction in [0, 1]), ``holes`` ((k, 3) mm) and
  ``centerline`` ((m, 3) mm), the ``colonbench estimate`` JSON contract;
* ``uses_truth = True`` (optional, references only): then it is called as
  ``estimate(points, truth=...)`` (:mod:`colonbench.benchmark.references`).

A method is named either by a module path, ``package.module:Class``, or by
the name of an entry point in the group ``colonbench.methods`` (a package
declares it in its ``pyproject.toml``; colonbench's own methods are
registered exactly so). A class is instantiated once per process with the
options it accepts among ``model`` and ``device``; an instance or a factory
function may be given instead of a class.
"""

from __future__ import annotations

import importlib
import inspect
from importlib.metadata import entry_points

import numpy as np

from colonbench.errors import InputError
from colonbench.estimate import Estimate

#: The entry-point group methods are registered in.
GROUP = "colonbench.methods"
#: What ``--methods all`` runs: the paper's method, its baselines and the reference rows.
DEFAULT_METHODS = ("completion", "thresholding", "unwrap", "unwrap-pca", "gt-heatmap", "unwrap-gt", "constant")


def available() -> dict[str, str]:
    """Registered methods: ``{name: "module:attr"}``."""
    return {ep.name: ep.value for ep in entry_points(group=GROUP)}


def _import(spec: str):
    module, _, attr = spec.partition(":")
    try:
        obj = importlib.import_module(module)
    except ImportError as exc:
        raise InputError(f"method {spec!r}: cannot import {module!r} ({exc})") from None
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise InputError(f"method {spec!r}: module {module!r} has no {attr!r}")
        obj = getattr(obj, part)
    return obj


def _instantiate(obj, options: dict):
    if not callable(obj) or (not inspect.isclass(obj) and hasattr(obj, "estimate")):
        return obj  # an instance
    try:
        params = inspect.signature(obj).parameters
    except (TypeError, ValueError):
        params = {}
    takes_any = any(p.kind is p.VAR_KEYWORD for p in params.values())
    kwargs = {k: v for k, v in options.items() if v is not None and (takes_any or k in params)}
    return obj(**kwargs)


def load_method(spec: str, **options):
    """A ready method from its registered name or ``module:attr``.

    Parameters
    ----------
    spec : str
        ``completion``, ``my_package.methods:MyMethod``, ...
    **options
        ``model``, ``device``: passed to the constructor if it takes them.

    Raises
    ------
    InputError
        Unknown name, import failure, or an object that is not a method.
    """
    spec = spec.strip()
    if ":" in spec:
        obj = _import(spec)
        default_name = spec.rpartition(":")[2].rpartition(".")[2]
    else:
        registered = available()
        if spec not in registered:
            raise InputError(f"unknown method {spec!r}; registered: {', '.join(sorted(registered)) or 'none'} "
                             "(or give package.module:Class)")
        obj = _import(registered[spec])
        default_name = spec
    method = _instantiate(obj, options)
    if not callable(getattr(method, "estimate", None)):
        raise InputError(f"method {spec!r}: {type(method).__name__} has no estimate(points) method")
    if not isinstance(getattr(method, "name", None), str) or not method.name:
        try:
            method.name = default_name
        except AttributeError:
            raise InputError(f"method {spec!r}: it has no name attribute") from None
    if not isinstance(getattr(method, "version", None), str):
        version = getattr(method, "version", None)
        try:
            method.version = "unversioned" if version is None else str(version)
        except AttributeError:
            pass
    return method


def _points(value, what: str, name: str) -> np.ndarray:
    try:
        a = np.asarray(value if value is not None else np.zeros((0, 3)), dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"method {name!r} returned {what} that are not numbers") from None
    if a.size == 0:
        return np.zeros((0, 3))
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(f"method {name!r} returned {what} of shape {a.shape}; expected (n, 3) mm")
    if not np.isfinite(a).all():
        raise InputError(f"method {name!r} returned {what} with NaN or infinite values")
    return a


def as_estimate(result, name: str) -> Estimate:
    """A method's return value checked and turned into an :class:`Estimate` (or an :class:`InputError`)."""
    if isinstance(result, Estimate):
        est = result
    elif isinstance(result, dict):
        if "coverage" not in result:
            raise InputError(f"method {name!r} returned a dict without 'coverage'")
        est = Estimate(result["coverage"], result.get("holes"), result.get("centerline"), name)
    else:
        raise InputError(f"method {name!r} returned {type(result).__name__}; expected an Estimate or a dict")
    try:
        coverage = float(est.coverage)
    except (TypeError, ValueError):
        raise InputError(f"method {name!r} returned coverage {est.coverage!r}, not a number") from None
    if not (np.isnan(coverage) or -1e-9 <= coverage <= 1 + 1e-9):
        raise InputError(f"method {name!r} returned coverage {coverage}; a fraction in [0, 1] is expected")
    est.coverage = coverage
    est.holes = _points(est.holes, "holes", name)
    est.centerline = _points(est.centerline, "centerline", name)
    est.method = name
    return est
