"""The Python package on the CPU backend: contacts, modes, bodies, and agreement with the C++
main program on the real scenes."""
import json
import subprocess

import numpy as np
import pytest

import lwsccd


@pytest.fixture(scope="module")
def cloth_steps():
    sim = lwsccd.ClothBallSimulation(3000)
    steps = [sim.next_step() for _ in range(3)]
    return sim, steps


def cpu_pipeline(sim, **kw):
    return lwsccd.Pipeline(sim.faces, bodies=sim.face_body, self_collides=sim.body_self_collides, device="cpu", **kw)


def test_contacts_are_sorted_structured_and_consistent(cloth_steps):
    sim, steps = cloth_steps
    ccd = cpu_pipeline(sim)
    total = 0
    for x0, x1 in steps:
        r = ccd.step(x0, x1)
        assert r.vertex_face.dtype == lwsccd.VERTEX_FACE_DTYPE and r.edge_edge.dtype == lwsccd.EDGE_EDGE_DTYPE
        vf, ee = r.vertex_face, r.edge_edge
        assert np.all((vf["toi"] >= 0) & (vf["toi"] <= 1)) and np.all((ee["toi"] >= 0) & (ee["toi"] <= 1))
        assert np.all(np.diff(vf["vertex"] * len(ccd.faces) + vf["face"]) > 0), "vertex-face pairs sorted, no repeats"
        assert np.all(ee["edge_a"] < ee["edge_b"])
        # A vertex is never tested against a face it belongs to; edges in a pair share no vertex.
        assert not np.any(ccd.faces[vf["face"]] == vf["vertex"][:, None])
        ea, eb = ccd.edges[ee["edge_a"]], ccd.edges[ee["edge_b"]]
        assert not np.any((ea[:, :, None] == eb[:, None, :]).any(axis=(1, 2)))
        tois = np.concatenate([vf["toi"], ee["toi"]])
        assert r.earliest_toi == (tois.min() if len(tois) else 1.0)
        assert r.stats["hits_vf"] == len(vf) and r.stats["hits_ee"] == len(ee)
        assert r.num_contacts == len(vf) + len(ee)
        # Device memory by purpose: the GPU's parts, none held by the CPU backend.
        memory = r.stats["device_memory"]
        assert list(memory) == ["mesh", "bvh", "feature_boxes", "candidates", "front", "scheduler", "feature_pairs",
                                "narrow_hits", "narrow_work", "other"]
        assert sum(memory.values()) == 0
        assert r.stats["device_allocations"] == 0  # (no device memory on the CPU backend)
        total += r.num_contacts
    assert total > 0, "the built-in scene collides"


def test_float32_positions_are_taken_as_given(cloth_steps):
    # Float32 arrays are not converted on the way in: the pipeline widens them exactly, so the
    # answers are those for the float32 values, as float64 gives them.
    sim, steps = cloth_steps
    f32, f64 = cpu_pipeline(sim), cpu_pipeline(sim)
    contacts = 0
    for x0, x1 in steps:
        a0, a1 = x0.astype(np.float32), x1.astype(np.float32)
        r, expected = f32.step(a0, a1), f64.step(a0.astype(np.float64), a1.astype(np.float64))
        assert np.array_equal(r.vertex_face, expected.vertex_face) and np.array_equal(r.edge_edge, expected.edge_edge)
        assert r.earliest_toi == expected.earliest_toi
        contacts += r.num_contacts
    assert contacts > 0
    x0, x1 = steps[0]
    a1 = x1.astype(np.float32)  # two dtypes: both taken as float64 (the float32 one exactly)
    mixed, expected = f32.step(x0, a1), f64.step(x0, a1.astype(np.float64))
    assert np.array_equal(mixed.vertex_face, expected.vertex_face) and np.array_equal(mixed.edge_edge, expected.edge_edge)


def test_rigid_ball_has_no_self_pairs(cloth_steps):
    sim, steps = cloth_steps
    ccd = cpu_pipeline(sim)
    ball_faces = np.flatnonzero(sim.face_body == 1)
    ball_vertices = np.unique(sim.faces[ball_faces])
    for x0, x1 in steps:
        vf = ccd.step(x0, x1).vertex_face
        inside = np.isin(vf["vertex"], ball_vertices) & np.isin(vf["face"], ball_faces)
        assert not inside.any()


def test_modes_agree(cloth_steps):
    sim, steps = cloth_steps
    contacts, earliest, pair_set = cpu_pipeline(sim), cpu_pipeline(sim, mode="earliest"), cpu_pipeline(sim, mode="set")
    for x0, x1 in steps:
        c, e, s = contacts.step(x0, x1), earliest.step(x0, x1), pair_set.step(x0, x1)
        assert len(e.vertex_face) == 0 and len(e.edge_edge) == 0
        assert e.earliest_toi == c.earliest_toi
        for a, b in ((s.vertex_face, c.vertex_face), (s.edge_edge, c.edge_edge)):
            names = a.dtype.names[:2]
            assert np.array_equal(a[list(names)], b[list(names)]), "mode set finds the same pairs"
            assert np.all(a["toi"] <= b["toi"]), "with lower bounds of their TOIs"


def test_parts_give_the_whole_steps_contacts(cloth_steps):
    sim, steps = cloth_steps
    whole, parts = cpu_pipeline(sim), cpu_pipeline(sim, part_pairs=200)
    for x0, x1 in steps:
        w, p = whole.step(x0, x1), parts.step(x0, x1)
        assert np.array_equal(p.vertex_face, w.vertex_face) and np.array_equal(p.edge_edge, w.edge_edge)
        assert p.earliest_toi == w.earliest_toi
        assert p.stats["narrow_parts"] > 1 and w.stats["narrow_parts"] == 0
    with pytest.raises(TypeError):
        cpu_pipeline(sim, part_pairs=-1)


