"""Units of benchmark work run here, in local processes, or on a Dask cluster, with the same results.

A *unit* is what one call of a unit function does (one shard at one noise
level; one whole colon at one noise level). Each worker process loads the
methods once (one torch thread) and keeps them for every unit it runs; the
results come back as units finish, and the caller stores each at once, so a
killed run resumes where it stopped. Method *objects* (a class defined in a
notebook) run in this process: they need not be importable elsewhere.
"""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool

from colonbench.errors import ColonbenchError, InputError

#: The methods loaded in this worker process: ``{"methods": {name: method}, "key": (specs, options)}``.
WORKER: dict = {}


def _load(specs: list[str], options: dict, threads: int = 1) -> dict:
    """The methods of ``specs``, loaded once per process (and again only for other specs or options)."""
    from colonbench.benchmark.registry import load_method

    key = repr((specs, sorted(options.items())))
    if WORKER.get("key") != key:
        try:
            import torch

            torch.set_num_threads(threads)
        except ImportError:
            pass
        WORKER["methods"] = {m.name: m for m in (load_method(s, **options) for s in specs)}
        WORKER["key"] = key
    return WORKER["methods"]


def _init_worker(specs: list[str], options: dict, threads: int):
    _load(specs, options, threads)


def _pool_unit(fn, args: tuple):
    """One unit in a local worker process, with the methods its initializer loaded."""
    return fn(*args, methods=WORKER["methods"])


def _dask_unit(fn, specs: list[str], options: dict, args: tuple):
    """One unit on a Dask worker: the methods loaded once per worker process."""
    return fn(*args, methods=_load(specs, options))


def run_units(fn, units: list, args, loaded: dict, options: dict, workers: int = 1, scheduler=None):
    """Yield ``(unit, fn(*args(unit), methods=...))`` for every unit, as they finish.

    Parameters
    ----------
    fn : callable
        The unit function; it takes the methods as ``methods={name: method}``.
    units : list
    args : callable
        ``args(unit)``: the unit function's positional arguments.
    loaded : dict
        ``{name: (spec, method)}`` (:func:`colonbench.benchmark.evaluate.load_methods`).
    options : dict
        Options the methods are loaded with in other processes.
    workers : int
        Local processes (1: this process).
    scheduler : str or distributed.Client, optional
        A Dask scheduler address (``tcp://host:8786``) or client: the units run on its workers, which must
        see the data and run folders at the same paths and have colonbench installed.

    Raises
    ------
    ColonbenchError
        A worker died; what was finished has been yielded.
    """
    objects = [name for name, (spec, _) in loaded.items() if spec is None]
    if objects and (workers > 1 or scheduler is not None):
        workers, scheduler = 1, None  # a method given as an object runs where it was made
    if scheduler is None and (workers == 1 or len(units) <= 1):
        methods = {n: m for n, (_, m) in loaded.items()}
        for u in units:
            yield u, fn(*args(u), methods=methods)
        return
    specs = [spec for spec, _ in loaded.values()]
    if scheduler is not None:
        yield from _on_dask(fn, units, args, specs, options, scheduler)
        return
    ctx = multiprocessing.get_context("spawn")  # torch and HDF5 are not fork-safe
    with ProcessPoolExecutor(min(workers, len(units)), mp_context=ctx, initializer=_init_worker,
                             initargs=(specs, options, 1)) as pool:
        futures = {pool.submit(_pool_unit, fn, tuple(args(u))): u for u in units}
        try:
            for f in as_completed(futures):
                yield futures[f], f.result()
        except BrokenProcessPool:
            raise ColonbenchError("a worker process died (out of memory?); what was finished is kept, "
                                  "rerun the same command (with fewer --workers) to resume") from None


def _on_dask(fn, units, args, specs, options, scheduler):
    try:
        from distributed import Client, as_completed as dask_completed
    except ImportError as exc:
        raise InputError(f"--scheduler needs Dask: pip install 'colonbench[cluster]' (import failed: {exc})") from None
    client = Client(scheduler) if isinstance(scheduler, str) else scheduler
    try:
        futures = {client.submit(_dask_unit, fn, specs, options, tuple(args(u)), pure=False): k
                   for k, u in enumerate(units)}
        for f in dask_completed(list(futures)):
            yield units[futures[f]], f.result()
    finally:
        if isinstance(scheduler, str):
            client.close()
