"""The GPU backend from Python (skipped without one): GPU == CPU pair for pair, TOIs bit for bit;
positions from CUDA arrays (PyTorch, CuPy: __cuda_array_interface__ and DLPack; float64 and float32)
read in place;
contacts left on the device equal the host ones."""
import numpy as np
import pytest

import lwsccd

pytestmark = pytest.mark.skipif(
    not lwsccd.gpu_available(),
    reason="SKIPPED: no GPU backend in this build or no CUDA device" if lwsccd.built_with_gpu()
    else "SKIPPED: this build of lwsccd has no GPU backend",
)


@pytest.fixture(scope="module")
def scene():
    sim = lwsccd.ClothBallSimulation(20000)
    return sim, [sim.next_step() for _ in range(3)]


def pipelines(sim, **kw):
    make = lambda device: lwsccd.Pipeline(sim.faces, bodies=sim.face_body, self_collides=sim.body_self_collides,
                                          device=device, **kw)
    return make("gpu"), make("cpu")


def same(a, b):
    assert np.array_equal(a.vertex_face, b.vertex_face) and np.array_equal(a.edge_edge, b.edge_edge)
    assert a.earliest_toi == b.earliest_toi and a.gave_up == b.gave_up


@pytest.mark.parametrize("policy", [{}, dict(bv="obb", scheduler="static"), dict(precision="float"), dict(mode="earliest"),
                                    dict(method="filtered-inclusion", scheduler="gproximity"), dict(fp64_ratio=64)])
def test_gpu_equals_cpu(scene, policy):
    sim, steps = scene
    gpu, cpu = pipelines(sim, **policy)
    assert gpu.device == "gpu" and cpu.device == "cpu"
    contacts = 0
    for x0, x1 in steps:
        g, c = gpu.step(x0, x1), cpu.step(x0, x1)
        same(g, c)
        contacts += g.num_contacts
    assert contacts > 0 or policy.get("mode") == "earliest"


def device_array_modules():
    mods = []
    try:
        import torch
        if torch.cuda.is_available():
            mods.append(("torch", lambda a: torch.from_numpy(a).cuda(), torch))
    except ImportError:
        pass
    try:
        import cupy
        mods.append(("cupy", lambda a: cupy.asarray(a), cupy))
    except ImportError:
        pass
    return mods


@pytest.mark.parametrize("name,to_device,module", device_array_modules() or [pytest.param(None, None, None, marks=pytest.mark.skip(
    reason="SKIPPED: neither PyTorch with CUDA nor CuPy is installed"))])
def test_device_positions_and_device_results(scene, name, to_device, module):
    sim, steps = scene
    gpu, cpu = pipelines(sim)
    resident, _ = pipelines(sim)
    for x0, x1 in steps:
        expected = cpu.step(x0, x1)
        d0, d1 = to_device(x0), to_device(x1)
        same(gpu.step(d0, d1), expected)  # __cuda_array_interface__ (both libraries have it)
        r = resident.step(d0, d1, on_device=True)
        assert isinstance(r, lwsccd.DeviceStepResult) and r.earliest_toi == expected.earliest_toi
        pairs = np.asarray(module.from_dlpack(r.vf_pairs).cpu().numpy() if name == "torch" else module.asnumpy(module.from_dlpack(r.vf_pairs)))
        toi = np.asarray(module.from_dlpack(r.vf_toi).cpu().numpy() if name == "torch" else module.asnumpy(module.from_dlpack(r.vf_toi)))
        assert np.array_equal(pairs[:, 0], expected.vertex_face["vertex"]) and np.array_equal(pairs[:, 1], expected.vertex_face["face"])
        assert np.array_equal(toi, expected.vertex_face["toi"])
        eep = module.from_dlpack(r.ee_pairs)
        eep = eep.cpu().numpy() if name == "torch" else module.asnumpy(eep)
        assert np.array_equal(eep[:, 0], expected.edge_edge["edge_a"])


def test_dlpack_only_input(scene):
    torch = pytest.importorskip("torch")
    if not torch.cuda.is_available():
        pytest.skip("SKIPPED: PyTorch without CUDA")
    sim, steps = scene
    gpu, cpu = pipelines(sim)

    class DlpackOnly:  # what JAX gives: DLPack, no __cuda_array_interface__
        def __init__(self, t):
            self.t, self.shape, self.dtype = t, tuple(t.shape), t.dtype

        def __dlpack__(self, **kw):
            return self.t.__dlpack__(**kw)

        def __dlpack_device__(self):
            return self.t.__dlpack_device__()

    x0, x1 = steps[0]
    same(gpu.step(DlpackOnly(torch.from_numpy(x0).cuda()), DlpackOnly(torch.from_numpy(x1).cuda())), cpu.step(x0, x1))
    f0, f1 = x0.astype(np.float32), x1.astype(np.float32)
    same(gpu.step(DlpackOnly(torch.from_numpy(f0).cuda()), DlpackOnly(torch.from_numpy(f1).cuda())),
         cpu.step(f0.astype(np.float64), f1.astype(np.float64)))
    with pytest.raises(TypeError, match="float64 or float32"):
        gpu.step(torch.from_numpy(x0).half().cuda(), torch.from_numpy(x1).half().cuda())


