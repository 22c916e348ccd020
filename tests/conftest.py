"""Shared fixtures: the real-data folder (skipped when absent) and a small mesh."""

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"

needs_data = pytest.mark.skipif(
    not DATA.is_dir(), reason=f"{DATA} not found: real-data test skipped "
                              "(clone with ../shared beside the project to run it)")


@pytest.fixture(scope="session", autouse=True)
def _private_cache(tmp_path_factory):
    """Keep the on-disk cache (facewrap.io.cache) of every test, and of the commands
    they start, out of the user's home: one fresh folder for the whole run."""
    import os
    old = os.environ.get("FACEWRAP_CACHE_DIR")
    os.environ["FACEWRAP_CACHE_DIR"] = str(tmp_path_factory.mktemp("facewrap-cache"))
    yield
    if old is None:
        os.environ.pop("FACEWRAP_CACHE_DIR", None)
    else:
        os.environ["FACEWRAP_CACHE_DIR"] = old


@pytest.fixture(scope="session")
def data_dir() -> Path:
    if not DATA.is_dir():
        pytest.skip(f"{DATA} not found: real-data test skipped")
    return DATA


@pytest.fixture(scope="session")
def ict_folder(data_dir, tmp_path_factory) -> Path:
    """ICT-FaceKit expanded (neutral + the shapes the tests use) into a temp folder."""
    from facewrap.datasets import expand_ict_facekit
    names = ["jawOpen", "eyeBlink_L", "eyeBlink_R", "mouthSmile_L", "identity000"]
    return expand_ict_facekit(data_dir / "ict-facekit",
                              tmp_path_factory.mktemp("ict") / "FaceXModel", names)


@pytest.fixture
def mixed_mesh():
    """Two quads and a triangle, with a UV seam and per-corner normals."""
    from facewrap.mesh import Mesh
    V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0],
                  [1, 2, 0.5]], dtype=float)
    faces = [[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 6]]
    uvs = np.array([[0, 0], [.5, 0], [0, .5], [.5, .5], [.6, 0], [1, 0], [.6, .5],
                    [1, .5], [.25, 1]])
    face_uvs = [[0, 1, 3, 2], [4, 5, 7, 6], [2, 3, 8]]  # seam between the quads
    normals = np.array([[0, 0, 1.0], [0, 0.3, 0.95]])
    face_normals = [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 1]]
    return Mesh(V, faces, uvs=uvs, face_uvs=face_uvs, normals=normals,
                face_normals=face_normals, face_materials=[0, 0, 1],
                materials=["skin", "lips"], face_groups=[0, 0, 0], groups=["head"],
                mtllib=["head.mtl"])


def facewrap(*argv) -> int:
    """Run ``facewrap ARGV`` in-process; returns the exit status."""
    from facewrap.cli import main
    return main([str(a) for a in argv])


def write_mirrored_obj(source: Path, target: Path) -> Path:
    """``source``'s OBJ text mirrored (x -> -x, each face's corners reversed so it
    still faces outward) into ``target``; every other line as it is."""
    lines = []
    for ln in Path(source).read_text().splitlines(keepends=True):
        if ln.startswith("v "):
            x, y, z = (float(t) for t in ln.split()[1:4])
            ln = f"v {-x!r} {y!r} {z!r}\n"
        elif ln.startswith("f "):
            ln = "f " + " ".join(reversed(ln.split()[1:])) + "\n"
        lines.append(ln)
    Path(target).write_text("".join(lines))
    return Path(target)
