"""Read-only arrays for the frozen records of both packages.

A frozen dataclass that holds numpy arrays is frozen only in name if its arrays are
writeable or are the caller's own: a write into a field (``records.col("health")[:] = 1``),
or a caller reusing the buffer it passed, would change a record that claims to be immutable,
and every result, cache or other record that shares it. The records therefore store their
arrays read-only, copied when the array given is writeable or a view of writeable memory;
an array that is already read-only all the way down is kept as it is, so that records built
from records cost no copy.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, DTypeLike, NDArray

__all__ = ["freeze_array_fields", "readonly_array"]


def _shares_writeable_memory(arr: NDArray[Any]) -> bool:
    base: object = arr
    while isinstance(base, np.ndarray):
        if base.flags.writeable:
            return True
        base = base.base
    return False


def readonly_array(values: ArrayLike, dtype: DTypeLike | None = None) -> NDArray[Any]:
    """``values`` as a read-only array that no writeable array shares.

    Parameters
    ----------
    values : array_like
        Any shape.
    dtype : data-type, optional
        The array's type (default: numpy's choice for ``values``).

    Returns
    -------
    ndarray
        ``values`` itself when it is already read-only down to its base (and of ``dtype``);
        otherwise a read-only copy. The caller's array is never changed, not even its flags.
    """
    arr = np.asarray(values, dtype=dtype)
    if not _shares_writeable_memory(arr):
        return arr
    fresh = arr.base is None and not (
        isinstance(values, np.ndarray) and np.may_share_memory(arr, values)
    )  # a conversion (a list, another dtype) that nobody else holds: no second copy
    if not fresh:
        arr = arr.copy()
    arr.setflags(write=False)
    return arr


def freeze_array_fields(record: object) -> None:
    """Make every numpy-array field of the frozen dataclass ``record`` read-only.

    Meant for a record's ``__post_init__``: each field holding an ndarray is replaced by
    :func:`readonly_array` of it (a copy only where the array is writeable).

    Parameters
    ----------
    record : dataclass instance
        A (frozen) dataclass; other fields are left as they are.
    """
    cls: Any = type(record)  # Any: mypy takes type[object] for unhashable
    for name in _field_names(cls):
        value = getattr(record, name, None)  # a field set later (init=False) is not there yet
        # the locator builds several records an epoch: the common cases without a call
        if isinstance(value, np.ndarray) and (value.flags.writeable or value.base is not None):
            if value.flags.writeable:
                value = value.copy()
                value.flags.writeable = False
            else:
                value = readonly_array(value)
            object.__setattr__(record, name, value)


@functools.cache
def _field_names(cls: type) -> tuple[str, ...]:
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"record must be a dataclass instance, got {cls.__name__}")
    return tuple(f.name for f in dataclasses.fields(cls))
