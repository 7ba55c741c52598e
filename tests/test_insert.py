"""Densification stage 4: radius-gated insertion with Warp HashGrid queries, against brute force."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from warpgs.densify import InsertConfig, insert_points, local_spacing, thin_points, within_radius

TOL = 1e-5  # relative slack for float32 distances right at the radius


def pairwise(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.sqrt(((a[:, None] - b[None]) ** 2).sum(-1))


def clustered(n, rng, centres=6, spread=0.08):
    """Points in a few tight blobs plus a uniform background: dense and sparse regions."""
    c = rng.uniform(0, 1, (centres, 3))
    k = rng.integers(0, centres, n)
    p = c[k] + rng.normal(0, spread, (n, 3))
    bg = rng.uniform(0, 1, (n // 4, 3))
    return torch.from_numpy(np.concatenate([p, bg]).astype(np.float32))


def lowbias32(x, seed):
    """The kernel's priority hash, in numpy (uint32 arithmetic)."""
    x = (np.asarray(x, np.uint64) ^ np.uint64(seed)) & np.uint64(0xFFFFFFFF)
    for shift, mul in ((16, 0x7FEB352D), (15, 0x846CA68B)):
        x ^= x >> np.uint64(shift)
        x = (x * np.uint64(mul)) & np.uint64(0xFFFFFFFF)
    return x ^ (x >> np.uint64(16))


def sequential_greedy(points, radius, seed):
    """Visit points by (priority, index); accept one unless an accepted point lies within radius."""
    n = len(points)
    order = np.lexsort((np.arange(n), lowbias32(np.arange(n), seed)))
    d = pairwise(points, points)
    accepted = np.zeros(n, bool)
    for i in order:
        if not (accepted & (d[i] <= radius)).any():
            accepted[i] = True
    return accepted


@pytest.fixture(scope="module")
def case():
    rng = np.random.default_rng(0)
    existing = clustered(2000, rng)
    cand = clustered(2400, rng)
    colors = torch.rand(len(cand), 3, generator=torch.Generator().manual_seed(0))
    return existing, cand, colors, 0.03


def test_insertion_against_brute_force(case):
    existing, cand, colors, r = case
    res = insert_points(existing, cand, colors, radius=r)
    E, C, N = existing.numpy(), cand.numpy(), res.means.numpy()
    d_ce = pairwise(C, E).min(1)
    # the radius query agrees with brute force (up to float32 rounding right at the radius)
    sure = np.abs(d_ce - r) > TOL * r
    assert np.array_equal(res.near_existing.numpy()[sure], (d_ce <= r)[sure])
    # no added point within the radius of an existing Gaussian
    assert len(N) > 0 and pairwise(N, E).min() > r * (1 - TOL)
    # added points are at least the radius apart, and every candidate not near an existing Gaussian
    # was added or has an added point within the radius (the thinning is maximal)
    dn = pairwise(N, N)
    np.fill_diagonal(dn, np.inf)
    assert dn.min() > r * (1 - TOL)
    free = ~res.near_existing.numpy()
    assert (pairwise(C[free], N).min(1) <= r * (1 + TOL)).all()
    # the new rows are the added candidates, in order, with their colours
    assert torch.equal(res.means, cand[res.added]) and torch.equal(res.colors, colors[res.added])
    assert not bool((res.added & res.near_existing).any())
    print(f"{len(C)} candidates, {len(E)} existing, radius {r}: {int(res.added.sum())} added, "
          f"{int(res.near_existing.sum())} near existing, {res.rounds} thinning rounds")


def test_scales_from_local_spacing_against_brute_force(case):
    existing, cand, colors, r = case
    cfg = InsertConfig(k=3, spacing_radius=0.1, scale_factor=0.7)
    res = insert_points(existing, cand, colors, radius=r, config=cfg)
    allp = np.concatenate([existing.numpy(), res.means.numpy()])
    d = pairwise(res.means.numpy(), allp)
    d[np.arange(len(res.means)), len(existing) + np.arange(len(res.means))] = np.inf  # not itself
    nearest = np.minimum(np.sort(d, axis=1)[:, :3], 0.1)  # missing neighbours count as the search radius
    ref = 0.7 * np.sqrt((nearest**2).mean(1))
    assert res.scales.shape == (len(res.means), 3)
    assert np.allclose(res.scales.numpy(), ref[:, None], rtol=1e-4, atol=1e-6)
    # local_spacing directly, k = 1 and 8, on the existing cloud
    idx = np.arange(0, len(existing), 37)
    for k in (1, 8):
        s = local_spacing(existing, torch.from_numpy(idx), k, 0.2).numpy()
        d = pairwise(existing.numpy()[idx], existing.numpy())
        d[np.arange(len(idx)), idx] = np.inf
        assert np.allclose(s, np.sqrt((np.minimum(np.sort(d, 1)[:, :k], 0.2) ** 2).mean(1)), rtol=1e-4)


def test_thinning_is_the_sequential_greedy_set():
    rng = np.random.default_rng(4)
    pts = clustered(1500, rng, centres=3, spread=0.05)
    for seed in (0, 11):
        mask, rounds = thin_points(pts, 0.04, seed)
        ref = sequential_greedy(pts.numpy(), 0.04, seed)
        assert np.array_equal(mask.numpy(), ref)
        assert 1 <= rounds < 60


def test_without_thinning_every_free_candidate_is_added(case):
    existing, cand, colors, r = case
    res = insert_points(existing, cand, None, radius=r, config=InsertConfig(thin=False))
    assert torch.equal(res.added, ~res.near_existing) and res.colors.shape == (len(res.means), 0)
    assert res.rounds == 0


def test_edge_cases():
    g = torch.Generator().manual_seed(1)
    cand = torch.rand(300, 3, generator=g)
    # nothing exists yet: the candidates are only thinned
    res = insert_points(torch.zeros(0, 3), cand, radius=0.05)
    assert not bool(res.near_existing.any()) and torch.equal(res.added, thin_points(cand, 0.05)[0])
    # no candidates
    res = insert_points(cand, torch.zeros(0, 3), radius=0.05)
    assert res.means.shape == (0, 3) and res.scales.shape == (0, 3) and res.added.shape == (0,)
    # every candidate sits on an existing Gaussian (distance 0): nothing added
    res = insert_points(cand, cand.clone(), radius=1e-4)
    assert res.means.shape[0] == 0 and bool(res.near_existing.all())
    # non-finite candidates are never added
    bad = cand.clone()
    bad[3, 1] = float("nan")
    bad[4, 0] = float("inf")
    res = insert_points(torch.zeros(0, 3), bad, radius=0.05)
    assert not bool(res.added[3]) and not bool(res.added[4]) and torch.isfinite(res.means).all()
    # within_radius with coincident points and exactly-at-radius pairs
    e = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    q = torch.tensor([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.25, 0.0, 0.0], [3.0, 0.0, 0.0]])
    assert within_radius(e, q, 0.5).tolist() == [True, True, True, False]
    for r in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError):
            insert_points(e, q, radius=r)
    with pytest.raises(ValueError):
        insert_points(e, q)  # no radius anywhere
    with pytest.raises(ValueError):
        insert_points(e, q[:, :2], radius=0.1)
    # deterministic
    a = insert_points(torch.zeros(0, 3), cand, radius=0.05)
    b = insert_points(torch.zeros(0, 3), cand, radius=0.05)
    assert torch.equal(a.added, b.added)
