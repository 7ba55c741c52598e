"""The standard sparse-view splits of the literature, as index lists.

- LLFF and DL3DV (and any video-like capture): frames sorted by name; test = every 8th (index % 8 == 0);
  train = ``round(linspace(0, len(rest) - 1, n))`` over the remaining frames (numpy's round, as the
  reference implementations use).
- DTU: train ids 25, 22, 28, 40, 44, 48, 0, 8, 13 (the first n); test = all other ids except
  3-7, 16-21 and 36-39 (the test set does not depend on n).
- Blender: train ids 26, 86, 2, 55, 75, 93, 16, 73 (the first n) of ``transforms_train.json``;
  test = every 8th frame of ``transforms_test.json``.
"""

from __future__ import annotations

import numpy as np

from .scene import SceneError

DTU_TRAIN_IDS = (25, 22, 28, 40, 44, 48, 0, 8, 13)
DTU_EXCLUDED_TEST_IDS = (3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 36, 37, 38, 39)
BLENDER_TRAIN_IDS = (26, 86, 2, 55, 75, 93, 16, 73)


def every_nth_split(num: int, n_train: int | None, test_every: int = 8,
                    test_rest: bool = False, source: str | None = None) -> tuple[list[int], list[int]]:
    """LLFF/DL3DV rule over ``num`` frames already sorted by name -> (train, test) indices.

    ``n_train=None`` takes every non-test frame; ``test_every=0`` makes no test views. ``test_rest``:
    the training views are chosen by the same rule, but every frame not trained on is a test view (a
    denser test set where ground truth is free, as for the synthetic scene). ``source``: the file the
    frames come from, named in the errors.
    """
    try:
        return _every_nth_split(num, n_train, test_every, test_rest)
    except SceneError as e:
        raise SceneError(f"{source}: {e}" if source else str(e)) from None


def _every_nth_split(num: int, n_train: int | None, test_every: int, test_rest: bool) -> tuple[list[int], list[int]]:
    if num <= 0:
        raise SceneError("the scene has no frames")
    idx = np.arange(num)
    if test_every and test_every > 0:
        test = [int(i) for i in idx if i % test_every == 0]
        rest = [int(i) for i in idx if i % test_every != 0]
    else:
        test, rest = [], [int(i) for i in idx]
    if n_train is None:
        return rest, test
    if isinstance(n_train, bool) or not isinstance(n_train, (int, np.integer)):
        raise SceneError(f"views={n_train!r}: expected a number of training views or 'all'")
    if n_train < 1:
        raise SceneError(f"views={n_train}: at least 1 training view is needed")
    if n_train > len(rest):
        raise SceneError(f"views={n_train}: asked for {n_train} training views but only {len(rest)} of the "
                         f"{num} frames are not test frames")
    pick = np.round(np.linspace(0, len(rest) - 1, n_train)).astype(int)
    train = [rest[i] for i in pick]
    if test_rest:
        test = [int(i) for i in idx if int(i) not in train]
    return train, test


def dtu_split(num: int, n_train: int | None) -> tuple[list[int], list[int]]:
    """DTU protocol over ids 0..num-1 -> (train, test) ids."""
    n = 3 if n_train is None else n_train
    if n < 1 or n > len(DTU_TRAIN_IDS):
        raise SceneError(f"DTU's protocol defines 1..{len(DTU_TRAIN_IDS)} training views, asked for {n}")
    train = list(DTU_TRAIN_IDS[:n])
    if max(train) >= num:
        raise SceneError(f"DTU protocol needs view {max(train)} but the scene has {num} views")
    test = [i for i in range(num) if i not in DTU_TRAIN_IDS and i not in DTU_EXCLUDED_TEST_IDS]
    return train, test


def blender_train_ids(n_train: int | None) -> list[int]:
    n = 8 if n_train is None else n_train
    if n < 1 or n > len(BLENDER_TRAIN_IDS):
        raise SceneError(f"the Blender protocol defines 1..{len(BLENDER_TRAIN_IDS)} training views, asked for {n}")
    return list(BLENDER_TRAIN_IDS[:n])
