"""PLY files: the one writer and reader of the vertex element every warpgs PLY holds (3D-GS models,
initial and densified point clouds) and of point clouds from COLMAP, Open3D or MeshLab. The format itself
is plyfile's (https://github.com/dranjan/python-plyfile): warpgs only chooses the columns.

    write_vertices(path, rec)         # rec: a numpy structured array (float32 / uint8 fields), written atomically
    header(n, rec.dtype)              # the header that goes with it (its size: len(header(...)))
    read_vertices(path)               # name -> array (ascii or binary, either endianness)
    read_elements(path)               # (name -> array of the vertices, element name -> count)

A 3D-GS model is one ``vertex`` element of little-endian float32 columns ``gaussian_fields(n_rest)``
(x y z nx ny nz f_dc_0..2 f_rest_0..M opacity scale_0..2 rot_0..3), the layout SuperSplat, gsplat's
viewer and the reference implementation read.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import plyfile

from warpgs.runfolder import atomic_write

_WRITE_TYPES = (np.dtype("<f4"), np.dtype("u1"))
GAUSSIAN_FIELDS_HEAD = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
GAUSSIAN_FIELDS_TAIL = ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]


def gaussian_fields(n_rest: int) -> list[str]:
    """The 3D-GS PLY's float32 columns with ``n_rest`` higher-order SH coefficients (three unused normals)."""
    return GAUSSIAN_FIELDS_HEAD + [f"f_rest_{i}" for i in range(n_rest)] + GAUSSIAN_FIELDS_TAIL


def float_fields(names: list[str]) -> np.dtype:
    return np.dtype([(name, "<f4") for name in names])


def _check_types(dtype: np.dtype) -> None:
    for name in dtype.names:
        if dtype.fields[name][0] not in _WRITE_TYPES:
            raise ValueError(f"PLY field {name!r}: type {dtype.fields[name][0]} is not written (float32 or uint8)")


def _ply_data(rec: np.ndarray) -> plyfile.PlyData:
    _check_types(rec.dtype)
    return plyfile.PlyData([plyfile.PlyElement.describe(rec, "vertex")], text=False, byte_order="<")


def header(n: int, dtype: np.dtype) -> bytes:
    """Binary little-endian header of ``n`` vertices with the fields of ``dtype`` (float32 or uint8), as
    ``write_vertices`` writes it."""
    _check_types(dtype)
    props = plyfile.PlyElement.describe(np.zeros(0, dtype), "vertex").properties
    return plyfile.PlyData([plyfile.PlyElement("vertex", props, n)], text=False, byte_order="<").header.encode(
        "ascii") + b"\n"


def write_vertices(path: str | Path, rec: np.ndarray) -> Path:
    """Writes the structured array ``rec`` as a binary PLY, through a temporary file and a rename."""
    data = _ply_data(np.ascontiguousarray(rec))

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            data.write(f)

    return atomic_write(path, write)


_TYPE_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
               "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}
MAX_HEADER = 1 << 20  # bytes: a longer "header" is not one


def check_header(path: str | Path) -> dict[str, int]:
    """Every element's name -> count, after checking the header against the file's size, before anything is
    allocated for the data: a header that claims more rows than the bytes after it can hold (a binary file holds
    each row's exact size, at least its list counts; an ascii one at least two characters per value) is a
    ``ValueError`` naming the file, the element, its claimed count and the bytes there are. A header that cannot
    be parsed is left to plyfile's messages (an empty dict)."""
    path = Path(path)
    with open(path, "rb") as f:
        head = f.read(MAX_HEADER)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return {}
    nl = head.find(b"\n", end)
    body = path.stat().st_size - (nl + 1 if nl >= 0 else len(head))
    fmt, elements = None, []  # [name, count, fixed bytes per row, values per row]
    for line in head[:end].decode("ascii", "replace").splitlines():
        w = line.split()
        if len(w) >= 2 and w[0] == "format":
            fmt = w[1]
        elif len(w) >= 3 and w[0] == "element":
            try:
                elements.append([w[1], int(w[2]), 0, 0])
            except ValueError:
                return {}
        elif len(w) >= 3 and w[0] == "property" and elements:
            if w[1] == "list" and len(w) >= 5:
                elements[-1][2] += _TYPE_SIZES.get(w[2], 1)  # the count; the items may be none
            else:
                elements[-1][2] += _TYPE_SIZES.get(w[1], 1)
            elements[-1][3] += 1
    need = 0
    for name, count, row_bytes, values in elements:
        if count < 0:
            raise ValueError(f"{path}: PLY header gives element {name!r} a negative count ({count})")
        need += count * (max(2 * values, 1) if fmt == "ascii" else row_bytes)
        if need > body:
            raise ValueError(f"{path}: PLY header claims {count} {name} rows, more than the {body} bytes after the "
                             "header can hold (truncated file or lying header)")
    return {name: count for name, count, _, _ in elements}


