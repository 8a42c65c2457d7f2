"""The results table (``runs.parquet``): its columns, rows to a pyarrow Table, and the rows a
resumed sweep keeps."""

from __future__ import annotations

import json
import os

import pyarrow as pa
import pyarrow.parquet as pq

from isaac.app.sweep import metrics as metric_columns
from isaac.app.sweep.worker import ROW_FILE_PREFIX, ROWS_DIR, read_rows, row_is_complete

TABLE = "runs.parquet"
TIMING_COLUMNS = ("wall_time_s", "worker")  # vary from run to run of one sweep


def _param_type(values) -> pa.DataType:
    if all(isinstance(v, bool) for v in values):
        return pa.bool_()
    if all(isinstance(v, int) and not isinstance(v, bool) for v in values):
        return pa.int64()
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        return pa.float64()
    return pa.string()  # strings; lists and mixtures as JSON text


def param_fields(sweep) -> list[pa.Field]:
    fields = []
    for axis in sweep.axes:
        if axis.dist is None:
            values = [plain for _, plain, _ in axis.values]
        elif axis.dist[0] == "choice":
            values = [plain for _, plain in axis.dist[1]]
        elif axis.dist[0] == "integers":
            values = [0]
        else:
            values = [0.0]
        fields.append(pa.field(axis.key, _param_type(values)))
    return fields


def schema(sweep) -> pa.Schema:
    fields = [pa.field("index", pa.int64()), *param_fields(sweep)]
    fields += metric_columns.columns(sweep.metrics, sweep.final_bodies)
    fields += [pa.field("status", pa.string()), pa.field("error", pa.string())]
    if sweep.record != "none":
        fields += [pa.field("log_path", pa.string()), pa.field("log_sha256", pa.string())]
    if sweep.record == "mcap+rrd":
        fields += [pa.field("rrd_path", pa.string()), pa.field("rrd_sha256", pa.string())]
    fields += [pa.field("wall_time_s", pa.float64()), pa.field("worker", pa.string())]
    return pa.schema(fields, metadata={"sweep": os.path.basename(sweep.path)})


def _cell(value, type_: pa.DataType):
    if type_ == pa.string() and value is not None and not isinstance(value, str):
        return json.dumps(value)
    if type_ == pa.float64() and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def to_table(rows: list[dict], schema_: pa.Schema) -> pa.Table:
    """The rows (sorted by index) as a Table of `schema_`."""
    rows = sorted(rows, key=lambda r: r["index"])
    columns = {}
    for f in schema_:
        values = [r.get(f.name) for r in rows]
        if (f.type == pa.string() or f.type == pa.float64()) and not all(
            v is None or type(v) is (str if f.type == pa.string() else float) for v in values
        ):
            values = [_cell(v, f.type) for v in values]  # JSON text, ints as floats
        columns[f.name] = pa.array(values, type=f.type)
    return pa.table(columns, schema=schema_)


def write(table: pa.Table, out_dir: str) -> str:
    """Write `table` as OUT/runs.parquet (a temporary name, then a rename)."""
    path = os.path.join(out_dir, TABLE)
    tmp = path + ".tmp"
    pq.write_table(table, tmp)
    os.replace(tmp, path)
    return path


def kept_rows(out_dir: str, n_runs: int, schema_: pa.Schema) -> dict[int, dict]:
    """{index: row} of the runs a resumed sweep keeps: rows in OUT/runs.parquet or OUT/rows/
    whose logs are complete (there, and with the sha256 the row names). Rows of another
    layout (a sweep whose columns differ) are not kept."""
    kept: dict[int, dict] = {}
    path = os.path.join(out_dir, TABLE)
    if os.path.exists(path):
        try:
            old = pq.read_table(path)
        except Exception:  # noqa: BLE001 - a damaged table: every run is redone
            old = None
        if old is not None and old.schema.remove_metadata().equals(schema_.remove_metadata()):
            for row in old.to_pylist():
                i = row["index"]
                # a row no worker finished (its chunk's workers kept dying) is redone
                if 0 <= i < n_runs and row["worker"] is not None and row_is_complete(out_dir, row):
                    kept[i] = row
    rows_dir = os.path.join(out_dir, ROWS_DIR)
    if os.path.isdir(rows_dir):
        for name in sorted(os.listdir(rows_dir)):
            if not (name.startswith(ROW_FILE_PREFIX) and name.endswith(".jsonl")):
                continue
            for row in read_rows(os.path.join(rows_dir, name)):
                i = row["index"]
                if (
                    0 <= i < n_runs
                    and i not in kept
                    and set(row) == set(schema_.names)
                    and row_is_complete(out_dir, row)
                ):
                    kept[i] = row
    return kept
