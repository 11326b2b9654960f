"""The fingerprint of the package's own source.

A development install changes code without changing ``predisat.__version__``; what keys a
result for reuse (a resume marker, the segmentation cache, a campaign job) therefore carries a
hash of the source, and a cluster's workers are checked to run the code of the command that
sends them tasks (:class:`predisat.scheduler.TaskRunner`'s ``code_version``).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from pathlib import Path

__all__ = ["code_fingerprint"]


def code_fingerprint(parts: Sequence[str] | None = None) -> str:
    """Hash of the package's own source, so results of changed code are never reused.

    A development install changes code without changing ``predisat.__version__``; the
    resume key and the segmentation cache therefore carry this fingerprint too.

    Parameters
    ----------
    parts : sequence of str, optional
        Files or folders relative to the package; default every ``.py`` file and the
        shipped models.

    Returns
    -------
    str
        16 hex digits of SHA-256 over the files' relative paths and contents.
    """
    root = Path(__file__).resolve().parent  # the predisat package
    if parts is None:
        files = sorted(root.rglob("*.py")) + sorted((root / "data" / "models").glob("*"))
    else:
        files = []
        for part in parts:
            q = root / part
            if not q.exists():
                raise FileNotFoundError(f"code_fingerprint: {q} is not part of the package")
            files += sorted(f for f in q.rglob("*") if f.is_file()) if q.is_dir() else [q]
    h = hashlib.sha256()
    for f in files:
        if f.is_file() and "__pycache__" not in f.parts:
            h.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes())
    return h.hexdigest()[:16]
