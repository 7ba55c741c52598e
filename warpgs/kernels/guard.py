"""The divergence guard's verdict on a step whose verdict the host reads later (warpgs/guard.py,
``DivergenceGuard.step_on_device``): two launches instead of the two dozen small torch ops the same arithmetic takes.

``window_middle``: the two middle values of the loss window (+inf entries sorted last), one thread per entry,
each counting the entries below and equal to its own: the entry whose rank range holds a middle rank writes it
(entries with the same value write the same number). ``step_verdict``: one thread reads them and the
inf-norms of the loss and gradients, and writes the step's record, whether its update applies, fused Adam's
``found_inf`` and the step's entry in the window (its slot read from the device, so that a CUDA graph of the step
can be replayed at any step). Only Warp code lives here.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.kernel
def window_middle(values: wp.array(dtype=wp.float64), middle: wp.array(dtype=wp.float64)):
    i = wp.tid()
    n = values.shape[0]
    v = values[i]
    count = int(0)  # finite entries (the rest are +inf)
    below = int(0)
    same = int(0)
    for j in range(n):
        w = values[j]
        if wp.isfinite(w):
            count += 1
        if w < v:
            below += 1
        elif w == v:
            same += 1
    # the ranks LossWindow.median takes: (count - 1 + [0, 1]) // 2, clamped to the window
    k0 = int(0)
    if count > 0:
        k0 = wp.min((count - 1) // 2, n - 1)
    k1 = wp.min(count // 2, n - 1)
    if below <= k0 and k0 < below + same:
        middle[0] = v
    if below <= k1 and k1 < below + same:
        middle[1] = v


@wp.kernel
def step_verdict(norms: wp.array(dtype=wp.float32), inputs: wp.array(dtype=wp.float32),
                 middle: wp.array(dtype=wp.float64), values: wp.array(dtype=wp.float64), slot: wp.array(dtype=wp.int32),
                 factor: wp.float64, check_explode: int, record: wp.array(dtype=wp.float64),
                 apply: wp.array(dtype=wp.uint8), found_inf: wp.array(dtype=wp.float32)):
    n = norms.shape[0]
    finite = int(1)
    for k in range(n):
        ok = wp.isfinite(norms[k])
        record[1 + k] = wp.where(ok, wp.float64(1.0), wp.float64(0.0))
        if not ok:
            finite = 0
    value = wp.float64(inputs[0])
    record[0] = value
    exploding = int(0)
    if finite == 1 and check_explode == 1:
        median = (middle[0] + middle[1]) / wp.float64(2.0)
        if median > wp.float64(0.0) and value / median > factor:
            exploding = 1
    record[n + 1] = wp.where(exploding == 1, wp.float64(1.0), wp.float64(0.0))
    record[n + 2] = wp.float64(0.0)  # the render's MSE: read only at a host read
    ok_step = finite == 1 and exploding == 0
    apply[0] = wp.where(ok_step, wp.uint8(1), wp.uint8(0))
    found_inf[0] = wp.where(ok_step, wp.float32(0.0), wp.float32(1.0))
    values[slot[0]] = wp.where(ok_step, value, wp.float64(wp.inf))
