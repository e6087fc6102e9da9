"""A sweep written to a results file (.csv, .npz or .parquet), chunk by chunk as it is computed."""

from __future__ import annotations

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
from .columns import axes_in_units, check_units, columns, invalid_rows, outputs_in_units, status_texts
from .result import SweepResult, check_kept


CSV_HINT_POINTS = 100_000  # from this many points, ``ks-jax sweep`` without pyarrow suggests it for a .csv


def _arrow_csv():
    """pyarrow's csv module, or None without pyarrow (``ResultWriter`` then formats the text itself,
    ``csv_texts``)."""
    try:
        import pyarrow.csv
    except ImportError:
        return None
    return pyarrow.csv


# Numbers in a .csv are written in plain notation for decimal exponents PLAIN_LOW .. PLAIN_HIGH - 1 (1e-6 to
# below 1e10), otherwise in exponent form: as pyarrow writes them, so that a file is the same either way
PLAIN_LOW, PLAIN_HIGH = -6, 10


def _number_text(shortest: str) -> str:
    """A number's text in a .csv from its shortest round-trip text as Python or NumPy writes it ("180.0",
    "1e-05", "1.5e+16"): the same digits, in the notation of ``PLAIN_LOW`` / ``PLAIN_HIGH``, no trailing
    ".0", the exponent without padding ("180", "0.00001", "1.5e+16", "1e-7")."""
    if shortest in ("nan", "inf", "-inf"):
        return shortest
    sign, text = ("-", shortest[1:]) if shortest.startswith("-") else ("", shortest)
    mantissa, _, exponent = text.partition("e")
    whole, _, fraction = mantissa.partition(".")
    digits = whole + fraction
    k = int(exponent or 0) + len(whole) - 1  # the decimal exponent of the first digit
    significant = digits.lstrip("0")
    k -= len(digits) - len(significant)
    significant = significant.rstrip("0")
    if not significant:
        return sign + "0"
    if PLAIN_LOW <= k < PLAIN_HIGH:
        if k >= 0:
            whole, fraction = significant[:k + 1].ljust(k + 1, "0"), significant[k + 1:]
        else:
            whole, fraction = "0", "0" * (-k - 1) + significant
        return sign + whole + ("." + fraction if fraction else "")
    rest = "." + significant[1:] if len(significant) > 1 else ""
    return f"{sign}{significant[0]}{rest}e{'+' if k >= 0 else '-'}{abs(k)}"


def number_texts(values) -> list:
    """The texts of a column of numbers in a .csv (``_number_text``): floats as the shortest text that reads
    back as the same value of their type (float32 as float32), integers as they are. Most values take
    Python's own shortest text with a trailing ".0" cut; only those Python writes in another notation (below
    1e-4 or from 1e10) are rewritten one by one."""
    values = np.asarray(values)
    if values.dtype.kind != "f":
        return [str(v) for v in values.tolist()]
    # NumPy's text of a float32 is its shortest float32 text; Python's of a float64 its shortest
    shortest = list(map(float.__repr__, values.tolist())) if values.dtype == np.float64 else values.astype(str).tolist()
    texts = [t[:-2] if t[-2:] == ".0" else t for t in shortest]
    with np.errstate(invalid="ignore", over="ignore"):
        size = np.abs(values.astype(np.float64))
        other = (size >= 10.0 ** PLAIN_HIGH) | ((size < 1e-4) & (size != 0))
    if values.dtype != np.float64:  # NumPy writes a float32 in exponent form from 1e16, and below 1e-4
        other |= np.array(["e" in t for t in shortest], dtype=bool)
    for i in np.flatnonzero(other).tolist():
        texts[i] = _number_text(shortest[i])
    return texts


def csv_field(text: str) -> str:
    """A text as one field of a .csv: quoted (its quotes doubled) where RFC 4180 needs it (a comma, a
    quote, a line break), else as it is."""
    if any(c in text for c in ',"\r\n'):
        return '"' + text.replace('"', '""') + '"'
    return text


def csv_header(names) -> str:
    """The header line of a .csv: the column names, quoted only where they must be (``csv_field``)."""
    return ",".join(csv_field(str(n)) for n in names) + "\n"


def csv_texts(values, invalid=None) -> list:
    """The fields of one column of a .csv, as pyarrow's writer (quoting where needed) writes them: numbers by
    ``number_texts``, booleans ``true`` / ``false`` (an empty field on the ``invalid`` rows: a flag of an
    invalid row has no value), texts always quoted; a column of texts already made (object) as it is."""
    values = np.asarray(values)
    if values.dtype == bool:
        texts = np.where(values, "true", "false").astype(object)
        if invalid is not None and invalid.any():
            texts[invalid] = ""
        return texts.tolist()
    if values.dtype.kind in "fiu":
        return number_texts(values)
    if values.dtype.kind == "U":
        return ['"' + t.replace('"', '""') + '"' for t in values.tolist()]
    return values.tolist()


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
    row's numbers are NaN and its flags (``contact.sliding``) empty (null in .parquet). One format
    whether pyarrow writes it (where it is installed: several times faster) or ks-jax formats it
    (``csv_texts``), byte for byte: the header unquoted (quoted only where RFC 4180 needs it),
    each number as the shortest text that reads back as the same float (a float32 result as the
    shortest float32 text), in plain notation from 1e-6 to below 1e10 without a trailing ".0"
    (``1``, ``180``, ``0.00001``) and otherwise as ``1e-7``, ``1.5e+10``; ``nan``, ``inf``;
    booleans ``true`` / ``false``; the status text always quoted; lines ended by "\n".
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
        # the swept values as the columns show them: in a .csv of a grid written without pyarrow, each
        # value's text, formatted once instead of once per row
        self._column_axes = self.axes
        if self.kind == ".csv" and self._arrow_csv is None and mode != "zip":
            self._column_axes = {p: np.array(number_texts(v), dtype=object) for p, v in self.axes.items()}
        self._sink = None  # the open .csv file under pyarrow's writer
        self.seconds = self.chunk_seconds = 0.0  # spent writing: in all, and inside ``chunk``

    @property
    def slow_csv(self) -> bool:
        """Whether this is a .csv written without pyarrow (``csv_texts`` formats it in Python): several times
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
            self._file = self._partial.open("w", newline="", encoding="utf-8")
            self._file.write(csv_header(cols))
        invalid = invalid_rows(cols["status"])
        cols["status_text"] = cols["status_text"].astype(str)  # a text column: quoted
        texts = [csv_texts(v, invalid) for v in cols.values()]
        self._file.write("".join(line + "\n" for line in map(",".join, zip(*texts))))

    def _arrow_csv_chunk(self, table):
        if self._file is None:
            self._sink = self._partial.open("wb")
            self._sink.write(csv_header(table.column_names).encode())
            options = self._arrow_csv.WriteOptions(include_header=False, quoting_style="needed")
            self._file = self._arrow_csv.CSVWriter(self._sink, table.schema, write_options=options)
        self._file.write_table(table)

    def _close_csv(self):
        """Close the .csv being written (pyarrow's writer, then the file under it)."""
        try:
            if self._file is not None:
                self._file.close()
        finally:
            self._file = None
            if self._sink is not None:
                self._sink.close()
                self._sink = None

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
                self._close_csv()
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
                self._close_csv()
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
        self._close_csv()
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
    check_kept(result)
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
