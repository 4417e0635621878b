"""numpy -> Arrow without pandas: the same data as pyarrow's own conversion, and pandas stays unimported."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pyarrow as pa
import pytest

from app.ingest import arrow
from tests.conftest import REPO


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int64, np.int32, np.int16, np.int8, np.uint8,
                                   np.uint16, np.uint32, ">i4", np.bool_])
def test_numeric_equals_pyarrow_conversion(dtype: str) -> None:
    values = (np.arange(-5, 12) % 3 == 0) if dtype is np.bool_ else np.arange(-5, 12)[::2].astype(dtype)
    got = arrow.numeric(values)
    assert got.equals(pa.array(values.astype(values.dtype.newbyteorder("="))))
    assert got.to_pylist() == values.tolist()


def test_strings_categories_and_table() -> None:
    labels = ["motor_speed_rpm", "", "Drehmoment Ä"]
    assert arrow.strings(labels).equals(pa.array(labels, pa.string()))
    cats = arrow.categories(np.array([2, 0, 0, 1], np.int32), labels)
    assert cats.to_pylist() == ["Drehmoment Ä", "motor_speed_rpm", "motor_speed_rpm", ""]
    t = arrow.table({"t_s": np.array([0.5, 1.0, 1.5, 2.0]), "channel": cats})
    assert t.column_names == ["t_s", "channel"] and t.column("t_s").to_pylist() == [0.5, 1.0, 1.5, 2.0]


def test_writing_parquet_does_not_import_pandas(tmp_path: object) -> None:
    code = (
        "import sys, numpy as np, pyarrow.parquet as pq\n"
        "from app.ingest import arrow\n"
        "t = arrow.table({'a': np.arange(4.0), 'c': arrow.categories(np.zeros(4, np.int32), ['x'])})\n"
        f"pq.write_table(t, {str(tmp_path)!r} + '/x.parquet')\n"
        "print('pandas' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
