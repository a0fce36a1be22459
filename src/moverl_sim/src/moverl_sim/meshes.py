"""Triangle meshes of a robot's visuals, read and simplified for the simulator's depth cameras. ROS-free.

A depth camera at 160x120 sees a link of the Panda over a few hundred pixels, yet its visual mesh has up to 22,000
triangles: PyBullet's TinyRenderer spends nine tenths of an image on them (docs/notes/sensing_history.md,
render_cost.py). Drawn as a quadric-error simplification of itself (fast_simplification, the decimation of pyvista)
with at most ``faces`` triangles, a link keeps its silhouette within millimetres (render_cost.py measures how far the
depths move) and the Panda's 160x120 image costs about a quarter (4.7 ms against 18). Meshes this module reads:
Wavefront OBJ (vertices and faces; texture and normal indices ignored), STL (ASCII or binary) and COLLADA (pycollada:
the triangles of the visual scene's geometries, placed by their nodes' transforms and scaled by the file's <unit>, its
<up_axis> not applied, as PyBullet reads them); any other format is drawn as it is.
"""

from __future__ import annotations

import os
import struct
import warnings

import numpy as np

__all__ = ["read_mesh", "write_obj", "simplified", "SIMPLIFIABLE"]

#: Mesh file suffixes this module reads (lower case).
SIMPLIFIABLE = (".obj", ".stl", ".dae")


def _read_obj(path: str) -> tuple[np.ndarray, np.ndarray]:
    vertices: list[list[float]] = []
    faces: list[list[int]] = []
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if line.startswith("v "):
                vertices.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                # v, v/vt, v//vn or v/vt/vn; 1-based, or negative: relative to the vertices read so far
                idx = [int(t.split("/")[0]) for t in line.split()[1:]]
                idx = [i - 1 if i > 0 else len(vertices) + i for i in idx]
                faces.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))  # a fan per polygon
    return np.asarray(vertices, dtype=float).reshape(-1, 3), np.asarray(faces, dtype=np.int64).reshape(-1, 3)


def _read_stl(path: str) -> tuple[np.ndarray, np.ndarray]:
    with open(path, "rb") as fh:
        data = fh.read()
    corners: np.ndarray
    if len(data) >= 84 and 84 + 50 * struct.unpack("<I", data[80:84])[0] == len(data):  # binary
        n = struct.unpack("<I", data[80:84])[0]
        record = np.dtype([("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
        corners = np.frombuffer(data, dtype=record, count=n, offset=84)["v"].reshape(-1, 3).astype(float)
    else:  # ASCII: "vertex x y z" lines, three per facet
        words = data.decode("utf-8", errors="replace").split()
        corners = np.asarray(
            [
                [float(words[k + 1]), float(words[k + 2]), float(words[k + 3])]
                for k, w in enumerate(words)
                if w == "vertex"
            ],
            dtype=float,
        ).reshape(-1, 3)
    # Shared corners become one vertex (the decimation needs the mesh's connectivity).
    vertices, inverse = np.unique(corners, axis=0, return_inverse=True)
    return vertices, inverse.reshape(-1, 3).astype(np.int64)


def _dae_corners(dae) -> list:
    """The corners of every triangle of the visual scene's geometries (each instance placed by its nodes' transforms,
    in document order), a k x 3 array per primitive; None without a visual scene."""
    if dae.scene is None:
        return None
    corners = []
    for geometry in dae.scene.objects("geometry"):
        for primitive in geometry.primitives():
            if hasattr(primitive, "triangleset"):  # polygons and polylists, as triangle fans
                primitive = primitive.triangleset()
            if not hasattr(primitive, "vertex_index") or primitive.vertex is None or len(primitive.vertex_index) == 0:
                continue  # lines, or an empty set
            corners.append(np.asarray(primitive.vertex, dtype=float)[np.asarray(primitive.vertex_index).reshape(-1)])
    return corners


def _read_dae(path: str) -> tuple[np.ndarray, np.ndarray]:
    import collada  # imported where used: only a robot with COLLADA visuals needs it

    try:
        with warnings.catch_warnings():  # pycollada builds numpy.matrix objects (a PendingDeprecationWarning)
            warnings.simplefilter("ignore", PendingDeprecationWarning)
            # Unsupported parts (materials, animations, ...) and references to what the file lacks are skipped, as
            # PyBullet skips them: only the geometry is read.
            dae = collada.Collada(path, ignore=[collada.common.DaeUnsupportedError, collada.common.DaeBrokenRefError])
            corners = _dae_corners(dae)
    except OSError:
        raise
    except Exception as exc:  # pycollada's parse errors are of several kinds: one ValueError naming the file
        raise ValueError("%s: not a COLLADA file pycollada can read: %s" % (path, exc)) from None
    if corners is None:
        raise ValueError("%s: no visual scene (<scene>): nothing would be drawn" % path)
    if not corners:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    # Shared corners become one vertex (the decimation needs the mesh's connectivity); <unit> in metres.
    vertices, inverse = np.unique(
        np.concatenate(corners) * (dae.assetInfo.unitmeter or 1.0), axis=0, return_inverse=True
    )
    return vertices, inverse.reshape(-1, 3).astype(np.int64)


def read_mesh(path: str) -> tuple[np.ndarray, np.ndarray]:
    """(vertices n x 3, triangles m x 3 vertex indices) of an OBJ, STL or COLLADA file, in metres where the file says
    its unit (COLLADA); ValueError for another format or a file without triangles."""
    suffix = os.path.splitext(path)[1].lower()
    if suffix not in SIMPLIFIABLE:
        raise ValueError("%s: a mesh of this format is not read here (only %s)" % (path, ", ".join(SIMPLIFIABLE)))
    vertices, faces = {".obj": _read_obj, ".stl": _read_stl, ".dae": _read_dae}[suffix](path)
    if len(faces) == 0 or (faces.size and (faces.min() < 0 or faces.max() >= len(vertices))):
        raise ValueError("%s: no triangles, or faces that name missing vertices" % path)
    return vertices, faces


def write_obj(path: str, vertices: np.ndarray, faces: np.ndarray) -> None:
    """A Wavefront OBJ of the triangles (vertex coordinates as given, 1-based faces)."""
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("".join("v %.9g %.9g %.9g\n" % tuple(v) for v in vertices))
        fh.write("".join("f %d %d %d\n" % (a + 1, b + 1, c + 1) for a, b, c in faces))


def simplified(vertices: np.ndarray, faces: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """The mesh with at most about max_faces triangles (quadric-error decimation); a mesh already that small is
    returned as it is."""
    if max_faces < 4:
        raise ValueError("max_faces must be >= 4, got %r" % (max_faces,))
    if len(faces) <= max_faces:
        return vertices, faces
    import fast_simplification  # imported where used: the simulator without simplified visuals does not need it

    return fast_simplification.simplify(vertices, faces, target_count=int(max_faces))
