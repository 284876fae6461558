"""The Embree ray engine against analytic answers and an exact float64 reference."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from render.engine import INVALID_ID, RayEngine
from render.scene.shapes import box_mesh, sphere_mesh


def moller_trumbore(origins, directions, vertices, faces):
    """Exact closest hit of every ray against every triangle, in float64 (brute force)."""
    v = vertices.astype(np.float64)[faces.astype(np.int64)]
    p0, e1, e2 = v[:, 0], v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    best = np.full(len(origins), np.inf)
    best_face = np.full(len(origins), -1)
    for i, (o, d) in enumerate(zip(origins.astype(np.float64), directions.astype(np.float64))):
        pvec = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, pvec)
        ok = np.abs(det) > 1e-15
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tvec = o - p0
        u = np.einsum("ij,ij->i", tvec, pvec) * inv
        qvec = np.cross(tvec, e1)
        w = (qvec @ d) * inv
        t = np.einsum("ij,ij->i", e2, qvec) * inv
        valid = ok & (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 0)
        if valid.any():
            k = np.argmin(np.where(valid, t, np.inf))
            best[i], best_face[i] = t[k], k
    return best, best_face


def random_rays_towards(center, radius, count, rng):
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    # Start outside at distance 3r and aim at random points inside the bounding ball.
    targets = center + radius * 0.9 * rng.uniform(-1, 1, size=(count, 3)) / np.sqrt(3)
    origins = targets - 3 * radius * directions
    return origins.astype(np.float32), directions.astype(np.float32)


def test_box_distances_match_slab_formula():
    lower, upper = np.array([-1.0, -2.0, 0.5]), np.array([2.0, 1.0, 3.0])
    engine = RayEngine()
    engine.add_mesh(*box_mesh(lower, upper), mesh_id=3)
    engine.commit()
    rng = np.random.default_rng(1)
    origins, directions = random_rays_towards((lower + upper) / 2, 1.0, 2000, rng)
    hits = engine.intersect(origins, directions)
    # Slab method in float64: entry distance into the box.
    inv = 1.0 / directions.astype(np.float64)
    t0 = (lower - origins) * inv
    t1 = (upper - origins) * inv
    t_enter = np.minimum(t0, t1).max(axis=1)
    t_exit = np.maximum(t0, t1).min(axis=1)
    expected_hit = t_exit >= max(t_enter.min(), 0)
    assert np.array_equal(hits.hit, expected_hit & (t_enter <= t_exit))
    np.testing.assert_allclose(hits.t[hits.hit], t_enter[hits.hit], rtol=1e-5)
    assert np.all(hits.mesh_id[hits.hit] == 3)
    # The entry normal points against the ray and along the axis of the slab that was hit last.
    axis = np.argmax(np.minimum(t0, t1), axis=1)[hits.hit]
    n = hits.normal[hits.hit]
    assert np.allclose(np.abs(n[np.arange(len(axis)), axis]), 1.0, atol=1e-6)
    assert np.all(np.einsum("ij,ij->i", n, directions[hits.hit]) < 0)


def test_sphere_hits_match_exact_triangle_reference():
    vertices, faces = sphere_mesh(center=(0.3, -0.2, 1.0), radius=2.0, subdivisions=3)
    engine = RayEngine()
    engine.add_mesh(vertices, faces, mesh_id=0)
    engine.commit()
    rng = np.random.default_rng(7)
    origins, directions = random_rays_towards(np.array([0.3, -0.2, 1.0]), 2.0, 300, rng)
    hits = engine.intersect(origins, directions)
    t_ref, face_ref = moller_trumbore(origins, directions, vertices, faces)
    assert np.array_equal(hits.hit, np.isfinite(t_ref))
    np.testing.assert_allclose(hits.t[hits.hit], t_ref[hits.hit], rtol=1e-5)
    same_face = hits.prim_id[hits.hit] == face_ref[hits.hit]
    assert same_face.mean() > 0.99  # ties on shared edges may pick either neighbour
    # Every hit point lies on the polyhedron: between the inscribed radius and the sphere radius.
    p = origins[hits.hit] + hits.t[hits.hit, None] * directions[hits.hit]
    r = np.linalg.norm(p - np.array([0.3, -0.2, 1.0]), axis=1)
    assert np.all(r <= 2.0 * (1 + 1e-5)) and np.all(r >= 2.0 * 0.98)
    # Outward normals: the ray enters against the normal.
    assert np.all(np.einsum("ij,ij->i", hits.normal[hits.hit], directions[hits.hit]) < 0)


def test_occluded_respects_tfar():
    engine = RayEngine()
    engine.add_mesh(*box_mesh((0, 0, 0), (1, 1, 1)), mesh_id=0)
    engine.commit()
    origins = np.array([[0.5, 0.5, 5.0]] * 3, dtype=np.float32)
    directions = np.array([[0, 0, -1]] * 3, dtype=np.float32)
    occluded = engine.occluded(origins, directions, tfar=np.array([3.9, 4.1, np.inf]))
    assert occluded.tolist() == [False, True, True]
    misses = engine.intersect(origins, -directions)
    assert np.all(misses.mesh_id == INVALID_ID) and np.all(np.isinf(misses.t))


def test_two_python_threads_get_identical_answers():
    vertices, faces = sphere_mesh(radius=1.0, subdivisions=5)
    engine = RayEngine()
    engine.add_mesh(vertices, faces, mesh_id=1)
    engine.commit()
    origins, directions = random_rays_towards(np.zeros(3), 1.0, 200_000, np.random.default_rng(3))
    serial = engine.intersect(origins, directions, threads=1)
    results: dict[int, object] = {}

    def worker(slot: int) -> None:
        results[slot] = engine.intersect(origins, directions, threads=2)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for hits in results.values():
        assert np.array_equal(hits.t, serial.t)
        assert np.array_equal(hits.prim_id, serial.prim_id)
        assert np.array_equal(hits.normal, serial.normal)


@pytest.mark.parametrize(
    "vertices, faces, message",
    [
        (np.zeros((0, 3)), np.zeros((0, 3)), "empty"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]]), np.array([[0, 1, 2]]), "non-finite"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 5]]), "refers to vertex 5"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, -1]]), "negative"),
    ],
)
def test_bad_meshes_are_refused_with_a_reason(vertices, faces, message):
    engine = RayEngine()
    with pytest.raises(ValueError, match=message):
        engine.add_mesh(vertices, faces, mesh_id=0)


def test_queries_before_commit_and_bad_shapes_raise():
    engine = RayEngine()
    engine.add_mesh(*box_mesh(), mesh_id=0)
    with pytest.raises(RuntimeError, match="commit"):
        engine.intersect(np.zeros((1, 3)), np.ones((1, 3)))
    engine.commit()
    with pytest.raises(ValueError, match="shape"):
        engine.intersect(np.zeros((4, 2)), np.ones((4, 2)))
    with pytest.raises(ValueError, match="NaN"):
        engine.intersect(np.full((1, 3), np.nan), np.ones((1, 3)))
