"""Bad input raises a clear Python exception with the library's message."""
import numpy as np
import pytest

import lwsccd

FACES = np.array([[0, 1, 2], [1, 3, 2]])
X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=np.float64)


def pipeline(**kw):
    return lwsccd.Pipeline(FACES, device="cpu", **kw)


def test_positions_of_the_wrong_shape_or_dtype():
    p = pipeline()
    with pytest.raises(ValueError, match=r"shape \(num_vertices, 3\)"):
        p.step(X[:, :2], X[:, :2])
    with pytest.raises(ValueError, match="3 points for a mesh of 4 vertices"):
        p.step(X[:3], X[:3])
    with pytest.raises(TypeError, match="real numbers"):
        p.step(X.astype(complex), X)
    with pytest.raises(TypeError, match="real numbers"):
        p.step(np.array([["a"] * 3] * 4), X)
    with pytest.raises(ValueError, match="both host arrays or both CUDA arrays|device memory"):
        p.step(X, X, on_device=True)


def test_non_finite_positions():
    bad = X.copy()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match="(?i)nan|finite"):
        pipeline().step(X, bad)


def test_float32_and_fortran_order_positions_are_converted():
    p = pipeline()
    r = p.step(np.asfortranarray(X.astype(np.float32)), X + 0.5)
    assert r.num_contacts == 0 and r.earliest_toi == 1.0


def test_bad_faces_and_bodies():
    with pytest.raises(ValueError, match="face 1"):
        lwsccd.Pipeline(np.array([[0, 1, 2], [1, 1, 2]]), device="cpu")
    with pytest.raises(ValueError, match="outside"):
        lwsccd.Pipeline(FACES, num_vertices=3, device="cpu")
    with pytest.raises(TypeError, match="integers"):
        lwsccd.Pipeline(FACES.astype(float), device="cpu")
    with pytest.raises(ValueError, match="shape"):
        lwsccd.Pipeline(FACES[:, :2], device="cpu")
    with pytest.raises(ValueError, match="bodies"):
        lwsccd.Pipeline(FACES, bodies=[0], device="cpu")


def test_bad_policies_and_parameters_name_what_is_accepted():
    with pytest.raises(ValueError, match="bv.*'sphere'.*aabb, obb"):
        pipeline(bv="sphere")
    with pytest.raises(ValueError, match="method.*accepted: certified"):
        pipeline(method="exact")
    with pytest.raises(ValueError, match="mode.*contacts, earliest, set"):
        pipeline(mode="all")
    with pytest.raises(ValueError, match="device.*auto, gpu, cpu"):
        lwsccd.Pipeline(FACES, device="tpu")
    with pytest.raises(ValueError, match="tolerance"):
        pipeline(tolerance=2.0)
    with pytest.raises(ValueError, match="min_separation"):
        pipeline(min_separation=-1.0)


@pytest.mark.skipif(lwsccd.gpu_available(), reason="a GPU is present")
def test_gpu_without_a_gpu_is_a_runtime_error():
    with pytest.raises(RuntimeError, match="GPU"):
        lwsccd.Pipeline(FACES, device="gpu")


def test_bad_devices():
    with pytest.raises(ValueError, match="devices.*at least one"):
        lwsccd.Pipeline(FACES, devices=[])
    with pytest.raises(ValueError, match="devices.*device='gpu' or 'auto'.*'cpu'"):
        pipeline(devices=[0])


@pytest.mark.skipif(lwsccd.gpu_available(), reason="a GPU is present")
def test_devices_without_a_gpu_is_a_runtime_error():
    with pytest.raises(RuntimeError, match="GPU"):
        lwsccd.Pipeline(FACES, devices=[0])


def test_files(tmp_path):
    with pytest.raises(FileNotFoundError):
        lwsccd.load_mesh(str(tmp_path / "missing.obj"))
    with pytest.raises(FileNotFoundError):
        lwsccd.load_scene(str(tmp_path / "no-scene"))
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
    with pytest.raises(ValueError, match=r"bad\.obj.*line 4"):
        lwsccd.load_mesh(str(bad))
