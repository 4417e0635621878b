"""numpy columns to Arrow arrays and tables without importing pandas.

``pyarrow.array`` and ``pyarrow.table`` ask on every call whether their input is a pandas
object, and the first question imports pandas: about a second of start-up (more on a loaded
machine) for a command that only writes a Parquet file of floats. Building arrays from their
buffers asks nothing; the result is the same Arrow data.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa

_TYPES = {np.dtype(np.float64): "float64", np.dtype(np.float32): "float32", np.dtype(np.int64): "int64",
          np.dtype(np.int32): "int32", np.dtype(np.int16): "int16", np.dtype(np.int8): "int8",
          np.dtype(np.uint8): "uint8", np.dtype(np.uint16): "uint16", np.dtype(np.uint32): "uint32"}


def numeric(values: npt.NDArray[Any]) -> Any:
    """A numeric Arrow array over ``values`` (1-D; native byte order; copied only if not contiguous)."""
    arr = np.ascontiguousarray(values)
    if arr.dtype == np.bool_:
        return pa.Array.from_buffers(pa.bool_(), arr.size, [None, pa.py_buffer(np.packbits(arr, bitorder="little"))])
    if not arr.dtype.isnative:
        arr = arr.astype(arr.dtype.newbyteorder("="))
    kind = _TYPES.get(arr.dtype)
    if kind is None:
        arr, kind = arr.astype(np.float64), "float64"
    return pa.Array.from_buffers(getattr(pa, kind)(), arr.size, [None, pa.py_buffer(arr)])


def strings(values: Sequence[str]) -> Any:
    """An Arrow string array of ``values``."""
    encoded = [v.encode() for v in values]
    offsets = np.zeros(len(encoded) + 1, np.int32)
    offsets[1:] = np.cumsum([len(e) for e in encoded], dtype=np.int64)
    return pa.Array.from_buffers(pa.string(), len(encoded), [None, pa.py_buffer(offsets),
                                                            pa.py_buffer(b"".join(encoded))])


def categories(index: npt.NDArray[np.int32], labels: Sequence[str]) -> Any:
    """A dictionary (categorical) Arrow array: ``labels[index[i]]`` for every row."""
    return pa.DictionaryArray.from_arrays(numeric(index.astype(np.int32)), strings(labels))


def table(columns: Mapping[str, Any]) -> Any:
    """An Arrow table from numpy columns (converted with :func:`numeric`) or ready Arrow arrays."""
    arrays = [numeric(c) if isinstance(c, np.ndarray) else c for c in columns.values()]
    return pa.Table.from_arrays(arrays, names=list(columns))