def test_thread_counts_give_the_same_contacts(cloth_steps):
    # The CPU backend is the oracle: one thread or several, the same contacts bit for bit.
    sim, steps = cloth_steps
    one, three = cpu_pipeline(sim, threads=1), cpu_pipeline(sim, threads=3)
    for x0, x1 in steps:
        a, b = one.step(x0, x1), three.step(x0, x1)
        assert np.array_equal(a.vertex_face, b.vertex_face) and np.array_equal(a.edge_edge, b.edge_edge)
        assert a.earliest_toi == b.earliest_toi and len(a.vertex_face) + len(a.edge_edge) > 0
    with pytest.raises(ValueError, match="threads"):
        cpu_pipeline(sim, threads=-2)
    # fp64_ratio plans the GPU's narrow phase; the CPU backend ignores it, a negative one is refused.
    planned = cpu_pipeline(sim, fp64_ratio=64).step(*steps[0])
    reference = cpu_pipeline(sim).step(*steps[0])
    assert np.array_equal(planned.vertex_face, reference.vertex_face) and np.array_equal(planned.edge_edge, reference.edge_edge)
    with pytest.raises(ValueError, match="fp64_ratio"):
        cpu_pipeline(sim, fp64_ratio=-1)


def test_restart_from_root_gives_the_same_contacts(cloth_steps):
    sim, steps = cloth_steps
    tracked, restarted = cpu_pipeline(sim), cpu_pipeline(sim)
    for x0, x1 in steps:
        restarted.restart_from_root()
        a, b = tracked.step(x0, x1), restarted.step(x0, x1)
        assert b.stats["restarted_from_root"]
        assert np.array_equal(a.vertex_face, b.vertex_face) and np.array_equal(a.edge_edge, b.edge_edge)
    assert not a.stats["restarted_from_root"]  # (the third step: from the front)


def test_obb_finds_a_subset_with_the_same_tois(cloth_steps):
    # OBBs cull more triangle pairs than AABBs; the narrow phase is the same, so every pair an
    # OBB pipeline reports is the AABB pipeline's, with the same TOI.
    sim, steps = cloth_steps
    aabb, obb = cpu_pipeline(sim), cpu_pipeline(sim, bv="obb")
    for x0, x1 in steps:
        a, o = aabb.step(x0, x1), obb.step(x0, x1)
        for big, small in ((a.vertex_face, o.vertex_face), (a.edge_edge, o.edge_edge)):
            lookup = {(int(p), int(q)): t for p, q, t in big.tolist()}
            for p, q, t in small.tolist():
                assert lookup[(p, q)] == t


def test_main_program_agrees_on_real_scenes(data_dir, ccd_program):
    for scene in ("cloth-funnel", "armadillo-rollers"):
        folder = data_dir / "scenes" / scene
        out = subprocess.run([ccd_program, str(folder), "--device", "cpu", "--json"], capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        expected = json.loads(out.stdout)["steps"][0]
        faces, x0, x1 = lwsccd.load_scene(str(folder))
        r = lwsccd.Pipeline(faces, num_vertices=len(x0), device="cpu").step(x0, x1)
        assert len(r.vertex_face) == expected["vf_hits"]
        assert len(r.edge_edge) == expected["ee_hits"]
        assert r.earliest_toi == expected["earliest_toi"]
        assert r.stats["triangle_pairs"] == expected["triangle_pairs"]
        assert r.stats["feature_pairs_vf"] == expected["vf_pairs"]
        assert r.stats["feature_pairs_ee"] == expected["ee_pairs"]


def read_png_rgb(path):
    """The RGB pixels of a PNG the library wrote (8-bit RGB, filter 0 scanlines)."""
    import zlib

    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    idat, pos = b"", 8
    while pos < len(data):
        length, kind = int.from_bytes(data[pos:pos + 4], "big"), data[pos + 4:pos + 8]
        if kind == b"IDAT":
            idat += data[pos + 8:pos + 8 + length]
        pos += 12 + length
    raw = np.frombuffer(zlib.decompress(idat), dtype=np.uint8).reshape(height, 1 + width * 3)
    assert np.all(raw[:, 0] == 0)
    return raw[:, 1:].reshape(height, width, 3).astype(int)


def red_pixels(rgb):
    return int(((rgb[:, :, 0] > 150) & (rgb[:, :, 1] < 80) & (rgb[:, :, 2] < 80)).sum())


def test_render_draws_the_contacts_in_red(cloth_steps, tmp_path):
    sim, steps = cloth_steps
    ccd = cpu_pipeline(sim)
    x0, x1 = steps[-1]
    r = ccd.step(x0, x1)
    assert r.num_contacts > 0
    picture = read_png_rgb(ccd.render(str(tmp_path / "step.png"), x0, x1, r, size=(160, 120)))
    assert picture.shape == (120, 160, 3)
    assert red_pixels(picture) > 0, "colliding triangles are drawn in red"
    still = read_png_rgb(ccd.render(str(tmp_path / "still.png"), x0, x0, size=(160, 120)))  # no motion, no contact
    assert red_pixels(still) == 0 and len(np.unique(still.reshape(-1, 3), axis=0)) > 10
    with pytest.raises(ValueError, match="size"):
        ccd.render(str(tmp_path / "bad.png"), x0, x1, r, size=(0, 10))
    with pytest.raises(RuntimeError, match="cannot write"):
        ccd.render(str(tmp_path / "missing-folder" / "x.png"), x0, x1, r, size=(16, 12))
