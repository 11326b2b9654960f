"""The tasks of a batch run and where they run (:class:`predisat.scheduler.TaskRunner`).

Two task functions, the same wherever they run (this process or the workers of a Dask
cluster): :func:`segment_task` segments a batch of frames into the cache, :func:`chunk_task`
reconstructs one chainage chunk and writes it atomically. :func:`run_segmentation` and
:func:`run_chunks` hand them to the runner and show a progress bar on stderr.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Iterable, Sequence
from typing import NoReturn

from tqdm import tqdm

from predisat.reconstruct.badframes import BadFrame
from predisat.reconstruct.carving import Reconstructor
from predisat.reconstruct.chunks import ChunkJob, reconstructor_for, run_chunk
from predisat.reconstruct.framecache import FrameJob
from predisat.reconstruct.frames import Segmenter, segment_frame
from predisat.scheduler import TaskRunner

__all__ = [
    "chunk_task",
    "run_chunks",
    "run_segmentation",
    "segment_task",
]

# One Reconstructor per worker thread, kept between its chunks: its camera rectifiers are
# built once. A memo only: a chunk's result does not depend on it (reconstructor_for checks
# the parameters).
_MEMO = threading.local()


def segment_task(segmenter: Segmenter, jobs: Sequence[FrameJob]) -> list[tuple[str, str | None]]:
    """Segment a batch of frames into the cache: ``(frame_id, problem or None)`` each."""
    return [segment_frame(j, segmenter) for j in jobs]


def chunk_task(_: None, job: ChunkJob) -> tuple[str, list[BadFrame]]:
    """Reconstruct one chunk and write it atomically: ``(name, bad frames it met)``."""
    rec: Reconstructor = reconstructor_for(job, getattr(_MEMO, "reconstructor", None))
    _MEMO.reconstructor = rec
    return run_chunk(job, rec)


def _progress(total: int, desc: str, enabled: bool) -> tqdm[NoReturn]:
    return tqdm(total=total, desc=desc, unit="frame" if "segment" in desc else "chunk",
                disable=not enabled or total == 0, file=sys.stderr)  # fmt: skip


def _batch_size(n_jobs: int, runner: TaskRunner) -> int:
    """Frames per segmentation task: one in this process (a fine progress bar), else a few
    (fewer, larger tasks), with at least 4 tasks per worker."""
    if not runner.parallel:
        return 1
    workers = max(runner.scheduler.workers, 4)  # an address: its size is not known here
    return max(1, min(16, n_jobs // (4 * workers)))


def run_segmentation(
    jobs: Sequence[FrameJob], runner: TaskRunner, segmenter: Segmenter, progress: bool
) -> Iterable[tuple[str, str | None]]:
    """Segment every job's frame; ``(frame_id, problem or None)`` as they finish."""
    bar = _progress(len(jobs), "segmenting frames", progress)
    try:
        size = _batch_size(len(jobs), runner)
        batches = [jobs[i : i + size] for i in range(0, len(jobs), size)]
        for res in runner.map_unordered(segment_task, segmenter, batches, "segment"):
            bar.update(len(res))
            yield from res
    finally:
        bar.close()


def run_chunks(jobs: Sequence[ChunkJob], runner: TaskRunner, progress: bool) -> None:
    """Reconstruct and write every chunk."""
    bar = _progress(len(jobs), "reconstructing chunks", progress)
    try:
        for _ in runner.map_unordered(chunk_task, None, jobs, "chunk"):
            bar.update(1)
    finally:
        bar.close()
