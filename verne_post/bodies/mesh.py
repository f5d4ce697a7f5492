"""STL meshes for the setup: read (binary or ASCII STL), and their bounds.

The format: an ASCII file starts with ``solid`` and lists ``facet normal ... outer loop vertex x
y z (x3) endloop endfacet``; a binary one has an 80-byte header, a little-endian uint32 triangle
count and 50 bytes per triangle (normal, three vertices as float32, a uint16 attribute) — the
3D Systems "StereoLithography Interface Specification" (1989), as every CAD exporter writes it.
A binary file may also start with ``solid``, so the binary size rule is tried first.

The checks treat a mesh as its bounding box (conservative: the box holds the mesh, so a clearance
to it is never larger than to the mesh). Units: the file's, as given (scaled by the caller).
"""

from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np

#: Bytes of an STL file read at most: a fixture or stock mesh, not a scan of the shop.
MAX_BYTES = 256 * 1024 * 1024
_VERTEX = re.compile(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)")


class MeshError(ValueError):
    """An STL file that cannot be read as one: the message says why."""


def read_stl(path: Path) -> np.ndarray:
    """The triangles (T, 3, 3) of a binary or ASCII STL file, in its units. Raises OSError where
    the file cannot be read, :class:`MeshError` where it is not an STL mesh."""
    size = path.stat().st_size
    if size > MAX_BYTES:
        raise MeshError(f"'{path}' is {size / 2**20:.0f} MiB, over the {MAX_BYTES // 2**20} MiB an STL may have")
    data = path.read_bytes()
    if len(data) >= 84:
        (count,) = struct.unpack_from("<I", data, 80)
        if 84 + 50 * count == len(data):
            record = np.dtype([("normal", "<f4", 3), ("vertex", "<f4", (3, 3)), ("attribute", "<u2")])
            triangles = np.frombuffer(data, record, count, 84)["vertex"].astype(float)
            return _checked(triangles, path)
    if not data.lstrip().lower().startswith(b"solid"):
        raise MeshError(f"'{path}' is neither a binary STL (its size does not match its triangle count) nor an "
                        f"ASCII one (it does not start with 'solid')")
    try:
        vertices = np.array([[float(v) for v in m.groups()] for m in _VERTEX.finditer(data)])
    except ValueError:
        raise MeshError(f"'{path}': an ASCII STL vertex has a coordinate that is not a number") from None
    if len(vertices) % 3:
        raise MeshError(f"'{path}': an ASCII STL needs three vertices per facet, it has {len(vertices)} in all")
    return _checked(vertices.reshape(-1, 3, 3), path)


def _checked(triangles: np.ndarray, path: Path) -> np.ndarray:
    if not len(triangles):
        raise MeshError(f"'{path}' holds no triangle")
    if not np.all(np.isfinite(triangles)):
        raise MeshError(f"'{path}' has a vertex that is not a finite number")
    return triangles


def mesh_bounds(triangles: np.ndarray) -> np.ndarray:
    """(2, 3): the smallest and largest x, y, z of the triangles' vertices (their units)."""
    points = triangles.reshape(-1, 3)
    return np.array([points.min(axis=0), points.max(axis=0)])
