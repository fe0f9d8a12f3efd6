"""lwsccd.ipc (ipc-toolkit's CCD calls on lwsccd) and lwsccd's TOIs against an exact oracle
(exact_ccd: rational arithmetic). ipctk, where installed, is compared beside it."""
import random
from fractions import Fraction

import numpy as np
import pytest

import lwsccd
from exact_ccd import Degenerate, edge_edge_toi, vertex_face_toi

TOL = 1e-6

try:
    import ipctk  # noqa: F401
    HAVE_IPCTK = True
except ImportError:
    HAVE_IPCTK = False


def two_triangles(drop: float):
    """A fixed triangle at z = 0 and a smaller one above it moving down by `drop`."""
    v0 = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0.3, 0.3, 1.0], [0.8, 0.3, 1.0], [0.3, 0.8, 1.2]], dtype=np.float64)
    v1 = v0.copy()
    v1[3:, 2] -= drop
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    edges = np.array([[0, 1], [1, 2], [0, 2], [3, 4], [4, 5], [3, 5]])
    return v0, v1, edges, faces


class DuckMesh:
    """What lwsccd.ipc reads of an ipctk.CollisionMesh."""

    def __init__(self, num_vertices, edges, faces):
        self.num_vertices, self.edges, self.faces = num_vertices, edges, faces


def exact_pair(kind, pair, x0, x1, faces, edges):
    """The exact TOI interval of one contact lwsccd reported (vertex-face or edge-edge)."""
    if kind == "vf":
        v, f = int(pair["vertex"]), int(pair["face"])
        pts = [v] + [int(i) for i in faces[f]]
    else:
        pts = [int(i) for i in edges[int(pair["edge_a"])]] + [int(i) for i in edges[int(pair["edge_b"])]]
    args = []
    for i in pts:
        args += [tuple(x0[i]), tuple(x1[i])]
    return (vertex_face_toi if kind == "vf" else edge_edge_toi)(*args)


def check_lower_bound_within_tolerance(toi, exact):
    """exact - TOL <= toi <= exact, decided on the exact interval (lo, hi)."""
    lo, hi = exact
    assert Fraction(toi) <= lo or (lo == hi and Fraction(toi) <= hi), f"TOI {toi!r} after the exact contact [{float(lo)}, {float(hi)}]"
    assert Fraction(toi) >= hi - Fraction(TOL), f"TOI {toi!r} more than the tolerance before the exact contact {float(hi)}"


def test_stepsize_is_the_rescaled_certified_contact_and_one_when_free():
    v0, v1, edges, faces = two_triangles(2.0)  # falls through the fixed triangle
    step = lwsccd.ipc.compute_collision_free_stepsize((v0, edges, faces), v0, v1)
    exact = vertex_face_toi(v0[3], v1[3], v0[0], v1[0], v0[1], v1[1], v0[2], v1[2])
    assert exact == (Fraction(1, 2), Fraction(1, 2))  # vertex 3 reaches z = 0 at t = 1/2 inside
    toi = step / 0.8
    check_lower_bound_within_tolerance(toi, exact)
    assert step == pytest.approx(0.4, abs=1e-6)
    assert not lwsccd.ipc.is_step_collision_free((v0, edges, faces), v0, v1)
    # Stopping short of the fixed triangle: a full step, collision free.
    v0, v1, edges, faces = two_triangles(0.5)
    assert lwsccd.ipc.compute_collision_free_stepsize((v0, edges, faces), v0, v1) == 1.0
    assert lwsccd.ipc.is_step_collision_free((v0, edges, faces), v0, v1)
    # min_distance: coming within 0.6 of the fixed triangle counts.
    assert not lwsccd.ipc.is_step_collision_free((v0, edges, faces), v0, v1, min_distance=0.6)
    assert lwsccd.ipc.compute_collision_free_stepsize((v0, edges, faces), v0, v1, min_distance=0.6) < 1.0
    # The rescaling: asked for, or read from an ipctk-like narrow phase; a duck-typed mesh.
    v0, v1, edges, faces = two_triangles(2.0)

    class Ccd:
        tolerance, conservative_rescaling = 1e-6, 0.5

    mesh = DuckMesh(6, edges, faces)
    assert lwsccd.ipc.compute_collision_free_stepsize(mesh, v0, v1, narrow_phase_ccd=Ccd()) == pytest.approx(0.25, abs=1e-6)
    assert lwsccd.ipc.compute_collision_free_stepsize(mesh, v0, v1, conservative_rescaling=1.0) == pytest.approx(0.5, abs=1e-6)


