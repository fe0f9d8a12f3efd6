"""Loaders: polygons triangulated, steps and sequences of one topology."""
import numpy as np
import pytest

import lwsccd

QUAD = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n"


def test_quad_is_triangulated(tmp_path):
    path = tmp_path / "quad.obj"
    path.write_text(QUAD)
    vertices, faces = lwsccd.load_mesh(str(path))
    assert vertices.shape == (4, 3) and vertices.dtype == np.float64
    assert faces.shape == (2, 3) and faces.dtype == np.int64
    assert sorted(np.unique(faces).tolist()) == [0, 1, 2, 3]


def test_step_and_sequence(tmp_path):
    for k, z in enumerate((0.0, 0.5, 1.0)):
        (tmp_path / f"frame{k}.obj").write_text(QUAD.replace("v 0 0 0", f"v 0 0 {z}"))
    faces, x0, x1 = lwsccd.load_step(str(tmp_path / "frame0.obj"), str(tmp_path / "frame1.obj"))
    assert faces.shape == (2, 3) and x0[0, 2] == 0.0 and x1[0, 2] == 0.5
    faces, frames = lwsccd.load_sequence(str(tmp_path))
    assert len(frames) == 3 and frames[2][0, 2] == 1.0
    r = lwsccd.Pipeline(faces, device="cpu").step(frames[0], frames[1])
    assert r.num_contacts == 0


def test_scene_folder(data_dir):
    faces, x0, x1 = lwsccd.load_scene(str(data_dir / "scenes" / "cloth-funnel"))
    assert faces.shape[1] == 3 and x0.shape == x1.shape and x0.shape[1] == 3
