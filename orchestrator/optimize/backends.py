"""Where populations are evaluated: in-process, worker processes, or a Dask cluster.

A population is split into ``n`` contiguous chunks (``numpy.array_split``
order, so the split is reproducible); every chunk is ONE batched twin call
(:func:`.evaluate.evaluate_population`). Results are joined in order.

Identical individuals are evaluated once: :class:`CachedEvaluator` keeps every
evaluated individual (keyed by its gene values on the grid) and is saved in
the checkpoints, so a resumed run sees the same cache as an uninterrupted one.

Note: in a batched run the cutting component takes the same number of
substeps for all members (the largest any member needs), so a member's
figures may differ in the last digits with the batch it was evaluated in.
A run is reproducible for a given population size and worker count.
"""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from typing import Callable, Protocol

import numpy as np

from .context import ProblemContext
from .evaluate import Evaluation, evaluate_population


def _evaluate_chunk(ctx: ProblemContext, feeds: np.ndarray, spindles: np.ndarray) -> Evaluation:
    """Module-level (picklable) task: one batched twin call, in one thread (the workers share the cores)."""
    return evaluate_population(ctx, feeds, spindles, threads=1)


class Backend(Protocol):
    """Evaluates a population (B, L) → Evaluation."""

    def __call__(self, ctx: ProblemContext, feeds: np.ndarray, spindles: np.ndarray) -> Evaluation: ...

    def close(self) -> None: ...


def _split(n: int, parts: int) -> list[np.ndarray]:
    return [idx for idx in np.array_split(np.arange(n), max(1, min(parts, n))) if idx.size]


class SerialBackend:
    """The whole population in one batched twin call in this process."""

    def __call__(self, ctx: ProblemContext, feeds: np.ndarray, spindles: np.ndarray) -> Evaluation:
        return evaluate_population(ctx, feeds, spindles)

    def close(self) -> None:
        """Nothing to release."""


class ProcessBackend:
    """``workers`` processes (``concurrent.futures.ProcessPoolExecutor``), one batched chunk each.

    Parameters
    ----------
    workers : int
        Number of processes (and chunks).
    """

    def __init__(self, workers: int) -> None:
        self.workers = int(workers)
        self._pool: ProcessPoolExecutor | None = None

    def __call__(self, ctx: ProblemContext, feeds: np.ndarray, spindles: np.ndarray) -> Evaluation:
        chunks = _split(len(feeds), self.workers)
        if len(chunks) == 1:
            return evaluate_population(ctx, feeds, spindles)
        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers)
        futures = [self._pool.submit(_evaluate_chunk, ctx, feeds[idx], spindles[idx]) for idx in chunks]
        return Evaluation.concatenate([f.result() for f in futures])

    def close(self) -> None:
        """Shut the worker processes down."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


class DaskBackend:
    """The same chunked job on a Dask cluster (``dask.distributed.Client``).

    Parameters
    ----------
    address : str or Client
        Scheduler address (``tcp://host:8786``) or an existing client.
    chunks : int, optional
        Number of chunks; default: the cluster's total worker threads.
    """

    def __init__(self, address: object, chunks: int | None = None) -> None:
        try:
            from dask.distributed import Client
        except ImportError as exc:  # pragma: no cover - depends on the installation
            from .errors import OptimizeError

            raise OptimizeError('--dask needs dask.distributed: pip install "cnctwin[dask]"') from exc
        if isinstance(address, Client):
            self.client, self._own = address, False
        else:
            self.client, self._own = Client(address), True
        self.chunks = chunks

    def _n_chunks(self) -> int:
        if self.chunks:
            return int(self.chunks)
        info = self.client.scheduler_info()
        threads = sum(int(w.get("nthreads", 1)) for w in info.get("workers", {}).values())
        return max(1, threads)

    def __call__(self, ctx: ProblemContext, feeds: np.ndarray, spindles: np.ndarray) -> Evaluation:
        chunks = _split(len(feeds), self._n_chunks())
        remote_ctx = self.client.scatter(ctx, broadcast=True)
        futures = [self.client.submit(_evaluate_chunk, remote_ctx, feeds[idx], spindles[idx], pure=False)
                   for idx in chunks]
        return Evaluation.concatenate(self.client.gather(futures))

    def close(self) -> None:
        """Close the client when this backend opened it."""
        if self._own:
            self.client.close()


class CachedEvaluator:
    """Evaluates only individuals not seen before, through a backend.

    Parameters
    ----------
    ctx : ProblemContext
        The problem.
    backend : Backend
        Where the unseen individuals are evaluated.
    cache : dict, optional
        ``{gene tuple: member figures}`` from a checkpoint.
    """

    def __init__(self, ctx: ProblemContext, backend: Backend, cache: dict | None = None) -> None:
        self.ctx = ctx
        self.backend = backend
        self.cache: dict[tuple, Evaluation] = dict(cache or {})
        self.on_batch: Callable[[int], None] | None = None

    @property
    def evaluations(self) -> int:
        """Distinct individuals evaluated on the twin."""
        return len(self.cache)

    def __call__(self, feeds: np.ndarray, spindles: np.ndarray) -> Evaluation:
        feeds, spindles = self.ctx.snap(feeds, spindles)
        keys = [tuple(np.concatenate([f, s]).tolist()) for f, s in zip(feeds, spindles)]
        todo: list[int] = []
        seen: set[tuple] = set()
        for i, k in enumerate(keys):
            if k not in self.cache and k not in seen:
                todo.append(i)
                seen.add(k)
        if todo:
            if self.on_batch is not None:
                self.on_batch(len(todo))
            ev = self.backend(self.ctx, feeds[todo], spindles[todo])
            for j, i in enumerate(todo):
                self.cache[keys[i]] = ev.take([j])
        return Evaluation.concatenate([self.cache[k] for k in keys])
