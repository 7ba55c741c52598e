"""Device check (session 17): the new CUDA backward (reduce-scatter accumulation) and SH kernels against the
committed ones (HEAD's files beside this script): gradients bit for bit, fixed point and float atomics, with and
without depth, on random Gaussians and (if given) a trained PLY."""
import importlib.util, sys, json, torch
sys.path.insert(0, ".")
sys.path.insert(0, "bench")
import warpgs.render as R
from warpgs.kernels import rasterize as new_kr, sh as new_sh

def load(name, path):
    spec = importlib.util.spec_from_file_location(name, path)
    m = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(m)
    return m

old_kr = load("rasterize_old", ".device/s17/rasterize_old.py")
old_sh = load("sh_old", ".device/s17/sh_old.py")
import rasterizer as rb

def grads(inp, w, h, deterministic, depth):
    p = rb.grad_inputs(inp)
    out = R.rasterize(p["means"], p["quats"], p["scales"], p["opacities"], p["colors"], inp["viewmat"], inp["K"], w, h,
                      sh_degree=inp.get("sh_degree"), deterministic=deterministic, check_finite=False)
    loss = (out.image * inp["w_img"]).sum() + (out.depth.sum() * 1e-3 if depth else 0.0)
    loss.backward()
    return [out.image.detach().clone()] + [p[k].grad.clone() for k in ("means", "quats", "scales", "opacities", "colors")]

res = {}
cases = [("random", rb.make_inputs(138766, 648, 420, "cuda"), 648, 420)]
if len(sys.argv) > 1:
    model, view = rb.trained_model_and_view(sys.argv[1], "llff", sys.argv[2], "cuda")
    inp, w, h = rb.inputs_from_model(model, view, 2.0, "cuda")
    cases.append(("trained", inp, w, h))
for name, inp, w, h in cases:
    for det in (True, False):
        for depth in (False, True):
            R.kr = old_kr
            a = grads(inp, w, h, det, depth)
            R.kr = new_kr
            b = grads(inp, w, h, det, depth)
            key = f"{name} {'fixed' if det else 'float'} {'depth' if depth else 'rgb'}"
            res[key] = {"bit_equal": [bool(torch.equal(x, y)) for x, y in zip(a, b)],
                        "max_rel": [float(((x - y).abs().max() / y.abs().max().clamp_min(1e-30))) for x, y in zip(a, b)]}
            print(key, res[key], flush=True)
print(json.dumps(res))
