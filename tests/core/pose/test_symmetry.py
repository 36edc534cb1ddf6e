"""core.pose.symmetry: a model's proper symmetries, and the twin pose nearest a reference."""

from __future__ import annotations

import numpy as np

from core.brep import BRep
from core.pose import edge_symmetries, nearest_twin, symmetry_transforms
from core.transforms import invert_T, make_T, pose_error, random_rotation


def test_a_box_has_four_symmetries_a_cube_twenty_four_and_each_maps_edge_k_onto_edge_p_k():
    for size, n in (((0.35, 0.231, 0.132), 4), ((0.1, 0.1, 0.1), 24), ((0.2, 0.2, 0.1), 8)):
        box = BRep.box(*size)
        sym = symmetry_transforms(box)
        assert len(sym) == len(edge_symmetries(box)) == n
        p0, S0 = sym[0]
        assert np.array_equal(p0, np.arange(len(box.edges))) and np.allclose(S0, np.eye(4))
        for p, S in sym:
            assert sorted(p) == list(range(len(box.edges)))  # a permutation
            assert np.allclose(S[:3, :3] @ S[:3, :3].T, np.eye(3)) and np.isclose(np.linalg.det(S[:3, :3]), 1.0)
            moved = box.vertices @ S[:3, :3].T + S[:3, 3]
            for k, e in enumerate(box.edges):
                assert np.allclose(np.sort(moved[e], axis=0), np.sort(box.vertices[box.edges[p[k]]], axis=0))


def test_a_model_without_faces_has_only_the_identity():
    assert [p.tolist() for p in edge_symmetries(BRep.cylinder(0.05, 0.2))] == [
        list(range(len(BRep.cylinder(0.05, 0.2).edges)))
    ]


def test_nearest_twin_turns_a_symmetric_pose_back_to_the_reference_and_keeps_hand_assignments():
    rng = np.random.default_rng(3)
    box = BRep.box(0.35, 0.231, 0.132)
    T_ref = make_T(random_rotation(rng), rng.uniform(-1, 1, 3))
    edges = np.array([0, 3, 5, 7])
    sym = symmetry_transforms(box)
    for p, S in sym[1:]:
        T_twin = T_ref @ S  # draws the same picture, with edge k where edge p[k] was under T_ref
        # under T_twin the clicked segments lie on the edges q with p[q] = edges
        edges_twin = np.argsort(p)[edges]
        T, e = nearest_twin(box, T_twin, edges_twin, T_ref)
        deg, m = pose_error(T, T_ref)
        assert deg < 1e-9 and m < 1e-12 and np.array_equal(e, edges)
        # the same picture, seen from the twin: identical world edges for the clicked segments
        a, b = box.edge_segments(T)[e], box.edge_segments(T_twin)[edges_twin]
        assert all(np.allclose(x, y) or np.allclose(x, y[::-1]) for x, y in zip(a, b))
    # a hand assignment that only the twin keeps: the twin it is, though it turns further from T_ref
    p, S = sym[1]
    T_twin = T_ref @ S
    edges_twin = np.argsort(p)[edges]
    T, e = nearest_twin(box, T_ref, edges, T_twin @ invert_T(S), hand={0: int(edges_twin[0])})
    assert pose_error(T, T_twin)[0] < 1e-9 and e[0] == edges_twin[0]
    # a hand assignment no symmetric pose keeps (a clicked segment on an edge none maps it to): None
    others = {int(q[edges[0]]) for q, _ in sym}
    impossible = next(k for k in range(len(box.edges)) if k not in others)
    assert nearest_twin(box, T_ref, edges, T_ref, hand={0: impossible}) is None
