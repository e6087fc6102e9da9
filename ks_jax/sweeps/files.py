"""A sweep written to a results file (.csv, .npz or .parquet), chunk by chunk as it is computed."""

from __future__ import annotations

import csv
import io
import math
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

from ..batch import CHUNK_ROWS
from ..case.errors import CaseError
from ..files import check_output_file
from ..model.types import STATUS_TEXT
from .columns import axes_in_units, check_units, columns, invalid_rows, missing_flags, outputs_in_units, status_texts
from .result import SweepResult


CSV_HINT_POINTS = 100_000  # from this many points, ``ks-jax sweep`` without pyarrow suggests it for a .csv


def _arrow_csv():
    """pyarrow's csv module, or None without pyarrow (``ResultWriter`` then writes with ``csv``)."""
    try:
        import pyarrow.csv
    except ImportError:
        return None
    return pyarrow.csv


def _arrow_table(cols):
    """A pyarrow table of ``cols`` (name -> flat array, "status" among them); a flag (bool) of an
    invalid row is null (its numbers are NaN), not a false that would read as a result."""
    import pyarrow as pa

    invalid = invalid_rows(cols["status"])
    return pa.table({k: pa.array(v, mask=invalid) if v.dtype == bool and invalid.any() else v
                     for k, v in cols.items()})


