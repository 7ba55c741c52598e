"""Fuzzed input: the nerfstudio, COLMAP (binary and text), LLFF and Blender loaders and the config parser on
hundreds of corrupted copies of real input, with a seeded random corrupter.

Each trial copies a small subset of a real scene from ../shared/data (a few frames and a trimmed scene
description, written into tmp_path) or a repository config, corrupts it (truncated or flipped bytes,
NaN / inf / wrong types in JSON, npy and COLMAP fields, missing keys, deleted files, images of the wrong
size or channels) and loads it. The outcome must be a normal load (a scene whose cameras and images are
finite) or a ``SceneError`` / ``ConfigError`` whose message names the file or key; any other exception
fails the test, with the corruptions that caused it. ``WARPGS_FUZZ_SEED`` picks another seed,
``WARPGS_FUZZ_SCALE`` multiplies the number of trials.
"""

from __future__ import annotations

import copy
import json
import os
import random
import shutil
import subprocess
import sys
import traceback
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image

from warpgs.config import CONFIG_DIR, Config, ConfigError, build_config, parse_override, read_yaml, to_dict
from warpgs.data import SceneError, load_scene
from warpgs.data import colmap as colmap_io

SHARED = Path(os.environ.get("WARPGS_SHARED_DATA", Path(__file__).resolve().parents[1].parent / "shared" / "data"))
needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason=f"shared data not found at {SHARED}")
SEED = int(os.environ.get("WARPGS_FUZZ_SEED", "19"))
# the run configs (methods, datasets, presets), not the loaders' files in configs/data/
RUN_CONFIGS = sorted(p for p in CONFIG_DIR.rglob("*.yaml") if p.parent.name != "data")
SCALE = float(os.environ.get("WARPGS_FUZZ_SCALE", "1"))
# trials per input kind: 600 in all at scale 1 (about 15 s on one CPU core)
TRIALS = {"nerfstudio": 120, "colmap_bin": 60, "colmap_txt": 60, "llff": 90, "blender": 60, "config_yaml": 120,
          "config_set": 90}
ODD_VALUES = [float("nan"), float("inf"), -float("inf"), None, "abc", 0, -1, -1e-9, 1e30, 1e308, [], {}, [1, 2], True,
              "", [[1, 2], [3]]]


# ----------------------------------------------------------------------------------------------
# the real inputs, trimmed (written once per module into tmp_path)


def _castle(root: Path, frames: int = 6) -> Path:
    meta = json.loads((SHARED / "castle_p30" / "transforms.json").read_text())
    meta["frames"] = sorted(meta["frames"], key=lambda f: f["file_path"])[:frames]
    (root / "images_8").mkdir(parents=True)
    for fr in meta["frames"]:
        name = Path(fr["file_path"]).name
        shutil.copy(SHARED / "castle_p30" / "images_8" / name, root / "images_8" / name)
    (root / "transforms.json").write_text(json.dumps(meta, indent=1))
    return root


def _colmap(root: Path, castle: Path, binary: bool) -> Path:
    """The castle subset as a COLMAP model (sparse/0 + images/), written by warpgs's own writer."""
    scene = load_scene(str(castle), views="all")
    cams, imgs = {}, {}
    (root / "images").mkdir(parents=True)
    for k, c in enumerate(sorted(scene.cameras, key=lambda c: c.name)):
        name = Path(c.image_path).name
        shutil.copy(c.image_path, root / "images" / name)
        fx, fy, cx, cy = (float(v) for v in (c.K[0, 0], c.K[1, 1], c.K[0, 2], c.K[1, 2]))
        cams[k + 1] = colmap_io.ColmapCamera(k + 1, "PINHOLE", c.width, c.height, np.array([fx, fy, cx, cy]))
        vm = c.viewmat.astype(np.float64)
        imgs[k + 1] = colmap_io.ColmapImage(k + 1, colmap_io.rotmat_to_qvec(vm[:3, :3]), vm[:3, 3], k + 1, name)
    rng = np.random.default_rng(0)
    n = 40
    pts = colmap_io.ColmapPoints(np.arange(1, n + 1), rng.normal(size=(n, 3)), rng.integers(0, 255, (n, 3)).astype(np.uint8),
                                 np.full(n, 0.5), np.zeros(n, np.int64))
    colmap_io.write_model(root / "sparse" / "0", cams, imgs, pts, binary=binary)
    return root


def _fern(root: Path, frames: int = 5) -> Path:
    (root / "images_8").mkdir(parents=True)
    files = sorted((SHARED / "llff_fern" / "images_8").iterdir())[:frames]
    for f in files:
        shutil.copy(f, root / "images_8" / f.name)
    np.save(root / "poses_bounds.npy", np.load(SHARED / "llff_fern" / "poses_bounds.npy")[:frames])
    return root