def require(names, wanted: list[str], path, what: str) -> None:
    """``ValueError`` naming the file and the columns of ``wanted`` that ``names`` lacks."""
    missing = [k for k in wanted if k not in names]
    if missing:
        raise ValueError(f"{path}: {what} without {', '.join(missing)}: not a complete file")


def read_elements(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """(the ``vertex`` element as name -> array in native byte order, every element's name -> count) of a
    PLY file (ascii or binary, either endianness, any other elements). Unreadable files are a ``ValueError``
    naming the file (``truncated`` where the data ends early, or the header claims more than the file holds:
    ``check_header``, before anything is allocated), a missing one ``FileNotFoundError``."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: PLY file is missing")
    check_header(path)
    try:
        data = plyfile.PlyData.read(str(path), mmap=False)
    except plyfile.PlyHeaderParseError as e:
        if e.line == 1:
            raise ValueError(f"{path}: not a PLY file (no 'ply' magic line)") from e
        raise ValueError(f"{path}: bad PLY header ({e})") from e
    except plyfile.PlyElementParseError as e:
        what = "file is truncated" if "end-of-file" in str(e) or "early end" in str(e) else "cannot read the data"
        raise ValueError(f"{path}: {what} ({e})") from e
    except (ValueError, TypeError, UnicodeDecodeError, MemoryError) as e:  # malformed numbers, odd types
        raise ValueError(f"{path}: cannot read it as PLY ({e})") from e
    counts = {el.name: el.count for el in data.elements}
    if "vertex" not in counts:
        raise ValueError(f"{path}: PLY file has no vertex element")
    arr = data["vertex"].data
    for name in arr.dtype.names:
        if arr.dtype.fields[name][0].kind == "O":
            raise ValueError(f"{path}: vertex element with list properties is not supported")
    vertices = {name: np.ascontiguousarray(arr[name]).astype(arr[name].dtype.newbyteorder("=")) for name in arr.dtype.names}
    return vertices, counts


def read_vertices(path: str | Path) -> dict[str, np.ndarray]:
    """The ``vertex`` element of a PLY file (ascii or binary, either endianness) as name -> array."""
    return read_elements(path)[0]


def keep_finite(v: dict[str, np.ndarray], names: list[str], path, drop: bool = False,
                what: str = "Gaussians") -> dict[str, np.ndarray]:
    """The rows of the vertex columns ``v`` whose ``names`` columns are all finite. Rows that are not make
    a ``ValueError`` naming the file, their count and the columns, unless ``drop``: then they are dropped
    with one warning line (``--drop-invalid``). A file with no finite row at all is an error either way."""
    names = [k for k in names if k in v and np.asarray(v[k]).dtype.kind == "f"]
    if not names:
        return v
    bad = ~np.all(np.stack([np.isfinite(v[k]) for k in names]), axis=0)
    n_bad, n = int(bad.sum()), len(bad)
    if not n_bad:
        return v
    cols = [k for k in names if not np.all(np.isfinite(v[k]))]
    shown = ", ".join(cols[:6]) + (f" and {len(cols) - 6} more" if len(cols) > 6 else "")
    if n_bad == n:
        raise ValueError(f"{path}: all {n} {what} have non-finite values (NaN or inf) in {shown}; nothing usable")
    if not drop:
        raise ValueError(f"{path}: {n_bad} of {n} {what} have non-finite values (NaN or inf) in {shown}; "
                         "--drop-invalid drops them")
    from warpgs.console import warn_once

    warn_once(f"warpgs: {path}: dropped {n_bad} of {n} {what} with non-finite values in {shown} (--drop-invalid)")
    return {k: np.asarray(a)[~bad] for k, a in v.items()}


__all__ = ["check_header", "float_fields", "gaussian_fields", "header", "keep_finite", "read_elements", "read_vertices",
           "require", "write_vertices"]