def test_pipelines_are_kept_per_topology_and_settings():
    """A line search's repeated calls reuse one pipeline; another topology, other settings or an
    array changed in place get their own; at most four are kept; clear_cache drops them."""
    from lwsccd import ipc

    ipc.clear_cache()
    v0, v1, edges, faces = two_triangles(2.0)
    first = ipc._pipeline((v0, edges, faces), "earliest", 0.0, TOL, 16384, "cpu")
    assert ipc._pipeline((v0, edges.copy(), faces.copy()), "earliest", 0.0, TOL, 16384, "cpu") is first
    assert ipc._pipeline((v0, edges, faces), "set", 0.0, TOL, 16384, "cpu") is not first
    assert ipc._pipeline((v0, edges, faces.astype(np.int32)), "earliest", 0.0, TOL, 16384, "cpu") is not first
    changed = faces.copy()
    changed[1] = [3, 5, 4]  # the same vertices, another orientation: another topology's faces
    other = ipc._pipeline((v0, edges, changed), "earliest", 0.0, TOL, 16384, "cpu")
    assert other is not first
    faces_in_place = faces.copy()
    kept = ipc._pipeline((v0, edges, faces_in_place), "earliest", 0.0, TOL, 16384, "cpu")
    assert kept is first  # the most recently used are kept
    faces_in_place[1] = [3, 5, 4]  # changed in place after the pipeline was made: compared by value
    assert ipc._pipeline((v0, edges, faces_in_place), "earliest", 0.0, TOL, 16384, "cpu") is other
    assert len(ipc._CACHE) == 4
    ipc._pipeline((v0, edges, faces), "contacts", 0.0, TOL, 16384, "cpu")
    assert len(ipc._CACHE) == 4
    ipc.clear_cache()
    assert not ipc._CACHE
    # The answers do not depend on which pipeline served them.
    assert ipc.compute_collision_free_stepsize((v0, edges, faces), v0, v1) == \
        ipc.compute_collision_free_stepsize((v0, edges, changed), v0, v1)


def test_bad_input_is_refused_with_a_clear_error():
    v0, v1, edges, faces = two_triangles(2.0)
    f = lwsccd.ipc.compute_collision_free_stepsize
    with pytest.raises(ValueError, match="belong to no face"):
        f((v0, np.vstack([edges, [[0, 4]]]), faces), v0, v1)  # a codimensional edge
    with pytest.raises(ValueError, match="belong to no face"):
        f((np.vstack([v0, [[5, 5, 5]]]), edges, faces), np.vstack([v0, [[5, 5, 5]]]), np.vstack([v1, [[5, 5, 5]]]))
    # Edges the extension looks up: indices outside the mesh, either sign, count as in no face.
    for outside in ([0, 6], [-1, 2], [2**40, 1]):
        with pytest.raises(ValueError, match="1 edges belong to no face"):
            f((v0, np.vstack([edges, [outside]]), faces), v0, v1)
    with pytest.raises(ValueError, match="edges must have shape"):
        f((v0, np.hstack([edges, edges[:, :1]]), faces), v0, v1)
    with pytest.raises(TypeError, match="must be integers"):
        f((v0, edges.astype(np.float64), faces), v0, v1)
    with pytest.raises(TypeError, match="must be integers"):
        f((v0, edges, faces.astype(np.float32)), v0, v1)
    with pytest.raises(ValueError, match="face index is outside"):
        f((v0, edges, np.vstack([faces, [[0, 1, 6]]])), v0, v1)
    with pytest.raises(ValueError, match="faces must have shape"):
        f((v0, edges, faces[:, :2]), v0, v1)
    # A refused mesh leaves no pipeline behind: the cache holds only the meshes that passed.
    lwsccd.ipc.clear_cache()
    with pytest.raises(ValueError, match="belong to no face"):
        f((v0, np.vstack([edges, [[0, 4]]]), faces), v0, v1)
    assert not lwsccd.ipc._CACHE
    with pytest.raises(ValueError, match="codimensional"):
        m = DuckMesh(6, edges, faces)
        m.num_codim_vertices = 2
        f(m, v0, v1)
    with pytest.raises(TypeError, match="CollisionMesh"):
        f("mesh", v0, v1)
    with pytest.raises(ValueError, match="points for a mesh of 6"):
        f((v0, edges, faces), v0[:5], v1[:5])
    bad = v1.copy()
    bad[4, 1] = np.nan
    with pytest.raises(ValueError):
        f((v0, edges, faces), v0, bad)
    with pytest.raises(ValueError, match="min_distance"):
        f((v0, edges, faces), v0, v1, min_distance=-1)
    with pytest.raises(ValueError, match="conservative_rescaling"):
        f((v0, edges, faces), v0, v1, conservative_rescaling=0)
    with pytest.raises(ValueError, match="max_iterations"):
        f((v0, edges, faces), v0, v1, max_iterations=0)