def _lego(root: Path, size: int = 100) -> Path:
    """One training frame of the 8-view protocol (r_26) and one test frame, the images shrunk to ``size``
    (the field of view does not depend on it)."""
    for split, keep in (("train", lambda n: n == 26), ("test", lambda n: n == 0)):
        meta = json.loads((SHARED / "blender_lego" / f"transforms_{split}.json").read_text())
        meta["frames"] = [fr for fr in meta["frames"] if keep(int(Path(fr["file_path"]).name.split("_")[-1]))]
        (root / split).mkdir(parents=True)
        for fr in meta["frames"]:
            rel = fr["file_path"] + ("" if fr["file_path"].endswith(".png") else ".png")
            with Image.open(SHARED / "blender_lego" / rel) as im:
                im.resize((size, size), Image.BOX).save(root / rel)
        (root / f"transforms_{split}.json").write_text(json.dumps(meta, indent=1))
    return root


@pytest.fixture(scope="module")
def bases(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz_bases")
    castle = _castle(root / "castle")
    return {"nerfstudio": (castle, 2), "colmap_bin": (_colmap(root / "colmap_bin", castle, True), 2),
            "colmap_txt": (_colmap(root / "colmap_txt", castle, False), 2), "llff": (_fern(root / "fern"), 2),
            "blender": (_lego(root / "lego"), 1)}


# ----------------------------------------------------------------------------------------------
# the corrupter


def _json_paths(node, path=()):
    """Every (path, value) in a JSON tree."""
    yield path, node
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _json_paths(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _json_paths(v, path + (i,))


def _corrupt_json(rng: random.Random, p: Path) -> str:
    try:
        tree = json.loads(p.read_text())
    except ValueError:
        return _corrupt_bytes(rng, p)
    paths = [pa for pa, _ in _json_paths(tree) if pa]
    if not paths:
        return _corrupt_bytes(rng, p)
    path = rng.choice(paths)
    parent = tree
    for k in path[:-1]:
        parent = parent[k]
    op = rng.choice(["delete", "set", "set", "set", "dup", "scale"])
    if op == "delete":
        del parent[path[-1]]
        what = f"deleted {path}"
    elif op == "dup" and isinstance(parent, list):
        parent.append(copy.deepcopy(parent[path[-1]]))
        what = f"duplicated {path}"
    elif op == "scale" and isinstance(parent[path[-1]], (int, float)) and not isinstance(parent[path[-1]], bool):
        parent[path[-1]] = parent[path[-1]] * rng.choice([-1, 0, 0.5, 2, 1e6])
        what = f"scaled {path}"
    else:
        value = rng.choice(ODD_VALUES)
        parent[path[-1]] = value
        what = f"set {path} = {value!r}"
    p.write_text(json.dumps(tree))
    return f"{p.name}: {what}"


def _corrupt_npy(rng: random.Random, p: Path) -> str:
    try:
        a = np.load(p)
    except Exception:
        return _corrupt_bytes(rng, p)
    op = rng.choice(["value", "value", "value", "shape", "dtype"])
    if op == "value" and a.size:
        idx = tuple(rng.randrange(n) for n in a.shape)
        value = rng.choice([np.nan, np.inf, -np.inf, 0.0, -1.0, 1e30, 1e-30])
        a = a.astype(np.float64)
        a[idx] = value
        what = f"[{idx}] = {value}"
    elif op == "shape":
        choice = rng.choice(["drop_col", "drop_row", "flat", "transpose", "empty"])
        a = {"drop_col": lambda: a[:, :-1], "drop_row": lambda: a[:-1], "flat": lambda: a.ravel(),
             "transpose": lambda: a.T, "empty": lambda: a[:0]}[choice]() if a.ndim == 2 else a[:0]
        what = choice
    else:
        a = a.astype(rng.choice([np.int32, np.float16, np.complex64]))
        what = f"dtype {a.dtype}"
    np.save(p, a)
    return f"{p.name}: {what}"


def _corrupt_text(rng: random.Random, p: Path) -> str:
    lines = p.read_text(errors="replace").splitlines()
    if not lines:
        return _corrupt_bytes(rng, p)
    i = rng.randrange(len(lines))
    op = rng.choice(["token", "token", "token", "delete", "dup", "cut"])
    if op == "token" and lines[i].split():
        toks = lines[i].split()
        j = rng.randrange(len(toks))
        toks[j] = rng.choice(["nan", "inf", "-1", "0", "abc", "1e400", "", "99999999999999999999", "-0"])
        lines[i] = " ".join(toks)
        what = f"line {i} token {j} -> {toks[j]!r}"
    elif op == "delete":
        del lines[i]
        what = f"deleted line {i}"
    elif op == "dup":
        lines.insert(i, lines[i])
        what = f"duplicated line {i}"
    else:
        lines[i] = lines[i][: rng.randrange(len(lines[i]) + 1)]
        what = f"cut line {i}"
    p.write_text("\n".join(lines) + "\n")
    return f"{p.name}: {what}"


def _corrupt_image(rng: random.Random, p: Path) -> str:
    try:
        with Image.open(p) as im:
            im.load()
            im = im.copy()
    except Exception:
        return _corrupt_bytes(rng, p)
    op = rng.choice(["size", "mode", "mode", "bytes"])
    if op == "size":
        im = im.resize((max(1, im.width + rng.choice([-7, -1, 1, 13, im.width])), max(1, im.height + rng.choice([-3, 0, 5]))))
        what = f"resized to {im.width}x{im.height}"
    elif op == "mode":
        mode = rng.choice(["L", "LA", "RGBA", "RGB", "P", "I;16", "1", "CMYK"])
        im = im.convert("L").convert("I;16") if mode == "I;16" else im.convert(mode)
        what = f"mode {mode}"
    else:
        return _corrupt_bytes(rng, p)
    fmt = "JPEG" if im.mode == "CMYK" else "PNG" if p.suffix.lower() == ".png" or im.mode in ("LA", "RGBA", "P", "I;16", "1") else "JPEG"
    im.save(p, format=fmt)
    return f"{p.name}: {what} ({fmt})"


def _corrupt_bytes(rng: random.Random, p: Path) -> str:
    data = bytearray(p.read_bytes())
    op = rng.choice(["truncate", "flip", "flip", "insert", "empty", "head"])
    if op == "truncate" or not data:
        cut = rng.randrange(len(data) + 1) if data else 0
        data = data[:cut]
        what = f"truncated at {cut}"
    elif op == "flip":
        n = rng.choice([1, 2, 8, 64])
        for _ in range(n):
            i = rng.randrange(len(data))
            data[i] ^= 1 << rng.randrange(8)
        what = f"{n} bits flipped"
    elif op == "insert":
        i = rng.randrange(len(data) + 1)
        data[i:i] = bytes(rng.randrange(256) for _ in range(rng.choice([1, 7, 100])))
        what = f"bytes inserted at {i}"
    elif op == "head":  # the first bytes: magic numbers, counts, headers
        for _ in range(4):
            data[rng.randrange(min(len(data), 24))] = rng.randrange(256)
        what = "header bytes changed"
    else:
        data = bytearray()
        what = "emptied"
    p.write_bytes(bytes(data))
    return f"{p.name}: {what}"


def corrupt(rng: random.Random, folder: Path) -> str:
    """One corruption of a file (or the removal of one) under ``folder``; returns what it did."""
    with warnings.catch_warnings(), np.errstate(all="ignore"):  # casts to int / float16 / complex on purpose
        warnings.simplefilter("ignore")
        return _corrupt(rng, folder)


def _corrupt(rng: random.Random, folder: Path) -> str:
    files = sorted(f for f in folder.rglob("*") if f.is_file())
    if rng.random() < 0.08:
        f = rng.choice(files)
        f.unlink()
        return f"deleted {f.relative_to(folder)}"
    # the scene description is where most of the structure is
    desc = [f for f in files if f.suffix in (".json", ".npy", ".bin", ".txt")]
    f = rng.choice(desc) if desc and rng.random() < 0.7 else rng.choice(files)
    if f.suffix == ".json":
        return _corrupt_json(rng, f) if rng.random() < 0.8 else _corrupt_bytes(rng, f)
    if f.suffix == ".npy":
        return _corrupt_npy(rng, f) if rng.random() < 0.7 else _corrupt_bytes(rng, f)
    if f.suffix == ".txt":
        return _corrupt_text(rng, f) if rng.random() < 0.8 else _corrupt_bytes(rng, f)
    if f.suffix.lower() in (".png", ".jpg", ".jpeg"):
        return _corrupt_image(rng, f)
    return _corrupt_bytes(rng, f)


def _scene_is_sane(scene) -> str | None:
    for c in scene.cameras:
        for name, a in (("K", c.K), ("viewmat", c.viewmat), ("image", c.image)):
            if not np.all(np.isfinite(a)):
                return f"{c.name}: {name} is not finite"
        if c.K[0, 0] <= 0 or c.K[1, 1] <= 0 or c.image.shape != (c.height, c.width, 3):
            return f"{c.name}: bad intrinsics or image shape"
        if c.image.min() < 0 or c.image.max() > 1:
            return f"{c.name}: image values outside [0, 1]"
    return None


# ----------------------------------------------------------------------------------------------
# the config parser


def _config_paths():
    """Dotted keys of the whole config tree, and its values."""
    def walk(d, prefix=""):
        for k, v in d.items():
            if isinstance(v, dict) and v:
                yield from walk(v, prefix + k + ".")
            else:
                yield prefix + k, v
    return list(walk(to_dict(Config())))


def _fuzz_yaml(rng: random.Random, folder: Path, k: int) -> tuple[str, object, str]:
    src = rng.choice(RUN_CONFIGS)
    text = src.read_text()
    lines = text.splitlines()
    keys = _config_paths()
    op = rng.choice(["value", "value", "value", "key", "line", "bytes", "indent", "add"])
    if op == "value":
        data = yaml.safe_load(text) or {}
        key, _ = rng.choice(keys)
        node = data
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {}) if isinstance(node, dict) else {}
        value = rng.choice(ODD_VALUES + ["-1e-3", "lots", -5, 0.0, 2.5, "all"])
        if isinstance(node, dict):
            node[parts[-1]] = value
        text, what = yaml.safe_dump(data), f"{key} = {value!r}"
    elif op == "key":
        data = yaml.safe_load(text) or {}
        key, v = rng.choice(keys)
        parts = key.split(".")
        parts[rng.randrange(len(parts))] += rng.choice(["x", "_", "s"])
        text, what = yaml.safe_dump({**data, parts[0]: {".".join(parts[1:]): v} if len(parts) > 1 else v}), f"key {parts}"
    elif op == "line" and lines:
        i = rng.randrange(len(lines))
        lines[i] = lines[i][: rng.randrange(len(lines[i]) + 1)] + rng.choice(["", ":", " [", " {a", " - x", "\t"])
        text, what = "\n".join(lines), f"line {i} cut"
    elif op == "indent" and lines:
        i = rng.randrange(len(lines))
        lines[i] = rng.choice(["  ", "    ", ""]) + lines[i].lstrip()
        text, what = "\n".join(lines), f"line {i} re-indented"
    elif op == "add":
        text, what = text + rng.choice(["\nbase: missing.yaml\n", "\n- a list\n", "\ntrain: 5\n", "\n: empty\n",
                                         "\nbase: " + src.name + "\n"]), "line added"
    else:
        b = bytearray(text.encode())
        for _ in range(rng.choice([1, 4])):
            if b:
                b[rng.randrange(len(b))] = rng.randrange(256)
        text, what = b.decode("utf-8", "replace"), "bytes changed"
    p = folder / f"c{k}.yaml"
    p.write_text(text)
    return f"{src.name}: {what}", lambda: build_config([(str(p), read_yaml(p))]), str(p)


def _fuzz_set(rng: random.Random, keys) -> tuple[str, object, str]:
    key, v = rng.choice(keys)
    if rng.random() < 0.2:
        key = rng.choice([key + "x", key.replace(".", "..", 1), "." + key, key.split(".")[-1], "", "train", key + ".sub"])
    raw = rng.choice(["-1", "0", "nan", ".nan", ".inf", "-.inf", "abc", "[1, 2]", "{a: 1}", "null", "1e400", "true",
                      "[", "{", "'", "2.5", "all", "-1e-3", "", "[0.5, 1.0]", "[nan]", str(v)])
    text = f"{key}={raw}" if rng.random() > 0.05 else key
    return text, lambda: build_config([(f"--set {text}", parse_override(text))]), "--set"


# ----------------------------------------------------------------------------------------------


def _run(kind: str, n: int, trial, failures: list, outcomes: Counter) -> None:
    for k in range(n):
        what, call, must_name = trial(k)
        try:
            result = call()
        except (SceneError, ConfigError) as e:
            msg = str(e)
            if must_name not in msg:
                failures.append(f"{kind} #{k} ({what}): {type(e).__name__} names neither the file nor a key: {msg}")
            outcomes[(kind, type(e).__name__)] += 1
        except Exception as e:
            failures.append(f"{kind} #{k} ({what}): unexpected {type(e).__name__}: {e}\n"
                            + "".join(traceback.format_exception(e)[-4:]))
            outcomes[(kind, "unexpected")] += 1
        else:
            bad = _scene_is_sane(result) if not kind.startswith("config") else None
            if bad:
                failures.append(f"{kind} #{k} ({what}): loaded, but {bad}")
            outcomes[(kind, "loaded")] += 1


@needs_shared
def test_fuzzed_loaders_and_config_parser(bases, tmp_path, record_property, capsys):
    """>= 300 corrupted inputs: each loads normally or is refused with a SceneError / ConfigError naming the
    file or key; nothing else escapes."""
    failures: list[str] = []
    outcomes: Counter = Counter()
    work = tmp_path / "trial"

    for kind in ("nerfstudio", "colmap_bin", "colmap_txt", "llff", "blender"):
        base, views = bases[kind]
        rng = random.Random(f"{SEED}-{kind}")

        def trial(k, base=base, views=views, rng=rng):
            if work.exists():
                shutil.rmtree(work)
            shutil.copytree(base, work)
            what = "; ".join(corrupt(rng, work) for _ in range(rng.choice([1, 1, 1, 2, 3])))
            return what, lambda: load_scene(str(work), views=views), str(work)

        _run(kind, int(TRIALS[kind] * SCALE), trial, failures, outcomes)

    rng = random.Random(f"{SEED}-config")
    (tmp_path / "cfg").mkdir()
    _run("config_yaml", int(TRIALS["config_yaml"] * SCALE), lambda k: _fuzz_yaml(rng, tmp_path / "cfg", k), failures,
         outcomes)
    keys = _config_paths()
    _run("config_set", int(TRIALS["config_set"] * SCALE), lambda k: _fuzz_set(rng, keys), failures, outcomes)

    tried = sum(outcomes.values())
    kinds = sorted({k for k, _ in outcomes})
    summary = ", ".join(f"{k}: " + "/".join(f"{o} {n}" for (kk, o), n in sorted(outcomes.items()) if kk == k) for k in kinds)
    record_property("fuzz_inputs", tried)
    with capsys.disabled():
        print(f"\nfuzz (seed {SEED}): {tried} corrupted inputs, {len(failures)} unexpected outcomes; {summary}")
    assert not failures, f"{len(failures)} of {tried} fuzzed inputs:\n" + "\n\n".join(failures[:15])
    assert tried >= 300 * SCALE
    # the corrupter reaches both outcomes for every loader (a corrupter that breaks nothing, or everything,
    # would test little)
    for kind in kinds:
        if not kind.startswith("config"):
            assert outcomes[(kind, "loaded")] > 0 and outcomes[(kind, "SceneError")] > 0, (kind, outcomes)


# ----------------------------------------------------------------------------------------------
# what a person does: data no camera could have taken, one frame listed twice, lying headers, odd images, a config
# that sets a key twice. Each case says whether it must be refused (impossible data), must load (data a user may
# really mean) or either; the outcome is counted, and a traceback, a refusal that names nothing, a silent acceptance
# of impossible data or a refusal of meant data fails the test.

REFUSE, ACCEPT, EITHER = "refuse", "accept", "either"


def _person_base(root: Path) -> Path:
    from tiny_scene import write_nerfstudio

    return write_nerfstudio(root, n_frames=6)  # 48x48, fl 52.8, cx = cy = 24


def _edit_meta(work: Path, fn) -> None:
    meta = json.loads((work / "transforms.json").read_text())
    fn(meta)
    (work / "transforms.json").write_text(json.dumps(meta))


# (field, value in units of the image side (focal, principal point) or as is (distortion), expected)
_CAMERA_CASES = (
    [("fl_x", f, REFUSE) for f in (1e-6, 1e-3, 0.03, 0.049, 100.5, 300.0, 1e4, 1e28, 0.0, -1.1)]
    + [("fl_y", f, REFUSE) for f in (0.01, 150.0, 1e30)]
    + [("fl_x", f, ACCEPT) for f in (0.051, 0.2, 1.1, 10.0, 99.0)]
    + [(c, v, REFUSE) for c in ("cx", "cy") for v in (-1.01, -5.0, 2.01, 10.0, 1e9, -1e9)]
    + [(c, v, ACCEPT) for c in ("cx", "cy") for v in (-0.99, -0.3, 0.5, 1.4, 1.99)]
    + [("k1", v, REFUSE) for v in (10.0, 1e3, -3.0, -1.0, -1e6)] + [("k2", v, REFUSE) for v in (100.0, -40.0)]
    + [("k3", 1e4, REFUSE), ("p1", 0.6, REFUSE), ("p2", -5.0, REFUSE)]
    + [("k1", v, ACCEPT) for v in (-0.3, -0.1, 0.05, 0.3, 1.0)] + [("k2", v, ACCEPT) for v in (0.05, -0.02)]
    + [("p1", 0.001, ACCEPT), ("p2", -0.002, ACCEPT)]
)


def _camera_case(rng: random.Random, work: Path):
    field, v, expect = rng.choice(_CAMERA_CASES)
    value = v * 48 if field in ("fl_x", "fl_y", "cx", "cy") else v
    per_frame = rng.random() < 0.5

    def edit(meta):
        target = rng.choice(meta["frames"]) if per_frame else meta
        target[field] = value
        if field in ("cx", "cy") and per_frame:  # a frame with its own intrinsics states all of them
            for k in ("fl_x", "fl_y", "cx", "cy"):
                target.setdefault(k, meta[k])

    _edit_meta(work, edit)
    return f"{field} = {value:g} ({'one frame' if per_frame else 'every frame'})", expect


def _path_case(rng: random.Random, work: Path):
    meta = json.loads((work / "transforms.json").read_text())
    frames = meta["frames"]
    i, j = rng.sample(range(len(frames)), 2)
    name_i = Path(frames[i]["file_path"]).name
    name_j = Path(frames[j]["file_path"]).name
    op = rng.choice(["spelling", "spelling", "absolute", "symlink", "copy", "folder_link", "own_spelling", "moved_link"])
    if op == "spelling":
        spelling = rng.choice(["images/./{n}", "./images/{n}", "images//{n}", "images/../images/{n}"]).format(n=name_i)
        frames[j]["file_path"], expect, what = spelling, REFUSE, f"frame {j} is {spelling}"
    elif op == "absolute":
        frames[j]["file_path"], expect, what = str(work / "images" / name_i), REFUSE, f"frame {j} by absolute path"
    elif op == "symlink":
        (work / "images" / "alias.png").symlink_to(name_i)
        frames[j]["file_path"], expect, what = "images/alias.png", REFUSE, f"frame {j} a symlink to frame {i}'s file"
    elif op == "copy":
        shutil.copy(work / "images" / name_i, work / "images" / "copy.png")
        frames[j]["file_path"], expect, what = "images/copy.png", REFUSE, f"frame {j} a byte-identical copy"
    elif op == "folder_link":
        (work / "imgs").symlink_to("images")
        frames[j]["file_path"], expect, what = f"imgs/{name_j}", ACCEPT, f"frame {j} through a symlinked folder"
    elif op == "own_spelling":
        frames[j]["file_path"], expect, what = f"./images/./{name_j}", ACCEPT, f"frame {j} spelled ./images/./"
    else:
        (work / "elsewhere").mkdir()
        shutil.move(work / "images" / name_j, work / "elsewhere" / name_j)
        (work / "images" / name_j).symlink_to(Path("..") / "elsewhere" / name_j)
        expect, what = ACCEPT, f"frame {j}'s file a symlink to its own moved file"
    (work / "transforms.json").write_text(json.dumps(meta))
    return what, expect


def _image_case(rng: random.Random, work: Path):
    meta = json.loads((work / "transforms.json").read_text())
    j = rng.randrange(len(meta["frames"]))
    p = work / meta["frames"][j]["file_path"]
    op = rng.choice(["constant", "noise", "one_bit", "sixteen_bit", "transparent", "all_black"])
    g = np.random.default_rng(rng.randrange(1 << 30))
    if op == "constant":
        Image.fromarray(np.full((48, 48, 3), rng.choice([0, 1, 128, 255]), np.uint8)).save(p)
    elif op == "noise":
        Image.fromarray(g.integers(0, 256, (48, 48, 3), dtype=np.uint8)).save(p)
    elif op == "one_bit":
        Image.fromarray(g.integers(0, 2, (48, 48), dtype=np.uint8) * 255).convert("1").save(p)
    elif op == "sixteen_bit":
        Image.fromarray(np.full((48, 48), rng.choice([0, 65535, 1]), np.uint16)).save(p)
    elif op == "transparent":  # alpha 0 everywhere: the colour under it is 0 / 0 without care
        Image.fromarray(np.zeros((48, 48, 4), np.uint8)).save(p)
    else:  # every frame the same black image: byte-identical files
        for fr in meta["frames"]:
            Image.fromarray(np.zeros((48, 48, 3), np.uint8)).save(work / fr["file_path"])
        return "every frame black", REFUSE
    return f"frame {j}: {op}", ACCEPT


def _ply_case(rng: random.Random, work: Path):
    """A Gaussian or point PLY with a lying or incomplete header; read as viz reads it."""
    from warpgs.model import GaussianModel
    from warpgs.ply import read_vertices, write_vertices
    from warpgs.viz import save_origin_ply

    g = np.random.default_rng(rng.randrange(1 << 30))
    n = rng.choice([1, 7, 50])
    if rng.random() < 0.5:
        path = GaussianModel.from_points(g.uniform(-1, 1, (n, 3)).astype(np.float32),
                                         g.random((n, 3)).astype(np.float32), sh_degree=rng.choice([0, 1])).save_ply(work / "g.ply")
    else:
        path = save_origin_ply(work / "p.ply", g.normal(size=(n, 3)), g.random((n, 3)))
    data = path.read_bytes()
    head_end = data.index(b"end_header\n") + len(b"end_header\n")
    head, body = data[:head_end], data[head_end:]
    op = rng.choice(["count", "count", "negative", "truncate", "drop", "comment", "extra_element", "ascii_claim"])
    if op == "count":
        k = rng.choice([2, 10, 10**6, 2**31, 2**40, 10**14])
        head, expect, what = head.replace(f"element vertex {n}".encode(), f"element vertex {n * k}".encode()), REFUSE, f"count x{k}"
    elif op == "negative":
        head, expect, what = head.replace(f"element vertex {n}".encode(), b"element vertex -5"), REFUSE, "count -5"
    elif op == "truncate":
        body, expect, what = body[: rng.randrange(len(body))], REFUSE, "body truncated"
    elif op == "drop" and path.name == "g.ply":
        v = read_vertices(path)
        drop = rng.choice([["opacity"], ["scale_0"], ["rot_0", "rot_1", "rot_2", "rot_3"], ["scale_2", "rot_3"]])
        keep = [k for k in v if k not in drop]
        rec = np.zeros(n, dtype=[(k, "<f4") for k in keep])
        for k in keep:
            rec[k] = v[k]
        write_vertices(path, rec)
        return path, f"Gaussian PLY without {drop}", REFUSE
    elif op == "ascii_claim":
        head, expect, what = head.replace(b"binary_little_endian", b"ascii"), EITHER, "binary body under an ascii header"
    elif op == "extra_element":
        head, expect, what = head.replace(b"end_header", b"element face 0\nproperty list uchar int vertex_indices\nend_header"), ACCEPT, "an empty face element"
    else:
        head, expect, what = head.replace(b"end_header", b"comment written by hand\ncomment another\nend_header"), ACCEPT, "comments"
    path.write_bytes(head + body)
    return path, what, expect


def _yaml_case(rng: random.Random, work: Path, k: int):
    src = rng.choice(RUN_CONFIGS)
    lines = src.read_text().splitlines()
    keyed = [i for i, ln in enumerate(lines) if ":" in ln and not ln.lstrip().startswith(("#", "-"))  # leaves only:
             and ln.split(":", 1)[0].strip() and ln.split(":", 1)[1].split("#")[0].strip()  # a value, not a comment
             and ln.split(":", 1)[0].strip() != "base"]
    p = work / f"y{k}.yaml"
    if not keyed or rng.random() < 0.25:  # the same leaf name under two parents: an ordinary config
        p.write_text("train:\n  iterations: 10\nmodel:\n  iterations_note: 1\neval:\n  iterations: 3\n")
        return p, "one name under two parents", ACCEPT, None
    i = rng.choice(keyed)
    key = lines[i].split(":", 1)[0].strip()
    indent = lines[i][: len(lines[i]) - len(lines[i].lstrip())]
    lines.insert(i + 1, f"{indent}{key}: {rng.choice(['1', '0.5', 'true', 'x'])}")
    p.write_text("\n".join(lines) + "\n")
    return p, f"{src.name}: {key} set twice", REFUSE, key


@needs_shared
def test_fuzzed_person_inputs(tmp_path, capsys):
    """Implausible cameras, aliased and symlinked paths, degenerate images, lying PLY headers, YAML keys set twice:
    each refused with a message naming the file, frame, field or key, or loaded when a user may mean it."""
    from warpgs.viz import read_cloud

    base = _person_base(tmp_path / "base")
    rng = random.Random(f"{SEED}-person")
    failures: list[str] = []
    counts: Counter = Counter()
    work = tmp_path / "work"

    def judge(kind, k, what, expect, call, must_name):
        try:
            result = call()
        except (SceneError, ConfigError, ValueError) as e:
            counts[(kind, "refused")] += 1
            if expect == ACCEPT:
                failures.append(f"{kind} #{k} ({what}): refused data a user may mean: {e}")
            elif must_name and must_name not in str(e):
                failures.append(f"{kind} #{k} ({what}): the refusal names neither file nor key: {e}")
            elif "\n" in str(e):
                failures.append(f"{kind} #{k} ({what}): the refusal is not one line: {e}")
        except Exception as e:
            counts[(kind, "traceback")] += 1
            failures.append(f"{kind} #{k} ({what}): {type(e).__name__}: {e}\n" + "".join(traceback.format_exception(e)[-4:]))
        else:
            counts[(kind, "loaded")] += 1
            if expect == REFUSE:
                counts[(kind, "silent")] += 1
                failures.append(f"{kind} #{k} ({what}): impossible data accepted without a word")
            elif kind != "yaml" and kind != "ply" and _scene_is_sane(result):
                failures.append(f"{kind} #{k} ({what}): loaded, but {_scene_is_sane(result)}")

    for kind, make, n in (("camera", _camera_case, 140), ("path", _path_case, 100), ("image", _image_case, 60)):
        for k in range(int(n * SCALE)):
            if work.exists():
                shutil.rmtree(work)
            shutil.copytree(base, work, symlinks=True)
            what, expect = make(rng, work)
            judge(kind, k, what, expect, lambda: load_scene(str(work), views="all"), str(work))  # every frame read
    for k in range(int(100 * SCALE)):
        if work.exists():
            shutil.rmtree(work)
        work.mkdir()
        path, what, expect = _ply_case(rng, work)
        judge("ply", k, what, expect, lambda: read_cloud(path), str(path))
    (tmp_path / "yaml").mkdir()
    for k in range(int(60 * SCALE)):
        path, what, expect, key = _yaml_case(rng, tmp_path / "yaml", k)
        judge("yaml", k, what, expect, lambda: read_yaml(path), key and f"{key!r}")

    tried = sum(n for (_, o), n in counts.items() if o in ("refused", "loaded", "traceback"))
    refused = sum(n for (_, o), n in counts.items() if o == "refused")
    tracebacks = sum(n for (_, o), n in counts.items() if o == "traceback")
    silent = sum(n for (_, o), n in counts.items() if o == "silent")
    with capsys.disabled():
        print(f"\nfuzz person (seed {SEED}): {tried} cases, {refused} refused, {tried - refused - tracebacks} loaded; "
              f"{tracebacks} tracebacks, 0 native crashes, {silent} silent acceptances of impossible data")
    assert not failures, f"{len(failures)} of {tried} cases:\n" + "\n\n".join(failures[:15])
    assert tried >= 400 * SCALE
    for kind in ("camera", "path", "ply", "yaml"):  # every generator reaches both outcomes
        assert counts[(kind, "refused")] > 0 and counts[(kind, "loaded")] > 0, (kind, counts)


def _sparse(data: Path, out: Path, *extra: str, env: dict | None = None) -> subprocess.CompletedProcess:
    argv = ["--data", str(data), "--views", "3", "--device", "cpu", "--no-progress", "--method", "baseline",
            "--set", "model.init=box", "--set", "model.init_box=[-1.2,-1.2,-1.2,1.2,1.2,1.2]", "--set", "model.init_num=200",
            "--set", "eval.lpips_weights=/nonexistent/alexnet.pth", "--set", "eval.fps_repeats=1",
            "--set", "eval.save_images=false", "--iterations", "5", "--out", str(out), *extra]
    return subprocess.run([sys.executable, "-m", "warpgs.pipelines.sparse", *argv], capture_output=True, text=True,
                          timeout=900, cwd=Path(__file__).resolve().parents[1], env={**os.environ, **(env or {})})


def test_fuzzed_person_inputs_through_the_main_job(tmp_path, capsys):
    """A few of the cases above through ``python -m warpgs.pipelines.sparse``, pycolmap included: impossible data
    ends with exit code 2 and one ``error:`` line naming the field; data a user may mean (a degenerate image), and an
    SfM whose native child dies (a real SIGSEGV, injected through the test hook), train to the end (exit 0), the
    fallback recorded in metrics.json."""
    from warpgs.densify.native import FAULT_ENV

    base = _person_base(tmp_path / "base")

    def variant(name, edit=None, image=None):
        work = tmp_path / name
        shutil.copytree(base, work)
        if edit:
            _edit_meta(work, edit)
        if image is not None:
            Image.fromarray(image).save(work / "images" / "f002.png")
        return work

    def set_all(field, value):
        return lambda meta: meta.__setitem__(field, value)

    def alias(meta):
        meta["frames"][3]["file_path"] = "images/./" + Path(meta["frames"][1]["file_path"]).name

    refused = [("cx far outside", variant("cx", set_all("cx", 1e6)), ["cx", "principal point"]),
               ("fl_x 1e30", variant("fl", set_all("fl_x", 1e30)), ["fx", "implausible intrinsics"]),
               ("k1 1000", variant("k1", set_all("k1", 1e3)), ["k1", "distortion"]),
               ("one image twice", variant("alias", alias), ["'images/f001.png'", "'images/./f001.png'", "listed twice"])]
    counts = Counter()
    for what, data, words in refused:
        r = _sparse(data, tmp_path / f"out_{data.name}")
        errors = [ln for ln in r.stderr.splitlines() if ln.startswith("error: ")]
        counts["native crashes"] += r.returncode < 0
        counts["tracebacks"] += "Traceback" in r.stderr
        assert r.returncode == 2 and len(errors) == 1 and "Traceback" not in r.stderr, (what, r.returncode, r.stderr[-3000:])
        for w in words:
            assert w in errors[0], (what, errors[0])
    flat = variant("flat", image=np.full((48, 48, 3), 128, np.uint8))
    r = _sparse(flat, tmp_path / "out_flat")
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-3000:]
    r = _sparse(base, tmp_path / "out_sfm", "--set", "model.init=sfm", env={FAULT_ENV: "sfm:segv"})
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-3000:]
    init = json.loads((tmp_path / "out_sfm" / "metrics.json").read_text())["init"]
    assert any("SIGSEGV" in line for line in init["native_failures"]), init
    assert init["method"] != "sfm" and sum(1 for ln in r.stderr.splitlines() if "SIGSEGV" in ln) == 1, r.stderr[-3000:]
    with capsys.disabled():
        print(f"\nfuzz person end to end: 6 runs, 4 refused with exit 2, 2 trained; {counts['tracebacks']} tracebacks, "
              f"{counts['native crashes']} native crashes")
