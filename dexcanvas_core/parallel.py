"""Running independent jobs on a local process pool or on Ray, results in the order they finish.

The one place the toolkit fans work out (``retarget batch``; the same engine serves any
picklable function): a ``concurrent.futures.ProcessPoolExecutor`` with the spawn start method
(no forked copies of Lance, MuJoCo or torch state; one process per core by default), or Ray
tasks (one CPU each) on an existing cluster (``auto``, ``HOST:PORT``) or on a private local Ray
(``local``: bound to 127.0.0.1, no dashboard, stopped at the end). A Ray already initialised by
the caller is used as it is and left running. No scheduling of its own: the pool or Ray decides.
"""

from __future__ import annotations

import multiprocessing
import os
import warnings
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

LOCAL_RAY = "local"
"""``ray_address`` value that starts a private local Ray."""


def map_unordered(
    fn: Callable[[Any], Any],
    jobs: Sequence[Any],
    *,
    workers: int | None = None,
    ray_address: str | None = None,
) -> Iterator[tuple[Any, Any, BaseException | None]]:
    """``(job, fn(job), None)`` for each job as it finishes, or ``(job, None, error)`` when its
    worker failed or died (``fn`` itself should turn its own errors into results).

    Args:
        fn: a module-level function (the workers import it by name).
        workers: local processes (default ``os.cpu_count()``); with ``ray_address="local"``
            the CPUs given to that Ray (default all).
        ray_address: ``None``: the local pool; ``"auto"`` or ``"HOST:PORT"``: that Ray
            cluster; ``"local"``: a private local Ray.

    >>> sorted(r for _, r, _ in map_unordered(abs, [-2, 1], workers=1))
    [1, 2]
    """
    if not jobs:
        return
    if ray_address is not None:
        yield from _ray(fn, jobs, workers, ray_address)
        return
    n = min(workers or os.cpu_count() or 1, len(jobs))
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=n, mp_context=ctx) as pool:
        futures = {pool.submit(fn, job): job for job in jobs}
        try:
            for fut in as_completed(futures):
                yield _outcome(fut.result, futures[fut])
        finally:
            for fut in futures:
                fut.cancel()


def _ray(fn, jobs, workers: int | None, address: str):
    import ray  # optional dependency (the ``distributed`` extra)

    started = not ray.is_initialized()
    with warnings.catch_warnings():
        # Ray starts its processes by fork + exec: nothing of Lance runs in the child
        warnings.filterwarnings("ignore", message="lance is not fork-safe")
        if started and address == LOCAL_RAY:
            ray.init(
                num_cpus=workers,
                include_dashboard=False,
                log_to_driver=False,
                _node_ip_address="127.0.0.1",
            )
        elif started:
            ray.init(address=address, log_to_driver=False)
    try:
        task = ray.remote(num_cpus=1, max_retries=0)(fn)
        refs = {task.remote(job): job for job in jobs}
        pending = list(refs)
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            ref = done[0]
            yield _outcome(lambda ref=ref: ray.get(ref), refs[ref])
    finally:
        if started:
            ray.shutdown()


def _outcome(get: Callable[[], Any], job):
    try:
        return job, get(), None
    except Exception as e:  # a lost worker fails its job, not the others
        return job, None, e
