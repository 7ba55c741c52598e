"""PLY export / import in the standard 3D-GS layout."""

import numpy as np
import pytest
import torch

from warpgs.model import GaussianModel, read_point_cloud
from warpgs.ply import read_vertices as read_ply_vertices

V = torch.eye(4)
K = torch.tensor([[40.0, 0, 24], [0, 40.0, 16], [0, 0, 1]])


def _trained_looking_model(n=50, degree=3, seed=0):
    g = torch.Generator().manual_seed(seed)
    m = GaussianModel.random_box(n, [-1, -1, 3], [1, 1, 5], generator=g, sh_degree=degree)
    with torch.no_grad():  # arbitrary values everywhere, as after training
        for name, p in m.params.items():
            p.add_(0.3 * torch.randn(p.shape, generator=g))
    m.active_sh_degree = degree
    return m


def _raw(path):
    """Independent reader: split the header by hand and view the body as float32 rows."""
    data = open(path, "rb").read()
    head, body = data.split(b"end_header\n", 1)
    lines = head.decode().splitlines()
    names = [ln.split()[2] for ln in lines if ln.startswith("property")]
    n = int(next(ln.split()[2] for ln in lines if ln.startswith("element vertex")))
    assert "format binary_little_endian 1.0" in lines
    assert all(ln.split()[1] == "float" for ln in lines if ln.startswith("property"))
    return names, np.frombuffer(body, "<f4").reshape(n, len(names))


def test_header_layout_is_3dgs(tmp_path):
    m = _trained_looking_model()
    names, rows = _raw(m.save_ply(tmp_path / "g.ply"))
    want = (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"] + [f"f_rest_{i}" for i in range(45)]
            + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])
    assert names == want and rows.shape == (50, 62)
    p = {k: v.detach().numpy() for k, v in m.params.items()}
    col = {n: rows[:, i] for i, n in enumerate(names)}
    assert np.array_equal(col["x"], p["means"][:, 0]) and np.array_equal(col["nz"], np.zeros(50, np.float32))
    assert np.array_equal(col["opacity"], p["opacities"])  # raw logit, as 3D-GS stores it
    assert np.array_equal(col["scale_1"], p["scales"][:, 1])  # log scale
    assert np.array_equal(col["rot_0"], p["quats"][:, 0])  # w first
    assert np.array_equal(col["f_dc_2"], p["sh0"][:, 0, 2])
    # f_rest is channel-major: f_rest_{c * 15 + k} = shN[:, k, c]
    for c in range(3):
        for k in (0, 7, 14):
            assert np.array_equal(col[f"f_rest_{c * 15 + k}"], p["shN"][:, k, c])


@pytest.mark.parametrize("degree", [3, 1])
def test_round_trip_renders_the_same_image(tmp_path, degree):
    m = _trained_looking_model(degree=degree)
    path = m.save_ply(tmp_path / "g.ply")
    r = GaussianModel.load_ply(path)
    assert r.max_sh_degree == degree and r.active_sh_degree == degree and len(r) == len(m)
    for name in m.params:
        assert torch.equal(r.params[name], m.params[name].detach()), name
    bg = torch.tensor([0.2, 0.3, 0.4])
    with torch.no_grad():
        a = m.render(V, K, 48, 32, background=bg).image
        b = r.render(V, K, 48, 32, background=bg).image
    assert float((a - b).abs().max()) <= 1e-5
    assert float(a.std()) > 0.01  # the image is not blank


def test_load_ply_refuses_a_plain_point_cloud(tmp_path):
    p = tmp_path / "pc.ply"
    p.write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
                 "end_header\n0 0 0\n1 1 1\n")
    with pytest.raises(ValueError, match="not a 3D Gaussian Splatting PLY"):
        GaussianModel.load_ply(p)


