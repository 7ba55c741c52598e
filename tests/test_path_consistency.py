"""``full.path_consistency`` (warpgs/pipelines/full.py): the photos of the two inputs a pseudo view lies between,
warped into it with its rendered depth, agree at the true depth of a surface both see; the term's gradient reaches
the depth; a run of the full method trains with it, and a resumed one finds the pairs again."""

import numpy as np
import pytest
import torch

from devices import DEVICES  # tests/devices.py: WARPGS_TEST_DEVICES restricts them
from warpgs.regularizers.pathconsistency import two_view_consistency
from warpgs.methods.full import pseudo_pair


def textured_plane(device="cpu"):
    """A plane at z = 4 of smoothly varying colour, as opaque round Gaussians (tests/test_binocular.py's)."""
    from warpgs.model import GaussianModel

    n = 60 * 40
    gx, gy = np.meshgrid(np.linspace(-2.4, 2.4, 60), np.linspace(-1.6, 1.6, 40))
    means = torch.tensor(np.stack([gx.ravel(), gy.ravel(), np.full(n, 4.0)], 1), dtype=torch.float32)
    colours = np.stack([0.5 + 0.4 * np.sin(3 * gx + 1) * np.cos(2 * gy), 0.5 + 0.4 * np.cos(2.5 * gx - 2 * gy),
                        0.5 + 0.4 * np.sin(2 * gy + 0.5)], -1).reshape(-1, 3)
    return GaussianModel.from_points(means.to(device), torch.tensor(colours, dtype=torch.float32, device=device),
                                     sh_degree=0, init_opacity=0.99, init_scale=1.0, device=device)


@pytest.mark.parametrize("device", DEVICES)
def test_term_is_lowest_at_the_true_depth_and_reaches_the_depth(device):
    """Inputs at x = -0.3 and +0.3 (moved in y and z too), the pseudo view between them: with the pseudo view's
    true depth the two warped photos agree far better than with the depth 30% off either way."""
    from types import SimpleNamespace

    model = textured_plane(device)
    W, H = 48, 32
    K = torch.tensor([[40.0, 0, W / 2], [0, 40.0, H / 2], [0, 0, 1]], device=device)
    bg = torch.zeros(3, device=device)

    def view(x, y=0.0, z=0.0):
        vm = torch.eye(4, device=device)
        vm[:3, 3] = -torch.tensor([x, y, z], device=device)  # world-to-camera of a camera at (x, y, z), no turn
        with torch.no_grad():
            out = model.render(vm, K, W, H, background=bg)
        return SimpleNamespace(viewmat=vm, K=K, width=W, height=H, image=out.image), out.depth

    a, _ = view(-0.3, 0.05, 0.1)
    b, _ = view(0.3, -0.05, -0.1)
    p, depth = view(0.0)

    def term(scale):
        with torch.no_grad():
            return float(two_view_consistency(depth * scale, p, a, b))

    right = term(1.0)
    assert right < 0.4 * term(1.3) and right < 0.4 * term(0.7), (right, term(1.3), term(0.7))
    d = (depth * 1.1).requires_grad_(True)
    two_view_consistency(d, p, a, b).backward()
    assert d.grad.abs().sum() > 0
    # no pixel lands in both (depth 0 everywhere): nothing to compare, a zero term
    assert float(two_view_consistency(torch.zeros_like(depth), p, a, b)) == 0.0


def test_pseudo_pair_reads_the_inputs_from_the_pseudo_views_name():
    assert pseudo_pair("c1_0_2_003", 3) == (0, 2)
    assert pseudo_pair("c2_4_3_001", 5) == (4, 3)
    assert pseudo_pair("c1_0_5_003", 3) is None  # no such input
    assert pseudo_pair("pseudo_0_1_001", 2) == (0, 1)
    assert pseudo_pair("view_003", 3) is None and pseudo_pair("c1_a_b_001", 3) is None