def fuzz_pair_of_triangles(rng: random.Random):
    """Two triangles, the second's vertex (or edge) aimed at a random point of the first at a
    random time, nudged by a tiny amount either way (near contacts, grazes, near misses)."""
    tri = [[rng.uniform(-1, 1) for _ in range(3)] for _ in range(3)]
    x0 = np.array(tri + [[rng.uniform(-1, 1) for _ in range(3)] for _ in range(3)], dtype=np.float64)
    x1 = x0 + np.array([[rng.uniform(-0.05, 0.05) for _ in range(3)] for _ in range(3)] + [[0, 0, 0]] * 3)
    # The moving triangle's first vertex passes through a point of the fixed one at time t_hit.
    w = [rng.random() for _ in range(3)]
    s = sum(w)
    target = sum((w[k] / s) * x0[k] for k in range(3))
    t_hit = rng.uniform(0.05, 0.95)
    direction = np.array([rng.uniform(-1, 1) for _ in range(3)])
    start = target - t_hit * direction + np.array([rng.uniform(-1e-7, 1e-7) for _ in range(3)])
    shift = start - x0[3]
    x0[3:] += shift
    x1[3:] = x0[3:] + direction
    return x0, x1


def test_fuzzed_near_contacts_against_the_exact_oracle():
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    rng = random.Random(7)
    checked = degenerate = contacts = 0
    for _ in range(60):
        x0, x1 = fuzz_pair_of_triangles(rng)
        p = lwsccd.Pipeline(faces, device="cpu")
        r = p.step(x0, x1)
        edges = p.edges
        reported = {("vf", int(h["vertex"]), int(h["face"])): h for h in r.vertex_face}
        reported.update({("ee", int(h["edge_a"]), int(h["edge_b"])): h for h in r.edge_edge})
        # Every non-incident pair: an exact contact must be reported, with its TOI a lower bound
        # within the tolerance.
        pairs = [("vf", v, f) for f in range(2) for v in range(6) if v not in faces[f]]
        pairs += [("ee", a, b) for a in range(len(edges)) for b in range(a + 1, len(edges))
                  if not set(edges[a]) & set(edges[b])]
        for kind, i, j in pairs:
            record = {"vertex": i, "face": j} if kind == "vf" else {"edge_a": i, "edge_b": j}
            try:
                exact = exact_pair(kind, record, x0, x1, faces, edges)
            except Degenerate:
                degenerate += 1
                continue
            checked += 1
            if exact is None:
                continue
            contacts += 1
            assert (kind, i, j) in reported, f"{kind} pair ({i}, {j}) touches at {float(exact[0])} and was missed"
            check_lower_bound_within_tolerance(float(reported[(kind, i, j)]["toi"]), exact)
            assert r.earliest_toi <= exact[1]
    print(f"\nfuzzed near contacts: {checked} pairs decided exactly, {contacts} contacts, {degenerate} degenerate skipped")
    assert contacts > 20


