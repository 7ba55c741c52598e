"""Radius queries over point sets with Warp's ``HashGrid``: "is anything within r?", a parallel
greedy thinning of candidates, and the k-nearest spacing used for new Gaussians' scales.
Only Warp code lives here (torch side: ``warpgs.densify.insert``).

A ``HashGrid`` query returns every point of the cells the query sphere touches, so each kernel checks
the exact distance itself. "Within r" means a squared distance <= r^2 (float32).
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

MAX_K = 8
vec_k = wp.types.vector(length=MAX_K, dtype=float)

UNDECIDED = wp.constant(0)
ACCEPTED = wp.constant(1)
REJECTED = wp.constant(2)
HASH_M1 = wp.constant(wp.uint32(0x7FEB352D))
HASH_M2 = wp.constant(wp.uint32(0x846CA68B))


@wp.func
def hash_priority(i: int, seed: int) -> wp.uint32:
    """A fixed pseudo-random priority per index (lowbias32 hash), so thinning takes O(log n) rounds."""
    x = wp.uint32(i) ^ wp.uint32(seed)
    x = x ^ (x >> wp.uint32(16))
    x = x * HASH_M1
    x = x ^ (x >> wp.uint32(15))
    x = x * HASH_M2
    x = x ^ (x >> wp.uint32(16))
    return x


@wp.func
def before(a: int, b: int, seed: int) -> bool:
    """True when index a outranks index b (priority, ties broken by index)."""
    pa = hash_priority(a, seed)
    pb = hash_priority(b, seed)
    return pa < pb or (pa == pb and a < b)


@wp.kernel
def any_within_radius(
    grid: wp.uint64,  # built over ``points`` with cell width >= radius
    points: wp.array(dtype=wp.vec3),
    queries: wp.array(dtype=wp.vec3),
    radius: float,
    hit: wp.array(dtype=wp.int32),  # out: 1 where a point lies within radius of the query
):
    t = wp.tid()
    q = queries[t]
    r2 = radius * radius
    found = int(0)
    it = wp.hash_grid_query(grid, q, radius)
    k = int(0)
    while wp.hash_grid_query_next(it, k):
        d = points[k] - q
        if wp.dot(d, d) <= r2:
            found = 1
            break
    hit[t] = found


@wp.kernel
def thin_round(
    grid: wp.uint64,  # built over ``points``
    points: wp.array(dtype=wp.vec3),
    radius: float,
    seed: int,
    state_in: wp.array(dtype=wp.int32),
    state_out: wp.array(dtype=wp.int32),
    undecided: wp.array(dtype=wp.int32),  # [1] counter of points still undecided after this round
):
    """One round of the parallel greedy independent set (points closer than radius conflict): an
    undecided point next to an accepted one is rejected; one that outranks all its undecided
    neighbours is accepted. Two conflicting points are never accepted in the same round (one outranks
    the other), and rounds continue until no point is undecided, so the result is the sequential
    greedy thinning in priority order."""
    t = wp.tid()
    st = state_in[t]
    if st != UNDECIDED:
        state_out[t] = st
        return
    q = points[t]
    r2 = radius * radius
    blocked = int(0)
    outranked = int(0)
    it = wp.hash_grid_query(grid, q, radius)
    k = int(0)
    while wp.hash_grid_query_next(it, k):
        if k == t:
            continue
        sk = state_in[k]
        if sk == REJECTED:
            continue
        d = points[k] - q
        if wp.dot(d, d) > r2:
            continue
        if sk == ACCEPTED:
            blocked = 1
            break
        if before(k, t, seed):
            outranked = 1
    if blocked == 1:
        state_out[t] = REJECTED
    elif outranked == 0:
        state_out[t] = ACCEPTED
    else:
        state_out[t] = UNDECIDED
        wp.atomic_add(undecided, 0, 1)


@wp.kernel
def knn_mean_sq_distance(
    grid: wp.uint64,  # built over ``points``
    points: wp.array(dtype=wp.vec3),
    query_index: wp.array(dtype=wp.int32),  # [Q] rows of ``points`` to query (each skips itself)
    k: int,  # <= MAX_K
    search_radius: float,
    out: wp.array(dtype=float),  # [Q] mean squared distance to the k nearest; missing ones count as search_radius
):
    t = wp.tid()
    self_i = query_index[t]
    q = points[self_i]
    r2 = search_radius * search_radius
    best = vec_k()
    for m in range(k):
        best[m] = r2
    it = wp.hash_grid_query(grid, q, search_radius)
    n = int(0)
    while wp.hash_grid_query_next(it, n):
        if n == self_i:
            continue
        d = points[n] - q
        d2 = wp.dot(d, d)
        if d2 >= best[k - 1]:
            continue
        # insert into the sorted list of the k smallest
        m = k - 1
        while m > 0 and best[m - 1] > d2:
            best[m] = best[m - 1]
            m -= 1
        best[m] = d2
    s = float(0.0)
    for m in range(k):
        s += best[m]
    out[t] = s / float(k)