def test_full_method_trains_with_it_and_a_resumed_run_finds_the_pairs_again(tmp_path):
    """Every step with a pseudo view adds the term, and the run differs from one without it. A resumed run gets its
    pseudo views from the checkpoint: their names, which give the pairs, come back with them."""
    from tiny_scene import param_copy, record_loss_parts, same_params, small_full_trainer

    _, whole = small_full_trainer(tmp_path / "whole", "--set", "full.path_consistency=1.0")
    parts = record_loss_parts(whole)
    whole.run()
    with_pv = [p for p in parts if "pseudo" in p]
    assert with_pv and all("path_consistency" in p for p in with_pv)
    assert len(with_pv) < len(parts)  # the baseline phase has no pseudo view, and no term
    _, off = small_full_trainer(tmp_path / "off")
    off.run()
    assert not same_params(param_copy(whole), param_copy(off))
    pairs = [pseudo_pair(c.name, len(whole.train_cams)) for c in whole.method.pseudo_cams]
    assert pairs and all(p is not None for p in pairs)
    _, again = small_full_trainer(tmp_path / "again", "--set", "full.path_consistency=1.0")
    again.method.load_state_dict(whole.method.state_dict())
    assert [pseudo_pair(c.name, len(again.train_cams)) for c in again.method.pseudo_cams] == pairs


def test_a_negative_weight_is_named():
    from warpgs.config import FullConfig
    from warpgs.methods.full import check_settings

    with pytest.raises(ValueError, match="path_consistency"):
        check_settings(FullConfig(path_consistency=-1.0))


def test_inputs_of_different_intrinsics_are_refused_by_name(tmp_path):
    from tiny_scene import small_full_trainer

    from warpgs.data.stress import stress_scene
    from warpgs.pipelines.sparse import make_trainer

    cfg, _ = small_full_trainer(tmp_path / "a", "--set", "full.path_consistency=1.0")
    scene = stress_scene("views_3", downscale=4)
    scene.train[1].K = scene.train[1].K * np.array([[1.1, 1, 1], [1, 1.1, 1], [1, 1, 1]], np.float32)
    with pytest.raises(ValueError, match="full.path_consistency needs input views of one size and one camera matrix"):
        make_trainer(cfg, scene, tmp_path / "b")


def test_any_method_has_it_at_drawn_path_poses_and_resumes_bit_for_bit(tmp_path):
    """``train.path_consistency``: the poses are the trajectories' interior ones between neighbouring inputs; from
    its start on every step adds the term (one more render), a run differs from one without it, and a run stopped
    half-way resumes to the same parameters (the draws come from the checkpointed generator)."""
    from tiny_scene import make_scene, param_copy, same_params, tiny_config
    from warpgs.train import Trainer

    def cfg_of(weight):
        cfg = tiny_config(30)
        cfg.train.path_consistency = weight
        cfg.train.path_consistency_start = 0.3
        cfg.train.checkpoint_every = 15
        cfg.pseudo.trajectory.n_frames = 5
        return cfg

    scene = make_scene()
    whole = Trainer(cfg_of(1.0), scene, tmp_path / "whole", log=lambda m: None)
    pc = whole.regularizers.get("path_consistency")
    n = len(scene.train)
    assert len(pc.pairs) == 3 * (n - 1) and all(abs(a - b) == 1 for a, b in pc.pairs)  # 3 poses between each pair of neighbours
    assert pc.active(9) and not pc.active(8)
    parts = []
    original = whole.compute_loss

    def spy(out, cam):
        loss, p = original(out, cam)
        parts.append(p)
        return loss, p

    whole.compute_loss = spy
    whole.train()
    assert ["path_consistency" in p for p in parts] == [k >= 9 for k in range(30)]
    off = Trainer(cfg_of(0.0), make_scene(), None, log=lambda m: None)
    assert off.regularizers.get("path_consistency") is None
    off.train()
    assert not same_params(param_copy(whole), param_copy(off))
    half = Trainer(cfg_of(1.0), make_scene(), tmp_path / "half", log=lambda m: None)
    half.train(15)
    half.save_checkpoint()
    resumed = Trainer(cfg_of(1.0), make_scene(), tmp_path / "half", log=lambda m: None)
    resumed.load_checkpoint()
    resumed.train()
    assert same_params(param_copy(resumed), param_copy(whole))