def test_point_cloud_ascii_with_8bit_colours_and_faces(tmp_path):
    p = tmp_path / "pc.ply"
    p.write_text("ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 3\nproperty float x\nproperty float y\n"
                 "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
                 "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                 "0 0 0 255 0 0\n1 0 0 0 255 0\n0 1 0 0 0 51\n3 0 1 2\n")
    xyz, rgb = read_point_cloud(p)
    assert np.allclose(xyz, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    assert np.allclose(rgb, [[1, 0, 0], [0, 1, 0], [0, 0, 0.2]])
    m = GaussianModel.from_points(xyz, rgb)
    assert len(m) == 3


def test_point_cloud_written_by_open3d(tmp_path):
    import open3d as o3d  # a dependency: its absence fails the test
    pts = np.random.default_rng(0).random((100, 3))
    cols = np.random.default_rng(1).random((100, 3))
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pc.colors = o3d.utility.Vector3dVector(cols)
    path = str(tmp_path / "o3d.ply")
    assert o3d.io.write_point_cloud(path, pc, write_ascii=False)
    xyz, rgb = read_point_cloud(path)
    assert np.allclose(xyz, pts, atol=1e-6)
    assert np.allclose(rgb, cols, atol=1 / 255)  # open3d stores 8-bit colours


def test_big_endian_and_truncated(tmp_path):
    arr = np.array([(1.5, -2.0, 3.25)], dtype=[("x", ">f4"), ("y", ">f4"), ("z", ">f4")])
    p = tmp_path / "be.ply"
    p.write_bytes(b"ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                  b"property float z\nend_header\n" + arr.tobytes())
    v = read_ply_vertices(p)
    assert (float(v["x"][0]), float(v["y"][0]), float(v["z"][0])) == (1.5, -2.0, 3.25)
    q = tmp_path / "short.ply"
    q.write_bytes(p.read_bytes()[:-2])
    with pytest.raises(ValueError, match="truncated"):
        read_ply_vertices(q)
    with pytest.raises(ValueError, match="not a PLY"):
        (tmp_path / "no.ply").write_text("hello\n")
        read_ply_vertices(tmp_path / "no.ply")


@pytest.mark.parametrize("degree", [3, 0])
def test_plyfile_reads_our_model_and_warpgs_reloads_it(tmp_path, degree):
    """The written file, read by plyfile itself (what SuperSplat / gsplat's viewer expect: one binary
    little-endian ``vertex`` element of float32 3D-GS columns, in this order), and reloaded by warpgs with
    every parameter within 1e-6."""
    import plyfile  # a dependency: its absence fails the test
    m = _trained_looking_model(n=200, degree=degree, seed=4)
    path = m.save_ply(tmp_path / "point_cloud.ply")
    data = plyfile.PlyData.read(str(path))
    assert [e.name for e in data.elements] == ["vertex"] and data["vertex"].count == 200
    assert not data.text and data.byte_order == "<"
    n_rest = 3 * ((degree + 1) ** 2 - 1)
    want = (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"] + [f"f_rest_{i}" for i in range(n_rest)]
            + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])
    assert [p.name for p in data["vertex"].properties] == want
    assert all(p.val_dtype in ("f4", "float", "float32") for p in data["vertex"].properties)
    v = data["vertex"].data
    p = {k: t.detach().numpy() for k, t in m.params.items()}
    assert np.array_equal(np.stack([v["x"], v["y"], v["z"]], 1), p["means"])
    assert np.array_equal(np.stack([v[f"rot_{i}"] for i in range(4)], 1), p["quats"])
    assert np.array_equal(v["opacity"], p["opacities"])
    back = GaussianModel.load_ply(path)
    assert len(back) == 200 and back.max_sh_degree == degree
    for name in m.params:
        assert back.params[name].shape == m.params[name].shape, name
        diff = (back.params[name] - m.params[name].detach()).abs()
        assert diff.numel() == 0 or float(diff.max()) <= 1e-6, name
    # and a file written by plyfile (the way 3D-GS's own export does it) loads into warpgs
    rows = np.zeros(200, dtype=[(k, "f4") for k in want])
    for k in want:
        rows[k] = v[k]
    other = tmp_path / "by_plyfile.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(rows, "vertex")]).write(str(other))
    again = GaussianModel.load_ply(other)
    for name in m.params:
        assert torch.equal(again.params[name], back.params[name]), name


def test_ply_header_size_is_what_plyfile_writes(tmp_path):
    from warpgs.ply import float_fields, gaussian_fields, header, write_vertices

    rec = np.zeros(7, float_fields(gaussian_fields(9)))
    path = write_vertices(tmp_path / "h.ply", rec)
    assert path.stat().st_size == len(header(7, rec.dtype)) + rec.nbytes
    assert path.read_bytes().startswith(header(7, rec.dtype))
    with pytest.raises(ValueError, match="float32 or uint8"):
        write_vertices(tmp_path / "bad.ply", np.zeros(2, [("x", "<f8")]))