@pytest.mark.parametrize("name,to_device,module", device_array_modules() or [pytest.param(None, None, None, marks=pytest.mark.skip(
    reason="SKIPPED: neither PyTorch with CUDA nor CuPy is installed"))])
def test_float32_positions_on_the_device(scene, name, to_device, module):
    # PyTorch's default dtype: read in place, widened exactly on the device; the answers are the
    # CPU backend's on the float32 values (as float64), pair for pair.
    sim, steps = scene
    gpu, cpu = pipelines(sim)
    contacts = 0
    for x0, x1 in steps:
        f0, f1 = x0.astype(np.float32), x1.astype(np.float32)
        expected = cpu.step(f0.astype(np.float64), f1.astype(np.float64))
        same(gpu.step(to_device(f0), to_device(f1)), expected)
        same(gpu.step(f0, f1), expected)  # float32 NumPy: uploaded as float32
        r = gpu.step(to_device(f0), to_device(f1), on_device=True)
        assert r.earliest_toi == expected.earliest_toi
        assert r.stats["hits_vf"] + r.stats["hits_ee"] == expected.num_contacts
        assert all(r.stats["device_memory"][part] > 0 for part in ("mesh", "bvh", "feature_boxes", "narrow_work"))
        contacts += expected.num_contacts
    assert contacts > 0
    x0, x1 = steps[0]
    with pytest.raises(TypeError, match="same dtype"):
        gpu.step(to_device(x0), to_device(x1.astype(np.float32)))


def test_devices_one_gpu_equals_cpu(scene):
    """devices=[0]: the split pipeline over one GPU (NCCL) answers as the CPU does."""
    if not lwsccd.built_with_nccl():
        with pytest.raises(RuntimeError, match="NCCL"):
            lwsccd.Pipeline(scene[0].faces, devices=[0])
        pytest.skip("SKIPPED: this build of lwsccd has no NCCL (devices= refused, as checked)")
    sim, steps = scene
    split = lwsccd.Pipeline(sim.faces, bodies=sim.face_body, self_collides=sim.body_self_collides, devices=[0])
    cpu = lwsccd.Pipeline(sim.faces, bodies=sim.face_body, self_collides=sim.body_self_collides, device="cpu")
    assert split.device == "gpu"
    for x0, x1 in steps:
        same(split.step(x0, x1), cpu.step(x0, x1))


def test_devices_two_gpus_equal_one(scene):
    """devices=[0, 1]: the step split over two GPUs, pair for pair the one-GPU pipeline's contacts."""
    if not lwsccd.built_with_nccl() or lwsccd.gpu_count() < 2:
        pytest.skip("SKIPPED: needs NCCL in this build and two CUDA devices, found %d" % lwsccd.gpu_count())
    sim, steps = scene
    split, one = (lwsccd.Pipeline(sim.faces, bodies=sim.face_body, self_collides=sim.body_self_collides, **kw)
                  for kw in (dict(devices=[0, 1]), dict(device="gpu")))
    contacts = 0
    for x0, x1 in steps:
        s, o = split.step(x0, x1), one.step(x0, x1)
        same(s, o)
        contacts += s.num_contacts
    assert contacts > 0


def test_bad_devices_on_a_gpu():
    if not lwsccd.built_with_nccl():
        pytest.skip("SKIPPED: this build of lwsccd has no NCCL")
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    with pytest.raises(ValueError, match="devices.*not one of the"):
        lwsccd.Pipeline(faces, devices=[lwsccd.gpu_count()])
    with pytest.raises(ValueError, match="devices.*listed twice"):
        lwsccd.Pipeline(faces, devices=[0, 0])
    with pytest.raises(ValueError, match="devices.*default policies.*obb"):
        lwsccd.Pipeline(faces, devices=[0], bv="obb")
    with pytest.raises(ValueError, match="does not stream"):
        lwsccd.Pipeline(faces, devices=[0], part_pairs=1000)


def test_non_finite_positions_in_a_later_step(scene):
    """A NaN coordinate is refused in a step after the first (the GPU's refit), on both backends,
    and the next step answers as before."""
    sim, steps = scene
    x0, x1 = steps[0]
    bad = x1.copy()
    bad[len(bad) // 2, 1] = np.nan
    gpu, cpu = pipelines(sim)
    for p in (gpu, cpu):
        p.step(x0, x1)
        with pytest.raises(ValueError, match="(?i)nan|finite"):
            p.step(x0, bad)
    same(gpu.step(x0, x1), cpu.step(x0, x1))