@pytest.mark.parametrize("scene", ["cloth-funnel", "armadillo-rollers", "cloth-ball"])
def test_scene_contacts_against_the_exact_oracle(data_dir, scene):
    faces, x0, x1 = lwsccd.load_scene(str(data_dir / "scenes" / scene))
    p = lwsccd.Pipeline(faces, device="cpu")
    r = p.step(x0, x1)
    edges = p.edges
    contacts = [("vf", h) for h in r.vertex_face] + [("ee", h) for h in r.edge_edge]
    assert contacts
    # cloth-funnel: every contact; the larger scenes: the 10 earliest and 30 more at random.
    if scene != "cloth-funnel":
        contacts.sort(key=lambda c: float(c[1]["toi"]))
        rest = contacts[10:]
        contacts = contacts[:10] + random.Random(3).sample(rest, min(30, len(rest)))
    exact_earliest = None
    degenerate = 0
    for kind, h in contacts:
        try:
            exact = exact_pair(kind, h, x0, x1, faces, edges)
        except Degenerate:
            degenerate += 1
            continue
        assert exact is not None, f"{kind} contact {h} does not touch exactly"
        check_lower_bound_within_tolerance(float(h["toi"]), exact)
        exact_earliest = exact if exact_earliest is None or exact[1] < exact_earliest[1] else exact_earliest
    assert exact_earliest is not None
    # The step's earliest TOI is no later than any exact contact checked, within the tolerance of
    # the earliest one among them (cloth-funnel: all of them, so of the step's exact earliest).
    assert Fraction(r.earliest_toi) <= exact_earliest[1]
    if scene == "cloth-funnel":
        assert Fraction(r.earliest_toi) >= exact_earliest[1] - Fraction(TOL)
    step = lwsccd.ipc.compute_collision_free_stepsize((x0, edges, faces), x0, x1, device="cpu")
    assert Fraction(step) <= exact_earliest[0]
    print(f"\n{scene}: {len(contacts)} contacts checked exactly ({degenerate} degenerate skipped), exact earliest "
          f"{float(exact_earliest[0]):.9g}, lwsccd earliest {r.earliest_toi:.9g}, lwsccd.ipc step {step:.9g}")


@pytest.mark.skipif(not HAVE_IPCTK, reason="SKIPPED: ipctk (ipc-toolkit) is not installed: pip install ipctk")
def test_beside_ipctk_on_a_real_collision_mesh(data_dir):
    import ipctk

    faces, x0, x1 = lwsccd.load_scene(str(data_dir / "scenes" / "cloth-funnel"))
    edges = ipctk.edges(faces.astype(np.int32)) if hasattr(ipctk, "edges") else None
    if edges is None:
        edges = lwsccd.Pipeline(faces, device="cpu").edges.astype(np.int32)
    mesh = ipctk.CollisionMesh(np.asfortranarray(x0), np.asfortranarray(edges, dtype=np.int32),
                               np.asfortranarray(faces, dtype=np.int32))
    ours = lwsccd.ipc.compute_collision_free_stepsize(mesh, x0, x1, device="cpu")
    theirs = ipctk.compute_collision_free_stepsize(mesh, np.asfortranarray(x0), np.asfortranarray(x1))
    # lwsccd's step is collision free by lwsccd's own test, the whole step is not.
    assert lwsccd.ipc.is_step_collision_free(mesh, x0, x0 + ours * (x1 - x0), device="cpu")
    assert not lwsccd.ipc.is_step_collision_free(mesh, x0, x1, device="cpu")
    # ipctk's step is free by both tests, and not after lwsccd's certified earliest contact.
    theirs_end = x0 + theirs * (x1 - x0)
    assert ipctk.is_step_collision_free(mesh, np.asfortranarray(x0), np.asfortranarray(theirs_end))
    assert lwsccd.ipc.is_step_collision_free(mesh, x0, theirs_end, device="cpu")
    assert theirs <= ours / lwsccd.ipc.DEFAULT_CONSERVATIVE_RESCALING + TOL
    # ipctk's own test at lwsccd's step: False where a pair comes within its effective distance
    # (min(0.2 x its initial distance, 1e-4)) though none touches (lwsccd.ipc's docstring).
    at_ours = ipctk.is_step_collision_free(mesh, np.asfortranarray(x0), np.asfortranarray(x0 + ours * (x1 - x0)))
    print(f"\ncloth-funnel: lwsccd.ipc step {ours:.9g}, ipctk step {theirs:.9g}; ipctk's test at lwsccd's step: "
          f"{'free' if at_ours else 'a pair within its effective distance'}")


def test_the_line_search_example_keeps_the_sheet_above_the_plate():
    import pathlib
    import subprocess
    import sys

    example = pathlib.Path(__file__).resolve().parents[2] / "examples" / "python" / "ipc_line_search.py"
    out = subprocess.run([sys.executable, str(example), "--device", "cpu", "--steps", "4", "--resolution", "10"],
                         capture_output=True, text=True, check=True).stdout
    heights = [line.split("z = ")[1] for line in out.splitlines() if "z = " in line]
    assert len(heights) == 4, out
    if "barrier: ipctk" in out:  # the barrier keeps the sheet away from the plate
        assert min(float(h) for h in heights) > 0, out
    else:  # steps bounded by the contacts alone: the sheet may come to rest on the plate, never below
        assert all(h.startswith("+") for h in heights), out
