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

A method is named by

* the name of an entry point in the group ``colonbench.methods`` (a package
  declares it in its ``pyproject.toml``; colonbench's own methods are
  registered exactly so);
* a module path, ``package.module:Class``;
* ``exec:PROGRAM ARGS``: any program, called as ``colonbench estimate`` is
  (:class:`colonbench.benchmark.external.ExecMethod`);
* ``predictions:DIR``: a folder of prediction files
  (:class:`colonbench.benchmark.external.PredictionMethod`);

and ``NAME=SPEC`` gives any of them its row name. A class is instantiated once
per process with the options it accepts among ``model``, ``device`` and
``context_model``; an instance or a factory function may be given instead of a
class.
"""

from __future__ import annotations

import importlib
import inspect
from importlib.metadata import entry_points
from pathlib import Path


from colonbench.errors import InputError

#: The entry-point group methods are registered in.
GROUP = "colonbench.methods"
#: Options a method's class is offered (those it takes): the model file, the torch device, the in-context model
#: and the symmetries the network's prediction is averaged over.
CLASS_OPTIONS = ("model", "device", "context_model", "tta")
#: What ``--methods all`` runs: the paper's method, its baselines, the classical reference and the reference rows.
DEFAULT_METHODS = ("completion", "thresholding", "unwrap", "unwrap-pca", "poisson", "gt-heatmap", "unwrap-gt",
                   "constant")
#: The paper's baselines: a leaderboard compares every method with the best of them (paired, per segment).
BASELINES = ("thresholding", "unwrap", "unwrap-pca")


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
    named, given = _split_name(spec)
    if named is not None:
        method = load_method(given, **{**options, "name": named})
        return method
    if spec.startswith(("exec:", "predictions:")):
        return _external(spec, options)
    if ":" in spec:
        obj = _import(spec)
        default_name = spec.rpartition(":")[2].rpartition(".")[2]
    else:
        obj = _import(_registered(spec, options.get("name")))
        default_name = spec
    method = _instantiate(obj, {k: v for k, v in options.items() if k in CLASS_OPTIONS})
    if options.get("name"):
        try:
            method.name = options["name"]
        except AttributeError:
            raise InputError(f"method {spec!r}: it cannot be renamed {options['name']!r}") from None
    return as_method(method, default_name, spec)


def as_method(method, default_name: str | None = None, spec: str | None = None):
    """A method object checked (it has ``estimate``) and given a ``name`` and a ``version`` if it lacks them.

    Parameters
    ----------
    method : object
        Anything with ``estimate(points)`` (:class:`colonbench.estimate.Method`); a class is instantiated.
    default_name : str, optional
        Its name if it has none (default: its class name).
    spec : str, optional
        How it was named, for messages.

    Raises
    ------
    InputError
        It has no ``estimate`` method, or no name can be given to it.
    """
    if inspect.isclass(method):
        method = _instantiate(method, {})
    what = spec or type(method).__name__
    if not callable(getattr(method, "estimate", None)):
        raise InputError(f"method {what!r}: {type(method).__name__} has no estimate(points) method")
    if not isinstance(getattr(method, "name", None), str) or not method.name:
        try:
            method.name = default_name or type(method).__name__
        except AttributeError:
            raise InputError(f"method {what!r}: it has no name attribute") from None
    if not isinstance(getattr(method, "version", None), str):
        version = getattr(method, "version", None)
        try:
            method.version = "unversioned" if version is None else str(version)
        except AttributeError:
            pass
    return method


def _registered(spec: str, named: str | None = None) -> str:
    """The ``module:attr`` of a registered method's name.

    Raises
    ------
    InputError
        No method of that name: the message names the closest, or, for what looks like a program's command line
        (words, a script, a program on ``PATH``), the ``exec:`` spec it may have meant (with its ``named`` row name).
    """
    import shutil

    from colonbench.benchmark.external import SCRIPT_SUFFIXES
    from colonbench.errors import did_you_mean

    registered = available()
    if spec in registered:
        return registered[spec]
    first = spec.split()[0] if spec.split() else spec
    if len(spec.split()) > 1 or Path(first).suffix in SCRIPT_SUFFIXES or shutil.which(first):
        meant = ("" if named is None else f"{named}=") + f"exec:{spec}"
        raise InputError(f"unknown method {spec!r}; a program's command line is given as exec:PROGRAM ARGS: did you "
                         f"mean {meant}?")
    raise InputError(f"unknown method {spec!r}{did_you_mean(spec, registered)}; registered: "
                     f"{', '.join(sorted(registered)) or 'none'} (or give package.module:Class, or exec:PROGRAM ARGS)")


def check_spec(spec: str) -> None:
    """Refuse, before anything runs or is written, a method spec that cannot run: an unknown name
    (:func:`_registered`), a ``module:attr`` that cannot be imported, an ``exec:`` program or a script its command
    line names that is not there (:func:`colonbench.benchmark.external.check_command`), or a ``predictions:``
    folder that is not one. What a method does when it is made is checked when it is loaded.

    Raises
    ------
    InputError
    """
    named, given = _split_name(spec.strip())
    kind, colon, rest = given.partition(":")
    if not colon:
        _registered(given, named)
    elif kind not in ("exec", "predictions"):
        _import(given)
    elif kind == "exec":
        from colonbench.benchmark.external import check_command

        check_command(rest)
    elif kind == "predictions" and not Path(rest).expanduser().is_dir():
        raise InputError(f"predictions:{rest}: no such folder")


def _split_name(spec: str) -> tuple[str | None, str]:
    """``NAME=SPEC`` gives the method its row name; ``(None, spec)`` without one."""
    head, eq, rest = spec.partition("=")
    if eq and head and all(c.isalnum() or c in "._-" for c in head) and ":" not in head and " " not in head:
        return head, rest.strip()
    return None, spec


def _external(spec: str, options: dict):
    """``exec:PROGRAM ARGS`` or ``predictions:DIR`` (:mod:`colonbench.benchmark.external`)."""
    from colonbench.benchmark.external import ExecMethod, PredictionMethod

    kind, _, rest = spec.partition(":")
    if kind == "exec":
        extra = {k: options[k] for k in ("timeout", "batch") if options.get(k) is not None}
        return ExecMethod(rest, predictions=options.get("predictions"), name=options.get("name"), **extra)
    folder = Path(rest).expanduser()
    if not folder.is_dir():
        raise InputError(f"predictions:{rest}: no such folder")
    return PredictionMethod(folder, name=options.get("name") or folder.name)
