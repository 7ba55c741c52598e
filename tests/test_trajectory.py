"""Camera trajectories: path ordering, slerp, the natural cubic spline, interpolated poses, perturbations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, Slerp

from warpgs.data.stress import look_along
from warpgs.pseudo.trajectory import (
    Trajectory,
    camera_centres,
    chord_knots,
    guidance_sources,
    natural_cubic_spline,
    focus_point,
    nearest_neighbour_path,
    offset_trajectories,
    path_trajectories,
    perturb_pose,
    perturb_trajectory,
    pose,
    quat_to_rotmat,
    rotmat_to_quat,
    slerp,
)


def _wxyz(q_xyzw):
    return np.roll(q_xyzw, 1)


def _random_poses(n, rng, spread=1.0):
    R = Rotation.random(n, random_state=rng.integers(1 << 31)).as_matrix()
    c = rng.normal(0, spread, (n, 3))
    return np.stack([pose(R[k], c[k]) for k in range(n)])


def test_nearest_neighbour_path_recovers_a_line():
    rng = np.random.default_rng(0)
    xs = np.cumsum(rng.uniform(0.5, 1.5, 7))
    perm = rng.permutation(7)
    pts = np.c_[xs[perm], 0.05 * rng.normal(size=7), np.zeros(7)]
    order = nearest_neighbour_path(pts)
    assert sorted(order) == list(range(7))
    walked = xs[perm][order]
    assert np.all(np.diff(walked) > 0) or np.all(np.diff(walked) < 0)


def test_nearest_neighbour_path_small_and_deterministic():
    assert nearest_neighbour_path(np.zeros((1, 3))) == [0]
    assert nearest_neighbour_path(np.eye(3)[:2]) == [0, 1]
    pts = np.array([[0.0, 0, 0], [3, 0, 0], [1, 0, 0], [2, 0, 0]])
    assert nearest_neighbour_path(pts) == [0, 2, 3, 1]


def test_quaternions_round_trip_and_match_scipy():
    rng = np.random.default_rng(1)
    for R in Rotation.random(20, random_state=2).as_matrix():
        q = rotmat_to_quat(R)
        assert q[0] >= 0 and np.isclose(np.linalg.norm(q), 1)
        assert np.allclose(quat_to_rotmat(q), R, atol=1e-12)
        ref = _wxyz(Rotation.from_matrix(R).as_quat())
        assert np.allclose(q, ref * np.sign(ref[0]), atol=1e-12)
    # near-180-degree rotations take the other branches of Shepperd's method
    for axis in np.eye(3):
        R = Rotation.from_rotvec(axis * (np.pi - 1e-3) + rng.normal(0, 1e-4, 3)).as_matrix()
        assert np.allclose(quat_to_rotmat(rotmat_to_quat(R)), R, atol=1e-10)


def test_slerp_against_scipy_and_half_angle():
    q0 = rotmat_to_quat(np.eye(3))
    q1 = rotmat_to_quat(Rotation.from_euler("z", 90, degrees=True).as_matrix())
    half = quat_to_rotmat(slerp(q0, q1, 0.5))
    assert np.allclose(half, Rotation.from_euler("z", 45, degrees=True).as_matrix(), atol=1e-12)
    Ra, Rb = Rotation.random(2, random_state=5)
    ref = Slerp([0, 1], Rotation.concatenate([Ra, Rb]))
    qa, qb = rotmat_to_quat(Ra.as_matrix()), rotmat_to_quat(Rb.as_matrix())
    for s in (0.0, 0.2, 0.7, 1.0):
        assert np.allclose(quat_to_rotmat(slerp(qa, qb, s)), ref([s]).as_matrix()[0], atol=1e-10)
    # q and -q are one rotation: slerp takes the shorter arc either way
    assert np.allclose(quat_to_rotmat(slerp(qa, -qb, 0.3)), ref([0.3]).as_matrix()[0], atol=1e-10)


def test_natural_cubic_spline_matches_scipy():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.3, 2.0, 6))
    y = rng.normal(size=(6, 3))
    s = np.linspace(t[0], t[-1], 57)
    ours = natural_cubic_spline(t, y)(s)
    ref = CubicSpline(t, y, bc_type="natural")(s)
    assert np.allclose(ours, ref, atol=1e-12)
    two = natural_cubic_spline(t[:2], y[:2])(s[:5] * 0 + t[0] + 0.25 * (t[1] - t[0]))
    assert np.allclose(two, y[0] + 0.25 * (y[1] - y[0]))  # two knots: a straight line


def test_path_trajectories_ends_rotations_and_spline():
    rng = np.random.default_rng(4)
    V = _random_poses(5, rng)
    trajs = path_trajectories(V, n_frames=9)
    order = nearest_neighbour_path(camera_centres(V))
    assert [(t.start, t.end) for t in trajs] == list(zip(order[:-1], order[1:]))
    C = camera_centres(V[order])
    knots = chord_knots(C)
    spline = CubicSpline(knots, C, bc_type="natural")
    for k, t in enumerate(trajs):
        assert len(t) == 9 and t.viewmats.shape == (9, 4, 4)
        assert np.array_equal(t.viewmats[0], V[t.start]) and np.array_equal(t.viewmats[-1], V[t.end])
        R = t.viewmats[:, :3, :3]
        assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-10)
        assert np.allclose(np.linalg.det(R), 1.0)
        s = np.linspace(0, 1, 9)
        assert np.allclose(t.centers, spline(knots[k] + s * (knots[k + 1] - knots[k])), atol=1e-9)
        # rotations: slerp between the two inputs' camera-to-world rotations
        ref = Slerp([0, 1], Rotation.from_matrix(np.stack([V[t.start, :3, :3].T, V[t.end, :3, :3].T])))
        assert np.allclose(R.transpose(0, 2, 1), ref(s).as_matrix(), atol=1e-9)


def test_line_centres_are_straight_between_the_neighbours_with_the_same_rotations():
    rng = np.random.default_rng(5)
    V = _random_poses(5, rng)
    for t_line, t_spline in zip(path_trajectories(V, 7, "capture", centres="line"), path_trajectories(V, 7, "capture")):
        a, b = camera_centres(V[[t_line.start]])[0], camera_centres(V[[t_line.end]])[0]
        assert np.allclose(t_line.centers, a + np.linspace(0, 1, 7)[:, None] * (b - a), atol=1e-9)
        assert np.allclose(t_line.viewmats[:, :3, :3], t_spline.viewmats[:, :3, :3], atol=1e-12)
    with pytest.raises(ValueError, match="spline or line"):
        path_trajectories(V, 5, "capture", centres="arc")


def test_collinear_equally_spaced_inputs_give_a_straight_uniform_path():
    V = np.stack([pose(np.eye(3), [x, 0.0, 0.0]) for x in (0.0, 2.0, 1.0, 3.0)])
    trajs = path_trajectories(V, n_frames=5)
    centers = np.concatenate([t.centers[:-1] for t in trajs] + [trajs[-1].centers[-1:]])
    assert np.allclose(centers[:, 0], np.linspace(0, 3, 13)) and np.allclose(centers[:, 1:], 0)


def test_capture_order_follows_the_inputs_as_given():
    """A walk-through's inputs in capture order: the path goes 0 -> 1 -> 2 -> 3 even where a
    nearest-neighbour tour would not (here it would visit 0, 2, 1, 3 along the line)."""
    V = np.stack([pose(np.eye(3), [x, 0.0, 0.0]) for x in (0.0, 2.0, 1.0, 3.0)])
    assert [(t.start, t.end) for t in path_trajectories(V, 5, "capture")] == [(0, 1), (1, 2), (2, 3)]
    assert [(t.start, t.end) for t in path_trajectories(V, 5, "nearest")] == [(0, 2), (2, 1), (1, 3)]
    assert [(t.start, t.end) for t in path_trajectories(V, 5)] == [(0, 2), (2, 1), (1, 3)]
    with pytest.raises(ValueError, match="capture, nearest"):
        path_trajectories(V, 5, "spiral")


def test_path_trajectories_rejects_bad_input():
    with pytest.raises(ValueError):
        path_trajectories(np.eye(4)[None], 5)
    with pytest.raises(ValueError):
        path_trajectories(np.stack([np.eye(4)] * 2), 1)


def test_perturb_pose_statistics():
    rng = np.random.default_rng(6)
    V = pose(Rotation.random(random_state=7).as_matrix(), [1.0, -2.0, 0.5])
    P = np.stack([perturb_pose(V, rng, 0.05, 0.1) for _ in range(4000)])
    dc = camera_centres(P) - camera_centres(V[None])
    assert np.allclose(dc.std(0), 0.05, rtol=0.08) and np.allclose(dc.mean(0), 0, atol=0.005)
    dR = np.einsum("nij,jk->nik", P[:, :3, :3], V[:3, :3].T)  # R_p R_v^T
    ang = np.degrees(Rotation.from_matrix(dR).magnitude())
    # |N(0, s^2 I_3)| is chi-distributed with 3 dof: mean 2 sqrt(2/pi) s
    assert ang.mean() == pytest.approx(0.1 * 2 * np.sqrt(2 / np.pi), rel=0.05)


def test_perturb_trajectory_keeps_the_most_uncertain_candidate():
    V = np.stack([pose(np.eye(3), [x, 0.0, 0.0]) for x in (0.0, 1.0)])
    traj = path_trajectories(V, n_frames=6)[0]
    target = np.array([0.0, 1.0, 0.0])
    seen: dict[int, list] = {}

    def score(f, m):  # "uncertainty" grows towards +y
        seen.setdefault(f, []).append(m)
        return float(camera_centres(m[None])[0] @ target)

    out = perturb_trajectory(traj, score, np.random.default_rng(8), n_candidates=5, translation=0.1)
    assert np.array_equal(out.viewmats[0], traj.viewmats[0]) and np.array_equal(out.viewmats[-1], traj.viewmats[-1])
    assert sorted(seen) == [1, 2, 3, 4] and all(len(v) == 5 for v in seen.values())
    for f in range(1, 5):
        best = max(seen[f], key=lambda m: float(camera_centres(m[None])[0] @ target))
        assert np.array_equal(out.viewmats[f], best)
    assert perturb_trajectory(traj, score, np.random.default_rng(0), n_candidates=0) is traj


def test_guidance_sources():
    V = np.stack([pose(np.eye(3), [x, 0.0, 0.0]) for x in (0.0, 1.0, 5.0)])
    traj = Trajectory(0, 1, path_trajectories(V[:2], n_frames=7)[0].viewmats)
    centers = camera_centres(V)
    assert guidance_sources(traj, centers).tolist() == [0, 0, 0, 0, 1, 1, 1]  # the midpoint tie goes to 0
    assert guidance_sources(traj, centers, "halves").tolist() == [0, 0, 0, 0, 1, 1, 1]
    traj8 = Trajectory(0, 1, path_trajectories(V[:2], n_frames=8)[0].viewmats)
    assert guidance_sources(traj8, centers, "halves").tolist() == [0, 0, 0, 0, 1, 1, 1, 1]
    with pytest.raises(ValueError):
        guidance_sources(traj, centers, "bogus")


def _ring_looking_at(target, n=4, radius=3.0, height=0.0, spread_deg=60.0):
    """n cameras on an arc of a horizontal circle (world z up) around ``target``, each looking at it, OpenCV axes
    (camera y points down the world's z)."""
    out = []
    for a in np.radians(np.linspace(-spread_deg / 2, spread_deg / 2, n)):
        c = target + np.array([radius * np.cos(a), radius * np.sin(a), height])
        out.append(look_along(c, target - c, np.array([0.0, 0.0, 1.0])))
    return np.stack(out)


def test_focus_point_is_where_the_axes_meet_and_none_for_parallel_axes():
    target = np.array([0.5, -1.0, 2.0])
    assert np.allclose(focus_point(_ring_looking_at(target, n=5)), target, atol=1e-9)
    forward = np.stack([pose(np.eye(3), [x, 0.0, 0.0]) for x in (0.0, 1.0, 2.0)])  # all looking along +z
    assert focus_point(forward) is None
    behind = _ring_looking_at(target, n=3)
    behind[:, :3, :] *= -1  # every camera turned round (rows of x, y, z negated: still a rotation? det -1 -> fix y)
    behind[:, 1, :] *= -1
    assert focus_point(behind) is None  # the point the axes meet lies behind the cameras


def test_offset_trajectories_move_up_by_the_share_of_the_pair_and_keep_the_look_at_point():
    """Cameras on a level arc looking at a point: the copy at offset e moves every frame by e x the pair's
    distance straight up (the world's z, perpendicular to the level chord), and each moved frame's optical axis
    still passes through the point its unmoved frame's axis looked at (the target's projection on that axis: the
    target itself at the inputs); offset 0 gives the path back; frames stay rotations."""
    target = np.array([0.0, 0.0, 0.0])
    V = _ring_looking_at(target, n=3, radius=4.0)
    trajs = path_trajectories(V, 7, "capture")
    for e in (0.5, -0.25):
        moved = offset_trajectories(trajs, V, [e])
        assert len(moved) == len(trajs)
        for t, m in zip(trajs, moved):
            assert (m.start, m.end, m.offset) == (t.start, t.end, e)
            chord = np.linalg.norm(t.centers[-1] - t.centers[0])
            assert np.allclose(m.centers - t.centers, [0.0, 0.0, e * chord], atol=1e-9)
            R = m.viewmats[:, :3, :3]
            assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-9) and np.allclose(np.linalg.det(R), 1)
            for M0, M, c0, c in zip(t.viewmats, m.viewmats, t.centers, m.centers):
                f0 = M0[2, :3]
                look = c0 + np.dot(target - c0, f0) * f0
                v, f = look - c, M[2, :3]
                assert np.linalg.norm(v - np.dot(v, f) * f) < 1e-9 and np.dot(v, f) > 0
            for k in (0, -1):  # at the inputs' ends that point is the target
                f = m.viewmats[k, 2, :3]
                v = target - m.centers[k]
                assert np.linalg.norm(v - np.dot(v, f) * f) < 1e-9
    same = offset_trajectories(trajs, V, [0.0])
    for t, m in zip(trajs, same):
        assert np.allclose(m.viewmats, t.viewmats, atol=1e-12)


def test_offset_trajectories_of_forward_facing_inputs_only_move():
    """Parallel axes (no focus point): the moved frames keep their rotations; 'up' is -y of the cameras."""
    V = np.stack([pose(np.eye(3), [x, 0.0, 0.0]) for x in (0.0, 1.0, 3.0)])
    trajs = path_trajectories(V, 5, "capture")
    for t, m in zip(trajs, offset_trajectories(trajs, V, [1.0])):
        chord = np.linalg.norm(t.centers[-1] - t.centers[0])
        assert np.allclose(m.centers - t.centers, [0.0, -chord, 0.0], atol=1e-9)
        assert np.allclose(m.viewmats[:, :3, :3], t.viewmats[:, :3, :3])
