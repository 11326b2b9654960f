"""Atomic file writes: readers see the old file or the new one, never a part.

Every output of a batch run (frames, chunks, masks, reports) goes through here, so that an
interrupted run leaves only whole files behind and can resume.
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, nullcontext
from pathlib import Path

__all__ = [
    "LOCK_NAME",
    "STORAGE_ERRNOS",
    "FolderInUseError",
    "access_error_text",
    "atomic_path",
    "check_writable",
    "exclusive_folder",
    "published_name",
    "staged_folder",
    "storage_errno",
    "storage_error_text",
    "write_bytes_atomic",
]

LOCK_NAME = ".predisat.lock"


class FolderInUseError(OSError):
    """Another run is writing into the output folder; the message names it and the fix."""


@contextmanager
def exclusive_folder(folder: str | os.PathLike[str]) -> Iterator[None]:
    """Hold an exclusive advisory lock on an output folder while a run writes into it.

    A second run on the same folder is refused at once, naming the first (its process and
    start), instead of doing all the work again and racing the first on the same files (a
    user trial ran two at once without a word). The lock is ``flock`` on
    ``FOLDER/.predisat.lock``: released when the run ends or its process dies; on a network
    file system it may hold only between runs of one machine.

    Raises
    ------
    FolderInUseError
        Another process holds the lock.
    """
    import fcntl
    from datetime import UTC, datetime

    path = Path(folder) / LOCK_NAME
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.read(fd, 200).decode("utf-8", "replace").strip() or "another process"
        os.close(fd)
        raise FolderInUseError(
            f"{folder}: another run is writing there ({holder}); wait for it to end, or give "
            "another output folder"
        ) from None
    try:
        os.ftruncate(fd, 0)
        stamp = datetime.now(UTC).isoformat(timespec="seconds")
        os.write(fd, f"process {os.getpid()}, since {stamp}".encode())
        yield
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path beside ``path``, moved onto it when the block succeeds.

    The temporary name keeps the suffix of ``path`` (writers such as ``cv2.FileStorage`` or
    ``numpy.savez`` choose their format from it); on an exception it is removed and ``path`` is
    left as it was.
    """
    p = Path(path)
    if p.is_dir():
        raise IsADirectoryError(
            f"{p}: is a directory, not a file to write; give a file path such as "
            f"{p / ('output' + p.suffix)}"
        )
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.stem}.", suffix=p.suffix, dir=p.parent)
    os.close(fd)
    try:
        try:
            yield Path(tmp)
        except OSError as exc:
            # writers (pyarrow, numpy, a write to the temporary name) raise a full disk without
            # the published file's name, which the message must give (a user trial)
            number = storage_errno(exc)
            if exc.filename is None and number is not None:
                raise OSError(number, os.strerror(number), str(p)) from exc
            if str(exc.filename) == tmp:
                exc.filename = str(p)
            raise
        # mkstemp makes the file 0600; a published mask file must get the mode any new file
        # would get (others in the team read it).
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, p)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _umask() -> int:
    """The process umask, read without changing it where the system allows."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


STAGING_PREFIX = ".staging-"

STORAGE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS})
"""Errors of the storage, not of the data: a disk or quota full, the file-size limit, a
read-only file system. A batch run stops on them (a line of a network is not "failed")."""


@contextmanager
def staged_folder(
    folder: str | os.PathLike[str],
    *,
    last: Sequence[str] = (),
    remove: Sequence[str] = (),
    lock: bool = True,
) -> Iterator[Path]:
    """A hidden folder inside ``folder`` to write a run's outputs in, published when the block
    succeeds.

    Written in place, a full disk, a file-size limit or a kill left cut files that readers took
    as whole (a CSV with half its rows, a report without its end), or a folder mixing two runs
    (a user trial). Here every output is written before any earlier one is touched; then the
    files named in ``last`` (a run's marker, such as ``run.json``) are removed, the files
    matching the ``remove`` patterns too, and each staged file is renamed onto its namesake
    (renames within one file system write no data), ``last`` ones at the end. On an exception
    the folder is left as it was.

    Parameters
    ----------
    folder : path
        The output folder (created).
    last : sequence of str
        File names (relative to ``folder``) published last and withdrawn first.
    remove : sequence of str
        Glob patterns of earlier outputs to remove before publishing (a table written in
        another format).
    lock : bool
        Hold :func:`exclusive_folder` on ``folder`` meanwhile (False: the caller holds it). A
        killed run's staging folders are removed under it.

    Raises
    ------
    FolderInUseError
        Another run holds the folder.
    """
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    with exclusive_folder(root) if lock else nullcontext():
        for old in root.glob(STAGING_PREFIX + "*"):  # a killed run's
            shutil.rmtree(old, ignore_errors=True)
        stage = Path(tempfile.mkdtemp(prefix=STAGING_PREFIX, dir=root))
        try:
            yield stage
            _publish_staged(root, stage, last, remove)
        finally:
            shutil.rmtree(stage, ignore_errors=True)


def _publish_staged(root: Path, stage: Path, last: Sequence[str], remove: Sequence[str]) -> None:
    files = sorted(p for p in stage.rglob("*") if p.is_file())
    names = [p.relative_to(stage).as_posix() for p in files]
    for name in last:
        (root / name).unlink(missing_ok=True)
    for pattern in remove:
        for old_file in root.glob(pattern):
            if old_file.is_file():
                old_file.unlink()
    order = sorted(range(len(files)), key=lambda k: names[k] in last)
    mode = 0o666 & ~_umask()
    for k in order:
        dest = root / names[k]
        dest.parent.mkdir(parents=True, exist_ok=True)
        os.chmod(files[k], mode)
        os.replace(files[k], dest)


_ERRNO_IN_TEXT = re.compile(r"\[errno (\d+)\]", re.IGNORECASE)
_TEMP_NAME = re.compile(r"^\.(.+)\.[A-Za-z0-9_]{8}(\.[^./]*)?$")


def storage_errno(exc: BaseException) -> int | None:
    """The storage error number of ``exc`` (:data:`STORAGE_ERRNOS`), else None; pyarrow's
    errors carry it in their text only."""
    if not isinstance(exc, OSError):
        return None
    number = exc.errno
    if number is None:
        found = _ERRNO_IN_TEXT.search(str(exc))
        number = int(found.group(1)) if found else None
    return number if number in STORAGE_ERRNOS else None


def published_name(path: str | os.PathLike[str]) -> str:
    """The file a temporary path of :func:`atomic_path` or :func:`staged_folder` stands for."""
    parts = [p for p in Path(path).parts if not p.startswith(STAGING_PREFIX)]
    if not parts:
        return str(path)
    m = _TEMP_NAME.match(parts[-1])
    if m:
        parts[-1] = m.group(1) + (m.group(2) or "")
    return str(Path(*parts))


def storage_error_text(exc: BaseException) -> str | None:
    """One line for a person when ``exc`` is a storage error (:func:`storage_errno`): what
    filled up, the file being written, and the fix; None for any other error."""
    number = storage_errno(exc)
    if number is None:
        return None
    name = getattr(exc, "filename", None)
    where = f" (writing {published_name(name)})" if name else ""
    then = ("and rerun the same command (a command that resumes keeps the work it had "
            "finished)")  # fmt: skip
    if number == errno.EFBIG:
        return (f"a file grew past this shell's file-size limit{where}: raise it "
                f"(ulimit -f unlimited) {then}")  # fmt: skip
    if number == errno.EROFS:
        return f"the file system is read-only{where}: give an output folder on a writable one"
    what = "the disk quota is used up" if number == errno.EDQUOT else "no space left on the disk"
    return f"{what}{where}: free space there, or give another output folder, {then}"


def access_error_text(exc: BaseException) -> str | None:
    """One line for a person when ``exc`` is a permission error or a file where a folder is
    needed (or the reverse), naming the path meant and the fix; None for any other error
    (a user trial's were Python's raw ``[Errno 13]`` on a temporary name)."""
    name = getattr(exc, "filename", None)
    if not isinstance(exc, OSError) or not name:
        return None
    path = published_name(name)
    if isinstance(exc, PermissionError):
        return (f"{path}: permission denied; check its permissions and its folder's, or give "
                "another path")  # fmt: skip
    if isinstance(exc, (FileExistsError, NotADirectoryError, IsADirectoryError)):
        return (f"{path}: {exc.strerror or exc} (a file stands where a folder is needed, or the "
                "reverse); give another path, or move that one away")  # fmt: skip
    return None


def check_writable(folder: str | os.PathLike[str]) -> None:
    """Refuse, before any work, an output folder this process cannot write (created when
    missing): a run into a read-only folder computed every epoch and then failed.

    Raises
    ------
    OSError
        Naming the folder, the reason and the fix.
    """
    root = Path(folder)
    try:
        root.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(prefix=".predisat-probe-", dir=root):
            pass
    except OSError as exc:
        why = storage_error_text(exc) or exc.strerror or str(exc)
        raise OSError(
            f"{root}: cannot write there ({why}); give an output folder you can write"
        ) from None
