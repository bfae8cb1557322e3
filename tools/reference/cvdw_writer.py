"""Writes (and reads back) the .cvdw weights format of engine/cvdw.h from Python (NumPy arrays or torch tensors):
"CVDW", u32 version 1, u64 header length, JSON header padded with spaces so that the data starts
64-byte aligned, then each tensor's little-endian row-major blob at a 64-aligned offset, with
its zlib CRC-32 in the tensor table. Written to a temporary name and renamed when complete.
"""
import json
import os
import struct
import zlib

import numpy as np

ALIGN = 64
VERSION = 1


def _align(n):
    return (n + ALIGN - 1) // ALIGN * ALIGN


def _as_array(t):
    if hasattr(t, "detach"):
        t = t.detach().cpu().numpy()
    a = np.asarray(t)
    # astype(order="C") keeps 0-d arrays 0-d (np.ascontiguousarray would make them 1-d).
    if a.dtype == np.float64:
        return a.astype("<f8", order="C"), "f64"
    if a.dtype == np.float32:
        return a.astype("<f4", order="C"), "f32"
    if a.dtype.kind in "iub":
        return a.astype("<f8", order="C"), "f64"  # counters are stored as f64
    raise ValueError(f"unsupported dtype {a.dtype}")


def write_cvdw(path, model, config, tensors):
    """tensors: list of (name, array_or_tensor, kind) with kind possibly ''."""
    blobs, table = [], []
    for name, t, kind in tensors:
        a, dtype = _as_array(t)
        data = a.tobytes()
        entry = {"name": name, "dtype": dtype, "shape": list(a.shape), "offset": 0, "nbytes": len(data),
                 "crc32": zlib.crc32(data) & 0xFFFFFFFF}
        if kind:
            entry["kind"] = kind
        blobs.append(data)
        table.append(entry)
    names = [e["name"] for e in table]
    if len(set(names)) != len(names):
        raise ValueError("duplicate tensor names")
    # The header length depends on the offsets it lists: iterate until the layout is stable.
    data_start = _align(16 + 256)
    while True:
        off = data_start
        for e, b in zip(table, blobs):
            e["offset"] = off
            off = _align(off + len(b))
        header = json.dumps({"format": "cvdw", "model": model, "config": config, "tensors": table}).encode()
        if 16 + len(header) <= data_start:
            break
        data_start = _align(16 + len(header))
    header += b" " * (data_start - 16 - len(header))
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "wb") as f:
        f.write(b"CVDW" + struct.pack("<IQ", VERSION, len(header)) + header)
        pos = data_start
        for e, b in zip(table, blobs):
            f.write(b"\0" * (e["offset"] - pos))
            f.write(b)
            pos = e["offset"] + len(b)
    os.replace(tmp, path)


def read_cvdw(path):
    """Reads a .cvdw file: returns (header dict, {name: numpy array}) (CRCs verified)."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"CVDW":
        raise ValueError(f"{path}: not a cvdw file")
    version, hlen = struct.unpack("<IQ", data[4:16])
    if version != VERSION:
        raise ValueError(f"{path}: unsupported cvdw version {version}")
    header = json.loads(data[16:16 + hlen])
    tensors = {}
    for e in header["tensors"]:
        blob = data[e["offset"]:e["offset"] + e["nbytes"]]
        if zlib.crc32(blob) & 0xFFFFFFFF != e["crc32"]:
            raise ValueError(f"{path}: tensor '{e['name']}': CRC mismatch")
        dt = "<f4" if e["dtype"] == "f32" else "<f8"
        tensors[e["name"]] = np.frombuffer(blob, dtype=dt).reshape(e["shape"]).copy()
    return header, tensors