class ResultWriter:
    """Writes a sweep to ``out`` (.csv, .npz or .parquet) chunk by chunk, as ``sweep`` computes it:
    pass ``writer.chunk`` as ``on_chunk`` (with ``keep=False``), then call ``close()`` (or ``abort()``
    on an error). Memory stays at a few chunks whatever the number of points (``ks-jax sweep``).

    .csv: one row per point: the swept inputs, the outputs, ``status``, ``status_text``; an invalid
    row's numbers are NaN and its flags (``contact.sliding``) empty (null in .parquet). Where
    pyarrow is installed its CSV writer formats the numbers (shortest text that reads back as the same
    float, as Python's, but 1.0 is written "1" and 1e-05 "0.00001"; float32 results as float32, so
    "0.1" where the csv module writes 0.10000000149011612), writes booleans true / false and
    quotes every text; without pyarrow the ``csv`` module writes it (1.0, 1e-05, True / False, texts
    quoted only where they must be), several times slower: Python's float formatting is the cost.
    .parquet: the same columns (pyarrow), in row groups of about 2^18 points.
    .npz: one array per output in the result's shape, ``axis:<path>`` for the axes, the status codes
    and texts (a bool array has no empty value: an invalid row's flag is False there, read its
    status). Each array is appended to a temporary .npy file beside ``out``, chunk by chunk; ``close``
    stores them in ``out`` (uncompressed, as ``np.savez``), so the disk briefly holds them twice.
    The file is written as ``.<name>.partial`` beside ``out`` and renamed to ``out`` by ``close``: a
    sweep that fails leaves an earlier ``out`` as it was.
    ``units="us"``: every swept input and output in the units of ``units.US_DISPLAY`` (mph, ft, lbf s,
    ft lbf, deg, deg/s, lb), its unit in its name ("vehicles[1].speed [mph]", in every format);
    dimensionless ones, booleans and the status as they are; a swept value typed as 25 mph is 25, not
    the 24.999999999999996 that comes back from m/s. Default "si": SI, names as paths.
    """

    ROW_GROUP = 1 << 18

    def __init__(self, out, axes, mode, shape, first=0, units="si"):
        """axes: path -> the swept values (SI); shape: the result's shape; first: the flat index of
        its first point (a sweep's ``index_range[0]``); units: "si" or "us" (the file's units)."""
        check_units(units, "the units of a results file")
        self.out = Path(out)
        self.kind = self.out.suffix.lower()
        if self.kind not in (".csv", ".npz", ".parquet"):
            raise CaseError(f"--out {out}: unknown file type '{self.out.suffix}' (use .csv, .npz or .parquet)")
        check_output_file(out, "--out")
        if self.kind == ".parquet":
            try:
                import pyarrow  # noqa: F401
            except ImportError:
                raise CaseError("parquet output needs pyarrow: pip install 'ks-jax[parquet]' "
                                "(or write .csv / .npz)") from None
        self.units, self.mode, self.shape, self.first = units, mode, tuple(shape), int(first)
        # the swept values (and below, the outputs) as the file holds them, by the names it gives them
        self.axes = axes_in_units(axes, units)
        self.points = math.prod(self.shape)
        self._partial = self.out.with_name(f".{self.out.name}.partial")
        self._file = self._parquet = self._tmpdir = None
        self._arrays, self._pending, self._written, self._npy_layout = {}, [], 0, {}
        self._arrow_csv = _arrow_csv() if self.kind == ".csv" else None
        # the swept values as the columns show them: in a .csv of a grid written by the csv module,
        # each value's text (what it writes for the Python float), formatted once instead of once per row
        self._column_axes = self.axes
        if self.kind == ".csv" and self._arrow_csv is None and mode != "zip":
            self._column_axes = {p: np.array([str(x) for x in np.asarray(v).tolist()], dtype=object)
                                 for p, v in self.axes.items()}
        self.seconds = self.chunk_seconds = 0.0  # spent writing: in all, and inside ``chunk``

    @property
    def slow_csv(self) -> bool:
        """Whether this is a .csv written by Python's csv module (pyarrow is not installed): several times
        slower than pyarrow's writer."""
        return self.kind == ".csv" and self._arrow_csv is None

    def chunk(self, lo, hi, chunk):
        """Points lo .. hi - 1 (flat indices, in order): ``chunk`` maps each output path and "status"
        to an array of hi - lo values."""
        t = time.perf_counter()
        try:
            self._chunk(lo, hi, chunk)
        finally:
            self.chunk_seconds += time.perf_counter() - t
            self.seconds += time.perf_counter() - t

    def _chunk(self, lo, hi, chunk):
        if lo - self.first != self._written:
            raise CaseError(f"{self.out}: points {lo}..{hi - 1} arrived after {self._written} of {self.points}")
        if self.units != "si":
            chunk = outputs_in_units(chunk, self.units)
        if self.kind == ".npz":
            self._npz_chunk(chunk)
        else:
            cols = columns(self._column_axes, self.mode, lo, hi, chunk)
            cols["status_text"] = status_texts(cols["status"])
            if self.kind == ".csv" and self._arrow_csv is None:
                self._csv_chunk(cols)
            else:
                table = _arrow_table(cols)
                if self.kind == ".csv":
                    self._arrow_csv_chunk(table)
                else:
                    self._pending.append(table)
                    if sum(t.num_rows for t in self._pending) >= self.ROW_GROUP:
                        self._flush_parquet()
        self._written += hi - lo

    def _csv_chunk(self, cols):
        if self._file is None:
            self._file = self._partial.open("w", newline="")
            self._csv = csv.writer(self._file)
            self._csv.writerow(list(cols))
        texts = (c.tolist() for c in missing_flags(cols).values())  # a flag of an invalid row: ""
        self._csv.writerows(zip(*texts))

    def _arrow_csv_chunk(self, table):
        if self._file is None:
            options = self._arrow_csv.WriteOptions(quoting_style="needed")
            self._file = self._arrow_csv.CSVWriter(str(self._partial), table.schema, write_options=options)
        self._file.write_table(table)

    def _flush_parquet(self):
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not self._pending:
            return
        table = pa.concat_tables(self._pending)
        if self._parquet is None:
            self._parquet = pq.ParquetWriter(self._partial, table.schema)
        self._parquet.write_table(table)
        self._pending = []

    def _npz_chunk(self, chunk):
        if self._tmpdir is None:
            self._tmpdir = tempfile.TemporaryDirectory(prefix=self.out.name + ".", dir=self.out.parent)
        for k, (p, v) in enumerate(chunk.items()):
            if p not in self._arrays:
                path = Path(self._tmpdir.name) / f"{k}.npy"
                f = path.open("wb")
                header = {"descr": np.lib.format.dtype_to_descr(v.dtype), "fortran_order": False, "shape": self.shape}
                np.lib.format.write_array_header_2_0(f, header)
                self._arrays[p] = (path, f)
                self._npy_layout[p] = (v.dtype, f.tell())
            self._arrays[p][1].write(np.ascontiguousarray(v).tobytes())

    def keep_incomplete(self):
        """After an interruption: the points written so far, finished as a file of their own beside ``out``,
        named ``<stem>.incomplete<suffix>`` (``out`` is left as it was). Returns (its path, the points it
        holds), counted from the file itself; (None, 0) where no point was written. A .npz holds them flat,
        the first points of the sweep in row-major order (``flat_index`` says which)."""
        target = self.out.with_name(f"{self.out.stem}.incomplete{self.out.suffix}")
        try:
            if self.kind == ".csv":
                if self._file is None:
                    return None, 0
                self._file.close()
                self._file = None
                with self._partial.open("rb") as f:
                    rows = sum(block.count(b"\n") for block in iter(lambda: f.read(1 << 24), b"")) - 1
            elif self.kind == ".parquet":
                self._flush_parquet()
                if self._parquet is None:
                    return None, 0
                self._parquet.close()
                self._parquet = None
                import pyarrow.parquet as pq

                rows = pq.read_metadata(self._partial).num_rows
            else:
                if not self._arrays:
                    return None, 0
                for _, f in self._arrays.values():
                    f.flush()
                # an output written in full for a point counts it: the least over the outputs
                rows = min((path.stat().st_size - start) // dtype.itemsize
                           for (path, _), (dtype, start) in zip(self._arrays.values(), self._npy_layout.values()))
                self._write_npz(rows)
            self._partial.replace(target)
            return target, int(rows)
        finally:
            self.abort()

    def close(self):
        """Finish the file (.npz: store the arrays). Raises if not every point was written."""
        t = time.perf_counter()
        try:
            if self._written != self.points:
                raise CaseError(f"{self.out}: {self._written} of {self.points} points written")
            if self.points == 0:
                raise CaseError(f"{self.out}: the sweep has no points to write")
            if self.kind == ".csv":
                self._file.close()
            elif self.kind == ".parquet":
                self._flush_parquet()
                self._parquet.close()
            else:
                self._write_npz()
            self._file = self._parquet = None
            self._partial.replace(self.out)
        finally:
            self.abort()
            self.seconds += time.perf_counter() - t

    def _write_npz(self, incomplete=None):
        """The .npz from the arrays written; ``incomplete``: only that many first points, flat."""
        for _, f in self._arrays.values():
            f.close()
        codes = np.array(sorted(STATUS_TEXT))
        small = {f"axis:{p}": np.asarray(v) for p, v in self.axes.items()}
        small.update(status_codes=codes, status_texts=np.array([STATUS_TEXT[c] for c in codes]))
        if incomplete is not None:
            small["flat_index"] = np.arange(self.first, self.first + incomplete)
        with zipfile.ZipFile(self._partial, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
            for p, (path, _) in self._arrays.items():
                if incomplete is None:
                    zf.write(path, f"{p}.npy")
                    continue
                dtype, start = self._npy_layout[p]
                buf = io.BytesIO()
                np.save(buf, np.fromfile(path, dtype, count=incomplete, offset=start))
                zf.writestr(f"{p}.npy", buf.getvalue())
            for name, v in small.items():
                buf = io.BytesIO()
                np.save(buf, v)
                zf.writestr(f"{name}.npy", buf.getvalue())

    def abort(self):
        """Close what is open and delete the unfinished file (``out`` itself is left as it was)."""
        if self._file is not None:
            self._file.close()
            self._file = None
        if self._parquet is not None:
            self._parquet.close()
            self._parquet = None
        for _, f in self._arrays.values():
            f.close()
        self._arrays = {}
        if self._tmpdir is not None:
            self._tmpdir.cleanup()
            self._tmpdir = None
        self._partial.unlink(missing_ok=True)


def write_results(result: SweepResult, out, units="si"):
    """Write a kept sweep (``SweepResult``) to .csv (one row per point), .npz (arrays) or .parquet
    (pyarrow), in the format of ``ks-jax sweep`` (``ResultWriter``); units: "si" or "us"."""
    lo, hi = result.index_range
    writer = ResultWriter(out, result.axes, result.mode, result.shape, first=lo, units=units)
    flat = {p: np.ravel(v) for p, v in result.outputs.items()}
    try:
        for a in range(0, hi - lo, CHUNK_ROWS):
            b = min(hi - lo, a + CHUNK_ROWS)
            writer.chunk(lo + a, lo + b, {p: v[a:b] for p, v in flat.items()})
        writer.close()
    except BaseException:
        writer.abort()
        raise
