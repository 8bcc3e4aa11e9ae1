"""Tube meshes: rings at the right radius, outward faces, closed surface, fixed topology."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from console.scene.tube import TubeTopology, frames_from_matrices, planar_frames


def helix_frames(m: int, pitch: float = 0.1, radius: float = 0.2):
    """Centres and an orthonormal frame (normal, binormal, tangent = n x b) along a helix."""
    t = np.linspace(0, 3, m)
    c = np.stack([radius * np.cos(t), radius * np.sin(t), pitch * t], -1)
    tangent = np.stack([-radius * np.sin(t), radius * np.cos(t), np.full_like(t, pitch)], -1)
    tangent /= np.linalg.norm(tangent, axis=-1, keepdims=True)
    n = np.cross(tangent, [0.0, 0.0, 1.0])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    b = np.cross(tangent, n)  # n x b = n x (t x n) = t
    return c, n, b, tangent


def face_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return np.cross(b - a, c - a)


def test_side_vertices_lie_on_circles_of_the_given_radius() -> None:
    c, n, b, t = helix_frames(30)
    topo = TubeTopology(30, sides=12)
    v = topo.vertices(c, n, b, 0.01).astype(float)
    rings = v[: 30 * 12].reshape(30, 12, 3)
    offset = rings - c[:, None]
    np.testing.assert_allclose(np.linalg.norm(offset, axis=-1), 0.01, rtol=1e-5)
    # Each ring lies in the plane normal to the tangent.
    np.testing.assert_allclose(np.einsum("mkj,mj->mk", offset, t), 0.0, atol=1e-6)


def test_faces_point_outward_and_caps_point_along_the_tangent() -> None:
    m, k = 20, 16
    c, n, b, t = helix_frames(m)
    topo = TubeTopology(m, sides=k)
    v = topo.vertices(c, n, b, 0.02).astype(float)
    f = topo.faces.astype(int)
    normals = face_normals(v, f)
    n_side = 2 * (m - 1) * k
    side = f[:n_side]
    # Outward: the face normal points away from the nearest centre-line point.
    centroid = v[side].mean(axis=1)
    nearest = c[np.argmin(np.linalg.norm(centroid[:, None] - c[None], axis=-1), axis=1)]
    assert np.all(np.einsum("fj,fj->f", normals[:n_side], centroid - nearest) > 0)
    assert np.all(normals[n_side:n_side + k] @ t[0] < 0)  # start cap faces backwards
    assert np.all(normals[n_side + k:] @ t[-1] > 0)  # end cap faces forwards


def test_surface_is_closed_every_edge_shared_by_two_faces_in_opposite_directions() -> None:
    # Cap rings duplicate the side rings' vertices (crisp edges), so weld by position first.
    c, n, b, _ = helix_frames(5)
    topo = TubeTopology(5, sides=7, n_tubes=3)
    shift = np.arange(3)[:, None, None] * np.array([1.0, 0.0, 0.0])
    v = topo.vertices(c + shift, np.broadcast_to(n, (3, 5, 3)), np.broadcast_to(b, (3, 5, 3)), 0.05)
    _, weld = np.unique(np.round(v.astype(float), 5), axis=0, return_inverse=True)
    f = weld.reshape(-1)[topo.faces.astype(int)]
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    directed = {tuple(e) for e in edges}
    assert len(directed) == len(edges), "an edge is used twice in the same direction"
    assert all((b, a) in directed for a, b in directed), "open boundary edge"
    assert topo.faces.max() == topo.n_vertices - 1 and topo.faces.min() == 0


@settings(max_examples=25, deadline=None)
@given(rings=st.integers(2, 40), sides=st.integers(3, 24), tubes=st.integers(1, 4),
       caps=st.booleans(), seed=st.integers(0, 2**16))
def test_topology_is_independent_of_the_configuration(rings, sides, tubes, caps, seed) -> None:
    rng = np.random.default_rng(seed)
    topo = TubeTopology(rings, sides, tubes, caps)
    faces = topo.faces.copy()
    frames = np.broadcast_to(np.eye(4), (tubes, rings, 4, 4)).copy()
    frames[..., :3, 3] = rng.normal(size=(tubes, rings, 3))
    v = topo.vertices(*frames_from_matrices(frames), rng.uniform(0.001, 0.1, size=(tubes, rings)))
    assert v.shape == (topo.n_vertices, 3) and v.dtype == np.float32
    assert np.array_equal(topo.faces, faces)
    expected = tubes * (2 * (rings - 1) * sides + (2 * sides if caps else 0))
    assert faces.shape == (expected, 3)


def test_planar_frames_follow_the_heading_and_lie_at_height_z() -> None:
    poses = np.array([[0.1, 0.2, 0.3], [-1.0, 0.5, 2.0]])
    c, n, b = planar_frames(poses, 0.0125)
    np.testing.assert_allclose(c, [[0.1, 0.2, 0.0125], [-1.0, 0.5, 0.0125]])
    tangent = np.cross(n, b)
    np.testing.assert_allclose(tangent[:, :2], np.stack([np.cos(poses[:, 2]),
                                                         np.sin(poses[:, 2])], -1), atol=1e-12)
    np.testing.assert_allclose(b, [[0, 0, 1], [0, 0, 1]])


@pytest.mark.parametrize("kwargs, message", [
    ({"n_rings": 1}, "at least 2 rings"),
    ({"n_rings": 4, "sides": 2}, "at least 3 sides"),
    ({"n_rings": 4, "n_tubes": 0}, "n_tubes"),
])
def test_bad_topology_is_refused(kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        TubeTopology(**kwargs)


def test_wrong_centre_shape_is_refused_with_the_expected_shape() -> None:
    topo = TubeTopology(4, 8, n_tubes=2)
    with pytest.raises(ValueError, match=r"centers must have shape \(2, 4, 3\)"):
        topo.vertices(np.zeros((4, 3)), np.zeros((2, 4, 3)), np.zeros((2, 4, 3)), 0.1)
