"""Tile binning (warpgs/kernels/binning.py): the binary search the CUDA forward finds its tile's range with,
against the range kernel the CPU uses and against numpy's searchsorted, on sorted keys with empty tiles, a tile
past the last key, padding keys (a fixed-capacity render's) and no keys at all; and the packing of the splats."""

import numpy as np
import torch
import warp as wp

from warpgs._warp import fast_launch
from warpgs.kernels import binning as kb


@wp.kernel
def _ranges_by_search(keys: wp.array(dtype=wp.int64), count: int, shift: int, ranges: wp.array2d(dtype=wp.int32)):
    tile = wp.tid()
    start, end = kb.tile_range(keys, count, shift, tile)
    ranges[tile, 0] = start
    ranges[tile, 1] = end


def _sorted_keys(tiles, shift, seed=0, padding=0):
    """Sorted keys of ``tiles`` with random depth parts of ``shift`` bits (the top one set in some), then
    ``padding`` padding keys (a fixed-capacity render's, whose shift is 32)."""
    g = np.random.default_rng(seed)
    depth = g.integers(1 << (shift - 2), 1 << shift, size=len(tiles))
    keys = np.sort((np.asarray(tiles, dtype=np.int64) << shift) | depth)
    return np.concatenate([keys, np.full(padding, (1 << 63) - 1, dtype=np.int64)])


def _search(keys, count, n_tiles, shift):
    got = torch.full((n_tiles, 2), -1, dtype=torch.int32)
    fast_launch(_ranges_by_search, n_tiles, "cpu", None, torch.from_numpy(keys), count, shift, got)
    return got


def test_tile_range_search_matches_the_range_kernel_and_searchsorted():
    n_tiles = 12
    tiles = [0, 0, 1, 3, 3, 3, 3, 7, 8, 8, 10] * 5  # empty tiles 2, 4-6, 9, 11 (the last)
    for shift, padding in ((32, 0), (32, 7), (27, 0), (5, 0)):
        keys = _sorted_keys(tiles, shift, padding=padding)
        count = len(keys)  # the padding is part of the sorted list, as in a fixed-capacity render
        got = _search(keys, count, n_tiles, shift)
        kernel = torch.zeros(n_tiles, 2, dtype=torch.int32)
        fast_launch(kb.tile_ranges_from_keys, count, "cpu", None, torch.from_numpy(keys), count, shift, kernel)
        t = np.arange(n_tiles, dtype=np.int64)
        want = np.stack([np.searchsorted(keys, t << shift), np.searchsorted(keys, (t + 1) << shift)], 1)
        assert np.array_equal(got.numpy(), want)
        # the range kernel leaves empty tiles at zero: equal where a tile has entries, empty where it has none
        filled = want[:, 1] > want[:, 0]
        assert np.array_equal(kernel.numpy()[filled], want[filled])
        assert (got.numpy()[~filled, 0] == got.numpy()[~filled, 1]).all()
        assert got[1].tolist() == [10, 15] and got[3].tolist() == [15, 35]


def test_tile_range_search_of_no_keys_is_empty():
    got = _search(np.zeros(0, dtype=np.int64), 0, 4, 27)
    assert got.tolist() == [[0, 0]] * 4


def test_emit_packs_the_splats_of_gaussians_on_screen():
    n = 3
    means2d = torch.tensor([[5.0, 6.0], [16.0, 3.0], [1.0, 1.0]])
    radii = torch.tensor([[2, 3], [4, 1], [0, 0]], dtype=torch.int32)  # the last is off screen
    depths = torch.tensor([1.5, 2.5, 3.5])
    conics = torch.rand(n, 3)
    opac, colors = torch.rand(n), torch.rand(n, 3)
    touched = torch.tensor([1, 2, 0], dtype=torch.int32)  # 16-px tiles of a 32x16 image: (0, 0); (1, 0) and (0, 0)
    offsets = torch.cumsum(touched, 0, dtype=torch.int32)
    keys, values = torch.zeros(6, dtype=torch.int64), torch.zeros(6, dtype=torch.int32)
    splats = torch.full((n, 10), -7.0)
    base = int(torch.tensor(1.0).view(torch.int32))  # a near plane of 1: the keys' depth parts are bits above its
    fast_launch(kb.emit_intersections, n, "cpu", None, means2d, radii, depths.view(torch.int32), offsets, 16, 2, 1,
                24, base, keys, values, conics, opac, colors, depths, splats)
    want = torch.cat([means2d, conics, opac[:, None], colors, depths[:, None]], 1)
    assert torch.equal(splats[:2], want[:2])
    assert (splats[2] == -7.0).all()  # not written: no tile list holds it
    assert values[:3].tolist() == [0, 1, 1]
    assert sorted((keys[:3] >> 24).tolist()) == [0, 0, 1]
    assert sorted((keys[:3] & ((1 << 24) - 1)).tolist()) == sorted(
        (depths.view(torch.int32)[values[:3].long()] - base).tolist())
