"""PLY files: the one writer and reader of the vertex element every warpgs PLY holds (3D-GS models,
initial and densified point clouds) and of point clouds from COLMAP, Open3D or MeshLab.

    write_vertices(path, rec)         # rec: a numpy structured array (float32 / uint8 fields), written atomically
    header(n, rec.dtype)              # the header that goes with it (its size: len(header(...)))
    read_vertices(path)               # name -> array (ascii or binary, either endianness)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

_WRITE_TYPES = {np.dtype("<f4"): "float", np.dtype("u1"): "uchar"}
GAUSSIAN_FIELDS_HEAD = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
GAUSSIAN_FIELDS_TAIL = ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]


def gaussian_fields(n_rest: int) -> list[str]:
    """The 3D-GS PLY's float32 columns with ``n_rest`` higher-order SH coefficients (three unused normals)."""
    return GAUSSIAN_FIELDS_HEAD + [f"f_rest_{i}" for i in range(n_rest)] + GAUSSIAN_FIELDS_TAIL


def header(n: int, dtype: np.dtype) -> bytes:
    """Binary little-endian header of ``n`` vertices with the fields of ``dtype`` (float32 or uint8)."""
    props = []
    for name in dtype.names:
        t = dtype.fields[name][0]
        if t not in _WRITE_TYPES:
            raise ValueError(f"PLY field {name!r}: type {t} is not written (float32 or uint8)")
        props.append(f"property {_WRITE_TYPES[t]} {name}\n")
    return ("ply\nformat binary_little_endian 1.0\n" + f"element vertex {n}\n" + "".join(props)
            + "end_header\n").encode("ascii")


def float_fields(names: list[str]) -> np.dtype:
    return np.dtype([(name, "<f4") for name in names])


def write_vertices(path: str | Path, rec: np.ndarray) -> Path:
    """Writes the structured array ``rec`` as a binary PLY, through a temporary file and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(header(len(rec), rec.dtype))
        f.write(np.ascontiguousarray(rec).tobytes())
    tmp.replace(path)
    return path


_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def read_vertices(path: str | Path) -> dict[str, np.ndarray]:
    """The ``vertex`` element of a PLY file (ascii or binary, either endianness) as name -> array."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: PLY file is missing")
    with open(path, "rb") as f:
        if f.readline().strip() != b"ply":
            raise ValueError(f"{path}: not a PLY file (no 'ply' magic line)")
        fmt, elements = None, []
        while True:
            line = f.readline()
            if not line:
                raise ValueError(f"{path}: PLY header has no end_header")
            tok = line.decode("ascii", "replace").split()
            if not tok or tok[0] in ("comment", "obj_info"):
                continue
            if tok[0] == "end_header":
                break
            if tok[0] == "format":
                fmt = tok[1]
            elif tok[0] == "element":
                elements.append((tok[1], int(tok[2]), []))
            elif tok[0] == "property":
                if not elements:
                    raise ValueError(f"{path}: property before any element")
                if tok[1] == "list":
                    elements[-1][2].append((tok[4], ("list", tok[2], tok[3])))
                else:
                    if tok[1] not in _PLY_TYPES:
                        raise ValueError(f"{path}: unknown PLY type {tok[1]!r}")
                    elements[-1][2].append((tok[2], tok[1]))
        if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
            raise ValueError(f"{path}: unsupported PLY format {fmt!r}")
        body = f.read()
    order = "<" if fmt == "binary_little_endian" else ">"
    offset = 0
    lines = body.decode("ascii", "replace").split("\n") if fmt == "ascii" else None
    line_no = 0
    for name, count, props in elements:
        has_list = any(isinstance(t, tuple) for _, t in props)
        if name == "vertex":
            if has_list:
                raise ValueError(f"{path}: vertex element with list properties is not supported")
            if fmt == "ascii":
                rows = [ln.split() for ln in lines[line_no:line_no + count]]
                if len(rows) < count:
                    raise ValueError(f"{path}: file ends inside the vertex data")
                arr = np.array(rows, dtype=np.float64).reshape(count, len(props))
                return {pname: arr[:, i].astype(_PLY_TYPES[t]) for i, (pname, t) in enumerate(props)}
            dtype = np.dtype([(pname, order + _PLY_TYPES[t]) for pname, t in props])
            if len(body) < offset + count * dtype.itemsize:
                raise ValueError(f"{path}: file is truncated ({len(body) - offset} bytes of vertex data, "
                                 f"{count * dtype.itemsize} expected)")
            arr = np.frombuffer(body, dtype=dtype, count=count, offset=offset)
            return {pname: arr[pname].astype(arr[pname].dtype.newbyteorder("=")) for pname, _ in props}
        # skip an element that comes before the vertices
        if fmt == "ascii":
            line_no += count
        elif has_list:
            raise ValueError(f"{path}: element {name!r} with lists precedes the vertices; not supported")
        else:
            offset += count * sum(np.dtype(_PLY_TYPES[t]).itemsize for _, t in props)
    raise ValueError(f"{path}: PLY file has no vertex element")


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


__all__ = ["float_fields", "gaussian_fields", "header", "keep_finite", "read_vertices", "write_vertices"]
