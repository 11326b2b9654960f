"""Where the work of a batch run runs: this process, or a pool of worker processes.

:class:`WorkerPool` starts its spawned processes on first use and serves both stages (each
worker loads the package, the models and the numba caches once); :func:`run_segmentation`
and :func:`run_chunks` run the frame and chunk jobs serially (one worker) or in the pool, with
a progress bar on stderr.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from multiprocessing import get_context
from typing import Any, NoReturn, TypeVar

from tqdm import tqdm

from predisat.reconstruct.badframes import BadFrame
from predisat.reconstruct.carving import Reconstructor
from predisat.reconstruct.chunks import ChunkJob, reconstructor_for, run_chunk
from predisat.reconstruct.framecache import FrameJob
from predisat.reconstruct.frames import Segmenter, segment_frame

__all__ = [
    "WorkerPool",
    "run_chunks",
    "run_segmentation",
]

T = TypeVar("T")
R = TypeVar("R")

_WORKER: dict[str, Any] = {}  # per-process segmenter set by the pool initialiser



def _pool_init(segmenter: Segmenter) -> None:
    _WORKER["segmenter"] = segmenter



def _pool_segment(jobs: Sequence[FrameJob]) -> list[tuple[str, str | None]]:
    return [segment_frame(j, _WORKER["segmenter"]) for j in jobs]



def _pool_chunk(job: ChunkJob) -> tuple[str, list[BadFrame]]:
    # one Reconstructor per worker process: its camera rectifiers are reused across chunks
    rec = _WORKER["reconstructor"] = reconstructor_for(job, _WORKER.get("reconstructor"))
    return run_chunk(job, rec)



def _progress(total: int, desc: str, enabled: bool) -> tqdm[NoReturn]:
    return tqdm(total=total, desc=desc, unit="frame" if "segment" in desc else "chunk",
                disable=not enabled or total == 0, file=sys.stderr)  # fmt: skip



class WorkerPool:
    """The worker processes of a run, started on first use and shared by both stages.

    Before 2026-12-02 each stage started its own pool, so every worker imported the package,
    loaded the models and the numba caches twice (about a second per worker and stage).
    """

    def __init__(self, workers: int, segmenter: Segmenter) -> None:
        self.workers = workers
        self.segmenter = segmenter
        self._pool: ProcessPoolExecutor | None = None

    def get(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(
                self.workers, mp_context=get_context("spawn"), initializer=_pool_init,
                initargs=(self.segmenter,),
            )  # fmt: skip
        return self._pool

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[R]:
        """``fn`` of every item in the workers, results as they finish; on an error or Ctrl-C
        the queued items are dropped (finished chunks are already on disk)."""
        futures: set[Future[R]] = {self.get().submit(fn, it) for it in items}
        try:
            while futures:
                done, futures = wait(futures, return_when=FIRST_COMPLETED)
                for fut in done:
                    yield fut.result()
        except BaseException:
            for fut in futures:
                fut.cancel()
            raise

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None



def run_segmentation(
    jobs: Sequence[FrameJob], pool: WorkerPool, progress: bool
) -> Iterable[tuple[str, str | None]]:
    bar = _progress(len(jobs), "segmenting frames", progress)
    try:
        if pool.workers == 1 or len(jobs) < 4:
            for j in jobs:
                yield segment_frame(j, pool.segmenter)
                bar.update(1)
            return
        batch = max(1, min(16, len(jobs) // (4 * pool.workers)))
        batches = [jobs[i : i + batch] for i in range(0, len(jobs), batch)]
        for res in pool.map_unordered(_pool_segment, batches):
            bar.update(len(res))
            yield from res
    finally:
        bar.close()



def run_chunks(jobs: Sequence[ChunkJob], pool: WorkerPool, progress: bool) -> None:
    bar = _progress(len(jobs), "reconstructing chunks", progress)
    try:
        if pool.workers == 1 or len(jobs) < 2:
            rec: Reconstructor | None = None
            for j in jobs:
                rec = reconstructor_for(j, rec)
                run_chunk(j, rec)
                bar.update(1)
            return
        for _ in pool.map_unordered(_pool_chunk, jobs):
            bar.update(1)
    finally:
        bar.close()
