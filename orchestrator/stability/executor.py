"""One executor interface for many runs: local processes by default (one run per core), a Dask
distributed cluster when a scheduler address (or a Client/cluster) is given. dask-jobqueue's
SLURMCluster/PBSCluster are Dask clusters too: pass ``cluster.scheduler_address``.

``Executor.run(tasks)`` yields ``(index, result)`` as tasks finish. A task that raises never takes
the others down: its result is ``{"status": "failed", "error": ...}`` (see :func:`run_task`).
"""
from __future__ import annotations

import os
import traceback
from abc import ABC, abstractmethod
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Callable, Iterator
from ..case import load_case
from ..clock import run_engine_seconds
from ..runner import run_case
from .observables import observables
from ..registry import get_engine
from ..derive import derive


def run_task(task: dict) -> dict:
    """Run one case on one engine (picklable, top level: runs in a worker process or on a Dask
    worker). ``task``: ``case`` (path), ``overrides`` (nested dict), ``engine``, ``runs_root``,
    optional ``force`` and ``progress`` (a label: the run's progress lines under it, as a ladder
    run rung by rung shows them; default none). Returns the run's status, directory, wall time
    and observables; never raises."""
    import time
    t0 = time.perf_counter()
    try:
        case = load_case(task["case"], overrides=task.get("overrides") or None)
        out = run_case(case, task["engine"], runs_root=task["runs_root"], force=task.get("force", False),
                       progress=task.get("progress") or False, analyze=task.get("analyze", False))
        res = {"status": out.status, "run_dir": str(out.run_dir), "reused": out.reused,
               "engine_time": run_engine_seconds(out.run_dir, out.summary),
               "total_time": out.summary.get("wall_time", {}).get("total"),
               "unstable": out.summary.get("unstable"), "dt": out.summary.get("dt"),
               "dt_fraction": out.summary.get("dt_fraction")}
        if out.status == "complete":
            try:
                res["observables"] = observables(case, out.run_dir)
            except Exception as exc:                         # a run is not lost for a failed measure
                res["observables_error"] = f"{type(exc).__name__}: {exc}"
        return res
    except Exception as exc:
        return {"status": "failed", "error": f"{type(exc).__name__}: {exc}",
                "traceback": traceback.format_exc(limit=5), "total_time": time.perf_counter() - t0}


class Executor(ABC):
    """Runs independent tasks; yields (index, result) in completion order."""
    workers: int = 1

    @abstractmethod
    def run(self, fn: Callable, tasks: list) -> Iterator[tuple[int, object]]:
        ...

    def close(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class SerialExecutor(Executor):
    """In this process, one task after the other (debugging, and 1-worker baselines)."""
    workers = 1

    def run(self, fn, tasks):
        for k, t in enumerate(tasks):
            yield k, fn(t)


def warm_worker(case_path=None, engines=(), overrides=None) -> None:
    """Pay a worker process's one-off costs before its first run: the engines' version probes
    (a LIGGGHTS start-up is ~0.5 s) and the case's derivation (the restitution inversion is
    cached per process). Errors are left to the runs themselves."""
    try:
        for e in engines or ():
            eng = get_engine(e)
            if eng.available():
                eng.version()
        if case_path is not None:
            derive(load_case(case_path, overrides=overrides or None))
    except Exception:
        pass


def _noop():
    return None


class LocalExecutor(Executor):
    """A pool of local processes, one task per core by default."""

    def __init__(self, workers: int | None = None):
        self.workers = workers or os.cpu_count() or 1
        self.pool = None

    def start(self, case_path=None, engines=(), overrides=None) -> None:
        """Start the worker processes now (they warm up with :func:`warm_worker`) so that their
        start-up overlaps the caller's own work (a sweep plans its runs meanwhile)."""
        if self.workers == 1 or self.pool is not None:
            return
        import multiprocessing as mp
        import threading
        if threading.active_count() == 1:
            # a single-threaded caller (the CLI, a script): fork it, so the workers start with its
            # imports and caches (engine versions, restitution inversion) at no cost
            ctx = mp.get_context("fork")
        else:
            # threads in the caller (a notebook, a Dask client) make fork unsafe. forkserver: workers
            # fork from a clean server that has imported the runner once, instead of each spawned
            # worker importing numpy/scipy/h5py/pydantic again (seconds per short run)
            ctx = mp.get_context("forkserver")
            ctx.set_forkserver_preload(["orchestrator.runner", "orchestrator.stability.sweep"])
        self.pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx, initializer=warm_worker,
                                        initargs=(str(case_path) if case_path else None, tuple(engines or ()),
                                                  overrides))
        for _ in range(self.workers):                  # the pool spawns a worker per submit, up to max
            self.pool.submit(_noop)

    def run(self, fn, tasks):
        if self.workers == 1:
            yield from SerialExecutor().run(fn, tasks)
            return
        futs = {}
        for k, t in enumerate(tasks):                  # tasks may be a generator: submitted as they come
            if self.pool is None:                      # workers start (and warm up) with the first task
                self.start(t.get("case"), [t["engine"]] if t.get("engine") else (), t.get("overrides"))
            futs[self.pool.submit(fn, t)] = k
        for f in as_completed(futs):
            k = futs[f]
            try:
                yield k, f.result()
            except Exception as exc:                      # the worker itself died
                yield k, {"status": "failed", "error": f"worker: {type(exc).__name__}: {exc}"}

    def close(self):
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
            self.pool = None


class DaskExecutor(Executor):
    """A dask.distributed cluster: ``address`` ("tcp://host:8786"), a ``Client`` or a cluster
    object (LocalCluster, dask-jobqueue's SLURMCluster/PBSCluster)."""

    def __init__(self, address=None, client=None):
        from distributed import Client
        self._own = client is None
        if client is None:
            client = Client(address) if isinstance(address, str) else Client(address)
        self.client = client
        info = client.scheduler_info()
        self.workers = max(1, sum(w.get("nthreads", 1) for w in info.get("workers", {}).values()))

    def run(self, fn, tasks):
        from distributed import as_completed as das_completed
        futs = [self.client.submit(fn, t, pure=False, key=f"orch-{k}-{os.getpid()}-{id(tasks)}")
                for k, t in enumerate(tasks)]
        index = {f.key: k for k, f in enumerate(futs)}
        for f in das_completed(futs):
            k = index[f.key]
            try:
                yield k, f.result()
            except Exception as exc:
                yield k, {"status": "failed", "error": f"dask: {type(exc).__name__}: {exc}"}

    def close(self):
        if self._own:
            self.client.close()


def get_executor(scheduler=None, workers: int | None = None) -> Executor:
    """Dask when ``scheduler`` (address, Client or cluster) is given, else local processes."""
    if scheduler is None:
        return LocalExecutor(workers)
    from distributed import Client
    if isinstance(scheduler, Client):
        return DaskExecutor(client=scheduler)
    return DaskExecutor(address=scheduler)
