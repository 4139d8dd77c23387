"""Read a saved view (.rrd) back with rerun's own reader, for checks and tests.

Rule: nothing here knows how the view was drawn beyond the entity paths and
rerun's component columns: `read_rrd` returns, per entity, the rows in event
order as {"event": sequence or None, "session_time": ns, component column: value}, decoded by
rerun's RrdReader into plain Python; `tensor` and `segmentation` rebuild numpy
arrays from a Tensor or SegmentationImage cell. A file that rerun cannot read
raises ValueError with rerun's reason.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
import pyarrow as pa
from rerun.chunk import RrdReader

_CONTROL_COLUMNS = {"rerun.controls.RowId", "log_time"}


def read_rrd(path: str | Path) -> dict[str, list[dict]]:
    """Every logged row of the first recording in the file, by entity path."""
    try:
        chunks = list(RrdReader(path).stream())
    except Exception as err:  # rerun raises its own error types; say which file
        raise ValueError(f"{path}: rerun cannot read it: {err}") from err
    rows: dict[str, list[dict]] = defaultdict(list)
    for chunk in chunks:
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if n not in _CONTROL_COLUMNS]
        columns = {n: _plain(batch.column(n)) for n in names}
        for i in range(batch.num_rows):
            row = {n: columns[n][i] for n in names}
            rows[chunk.entity_path.lstrip("/")].append(row)
    for entity_rows in rows.values():
        entity_rows.sort(key=lambda r: -1 if r.get("event") is None else r["event"])
    return dict(rows)


def _plain(column: pa.Array) -> list:
    """Python values of a column; timestamps as int ns (datetime would lose the ns)."""
    if pa.types.is_timestamp(column.type):
        column = column.cast(pa.int64())
    return column.to_pylist()


def has_blueprint(path: str | Path) -> bool:
    """True if the file carries a blueprint (the view's layout)."""
    return bool(RrdReader(path).blueprints())


def tensor(cell: list[dict]) -> np.ndarray:
    """A Tensor:data cell as a numpy array of its shape."""
    data = cell[0]
    return np.asarray(data["buffer"], dtype=float).reshape([int(s) for s in data["shape"]])


def segmentation(buffer_cell: list[list[int]], format_cell: list[dict]) -> np.ndarray:
    """A SegmentationImage (buffer, format) pair as a (height, width) array."""
    fmt = format_cell[0]
    return np.asarray(buffer_cell[0], dtype=np.uint8).reshape(int(fmt["height"]), int(fmt["width"]))
