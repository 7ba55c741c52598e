"""A deferred training step as one CUDA graph (``train.cuda_graph``): the host launches it in one call.

On a GPU the training step is bound by the host: a step of fern at 504x378 keeps the GPU busy about a fifth of
the time, the rest is Python and the launches of some hundred kernels and torch operations (measured in
``bench/perf/host_profile.py``). A step whose verdict the host reads later (``StepGuard.deferred_step``) has no host
read left but one, the render's count of tile intersections that sizes its sort buffers, so it can be
recorded once as a CUDA graph and replayed:

    graph = StepGraph(trainer)
    if graph.covers(step, cam):          # a deferred step the graph can hold (below)
        info = graph.step(step, cam)     # None: captured nothing (the trainer runs the step itself)

What one replay does, in order, is exactly the deferred step: render the view, the loss, backward, the guard's
verdict on the device (``DivergenceGuard.step_on_device``), the masked fused Adam update, the densification
statistics (``update_state``). What changes from step to step is read from the device: the camera, target and
background (copied into the graph's own tensors; a random colour behind an alpha channel and the far field's
image are made outside the graph, as the step without it makes them), the means' learning rate
(``GroupedAdam.set_lr``), the guard's slot (``LossWindow.set_slot``), DropGaussian's rate
(``Dropout.rate_tensors``). Dropout and opacity noise draw inside the graph from the trainer's
``drop_gen``, registered with it (``register_generator_state``), and the binocular term draws its partner's move
from its own generator, registered too: each replay draws anew, the numbers the step without the graph would
draw. The full method's pseudo view (``FullMethod.graph_inputs``) is picked on the host before the replay and its
tensors (pose, image, masks, depth, far-field image; the input's depth prior) copied into the graph's own. The
renders use buffers of a fixed capacity (``rasterize(isect_capacity=...)``): before each replay
``count_intersections`` counts the input's and the pseudo view's intersections (one host read, as the step without
the graph makes one per render; on opacities scaled by the largest factor dropout and noise can give,
``Regularizers.opacity_scale_bound``, since the screen box grows with the opacity) and a count above the capacity
records the graph again with more room, so neither ever renders less than it would without the graph. The
binocular partner's pose is drawn on the device, so its count cannot be read first: it renders into the same
capacity (1.5x the largest count); a render that needed more sits its term out for that step and is counted
(``Binocular.overflows``), and the next recording gets twice the room. Otherwise the same kernels in the same order
give the same numbers as the step without the graph, bit for bit (``bench/perf/graph_check.py`` checks it on a
GPU).

The graph is recorded again whenever what it holds changed: the Gaussians (growth, pruning, a reset, a
rollback: other tensors), the optimiser's state or its other learning rates, the densification statistics,
the guard's window, the image size, the SH degree in use, the kind of background, whether the binocular term is
on, which of the pseudo view's tensors exist. It covers only steps with nothing the graph cannot hold: no
densification at that step (``Trainer.densify_only_updates_state``), no Pearson depth prior of the baseline's
``loss.depth_prior: scene``, no co-regularised pair, no path consistency, no LPIPS on the pseudo views
(``FullMethod.graph_safe``). A recording that fails turns the graphs off for the run, with one line saying why;
training goes on without them.
"""

from __future__ import annotations

import dataclasses

import torch

from warpgs import render
from warpgs.render import count_intersections, means2d_grad_norm


class StepGraph:
    def __init__(self, trainer):
        self.tr = trainer
        self.graph: torch.cuda.CUDAGraph | None = None
        self.key = None  # what the recorded graph holds (``_key``)
        self.capacity = 0  # the render's intersection buffers
        self.record: torch.Tensor | None = None  # the graph's output: the step's record (``StepGuard.step_record``'s layout)
        self.off: str | None = None  # why the graphs are off for this run
        self.captures = 0
        self.replays = 0
        self.stream = torch.cuda.Stream(trainer.device)
        self.inputs: dict[str, torch.Tensor] = {}
        self.background: torch.Tensor | None = None  # what the recorded step renders over
        self.extra: dict[str, torch.Tensor] = {}  # the method's inputs of the step (``Method.graph_inputs``)
        self.headroom = 1.5  # capacity / the largest count of the step's views: room for a pose drawn on the device
        self.cut = 0  # renders cut short by the capacity so far (``Regularizers.graph_counters``)

    # ------------------------------------------------------------------------------------------

    def covers(self, step: int, cam) -> bool:
        """Whether the deferred step ``step`` on the view ``cam`` can be a replay (module docstring)."""
        tr = self.tr
        lc = tr.cfg.loss
        if self.off is not None or tr.pair is not None:
            return False
        if self.generators() and not hasattr(torch.cuda.CUDAGraph, "register_generator_state"):
            return False  # a torch whose graphs cannot hold draws from the trainer's own generators
        if lc.depth_weight > 0 and lc.depth_prior == "scene" and cam.depth is not None:
            return False
        if not tr.regularizers.graph_safe(tr.context, step):
            return False  # e.g. a second render a step, of a pose drawn anew: not held
        if not tr.densify_only_updates_state(step) or not getattr(tr.method, "graph_safe", lambda: False)():
            return False
        # every parameter has its Adam state (the first step makes it, outside any graph)
        return all(len(opt.state) == sum(len(g["params"]) for g in opt.param_groups) for opt in tr.optimizers)

    def draws(self, step: int) -> bool:
        """Whether the step's render draws from the trainer's ``drop_gen`` (DropGaussian, opacity noise): the graph
        holds the draws (the generator is registered with it, so each replay draws anew, what the step without
        the graph would draw) and reads the dropout rate from the device (``Dropout.rate_tensors``)."""
        return self.tr.regularizers.opacity_scale_bound(self.tr.context, step) is not None

    def step(self, step: int, cam) -> dict | None:
        """Step ``step`` on the view ``cam`` as a replay: the record waits in the trainer's ``_pending`` as a
        deferred step's does. None (nothing done) when recording failed."""
        tr = self.tr
        model = tr.model
        window = tr.stepguard.loss_window(step)
        # the method's inputs of the step (its pseudo view, picked now) and the cameras it renders besides ``cam``
        extra_key, extra, extra_cams = tr.method.graph_inputs(cam)
        bound = tr.regularizers.opacity_scale_bound(tr.context, step)  # dropout's and the noise's largest factor: the count bounds the render's
        with torch.no_grad():  # no autograd graph outlives this: one that holds a parameter's gradient accumulator,
            # made on the default stream, makes the recording's backward wait on that stream, which voids the capture
            opac = model.opacities if bound is None else model.opacities * bound
            counts = [count_intersections(model.means, model.quats, model.scales, opac, c.viewmat, c.K, c.width,
                                          c.height, read=False) for c in [cam, *extra_cams]]
        del opac
        counters = tr.regularizers.graph_counters()  # renders cut short by the capacity (the moved binocular one)
        values = torch.stack([c.reshape(()).to(torch.int64) for c in counts + counters]).tolist()  # one host read
        count = max(values[:len(counts)])
        cut = sum(values[len(counts):])
        if cut > self.cut:  # a render of a pose drawn on the device needed more: record with more room
            self.cut, self.headroom = cut, self.headroom * 2
            self.key = None
        # the target and background of the step (a random colour behind an alpha channel, the far field), as
        # the step without the graph makes them, outside the graph
        cam, bg = tr.with_training_background(cam, tr.split_gen)
        dropout = tr.regularizers.get("dropout")
        if dropout is not None and dropout.rate_at(tr.context, step) > 0:
            dropout.rate_tensors(tr.context, step)
        key = self._key(cam, bg) + (extra_key,)
        if self.graph is None or key != self.key or count > self.capacity:
            capacity = max(int(count * self.headroom), 1024)  # room for the other views and the next steps' growth
            if not self._capture(cam, bg, capacity, extra, extra_key):
                return None
        inp = self.inputs
        inp["viewmat"].copy_(cam.viewmat)
        inp["K"].copy_(cam.K)
        inp["image"].copy_(cam.image)
        if cam.alpha is not None:
            inp["alpha"].copy_(cam.alpha)
        if "bg" in inp:
            inp["bg"].copy_(bg)
        for name, t in extra.items():
            self.extra[name].copy_(t)
        window.set_slot(step)
        self.graph.replay()
        self.replays += 1
        tr.method.graph_done()
        tr.stepguard.pending.append((step, tr.guard.stat_start, self.record.clone()))
        return {"cloned": 0, "split": 0, "pruned": 0, "reset": 0}

    def generators(self) -> list[tuple[object, str]]:
        """The device generators the step at ``tr.step`` draws from, as (holder, attribute): the trainer's
        ``drop_gen`` when it draws (``draws``), then the regularisers' own (the binocular partner's move)."""
        tr = self.tr
        return ([(tr, "drop_gen")] if self.draws(tr.step) else []) + tr.regularizers.graph_generators()

    # ------------------------------------------------------------------------------------------

    def _key(self, cam, bg) -> tuple:
        """Everything the recorded graph holds that may change between steps: the tensors it reads and writes
        (by address), the numbers it was recorded with."""
        tr = self.tr
        model = tr.model
        ptrs = [p.data_ptr() for p in model.params.values()] + [len(model)]
        for opt in tr.optimizers:
            for g in opt.param_groups:
                ptrs.append((g.get("name"), g["lr"] if g.get("name") not in opt.lr_tensors else None,
                             g["betas"], g["eps"]))
                for p in g["params"]:
                    ptrs.append(p.data_ptr())
                    ptrs.extend(v.data_ptr() for v in opt.state[p].values() if isinstance(v, torch.Tensor))
            ptrs.extend(t.data_ptr() for t in opt.lr_tensors.values())
        ptrs.extend(v.data_ptr() for v in tr.state.values())
        w = tr.stepguard.window
        ptrs += [w.values.data_ptr(), w.middle.data_ptr(), w.slot.data_ptr(), tr.background.data_ptr()]
        ptrs += [t.data_ptr() for t in tr.regularizers.graph_tensors()]
        ptrs += [b.data_ptr() for b in render._ZERO_INPUTS.values()]  # the zeros a backward reads (it only grows)
        sc = tr.strategy
        return (tuple(ptrs), cam.width, cam.height, cam.alpha is not None, model.active_sh_degree,
                tr.step < sc.refine_stop_iter, tr.regularizers.graph_key(tr.context, tr.step), tr.guard.cfg.explode_factor,
                bg is tr.background, tuple(bg.shape), self.draws(tr.step))

    def _capture(self, cam, bg, capacity: int, extra: dict, extra_key: tuple) -> bool:
        """Records the step (a warm-up of its forward and backward on the graph's stream first, then the capture);
        False, with the graphs off for the run, when that fails. ``extra``: the method's inputs of the step
        (``Method.graph_inputs``), copied into the recording's own tensors."""
        tr = self.tr
        # the previous recording lives until this one is made, which records into its memory pool: a pool of its
        # own each time would leave every old pool's memory reserved when its graph goes (torch frees a dropped
        # graph's pool only on empty_cache or its own out of memory), tens of GB over a run's recordings, out of
        # reach of other processes on the GPU (and of this one's CUDA, cuBLAS and Warp allocations)
        previous, self.graph, self.record = self.graph, None, None
        self.inputs = inp = {"viewmat": cam.viewmat.clone(), "K": cam.K.clone(), "image": cam.image.clone()}
        if cam.alpha is not None:
            inp["alpha"] = cam.alpha.clone()
        if bg is not tr.background:  # a random colour or the far field's image: copied in before each replay
            inp["bg"] = bg.clone()
        self.extra = {name: t.clone() for name, t in extra.items()}
        self.background = inp.get("bg", tr.background)
        static = dataclasses.replace(cam, viewmat=inp["viewmat"], K=inp["K"], image=inp["image"],
                                     alpha=inp.get("alpha"), depth=None, mask=None)
        gens = self.generators()
        drawn = None
        tr.method.graph_bind(self.extra)
        try:
            self.stream.wait_stream(torch.cuda.current_stream(tr.device))
            # the warm-up's draws are given back: the replays draw what eager steps would
            drawn = [getattr(holder, name).get_state() for holder, name in gens]
            with torch.cuda.stream(self.stream):  # the warm-up: lazy set-ups happen outside the capture
                out, _, _ = tr.forward_backward(tr.step, static, self.background, capacity)
                means2d_grad_norm(out, static.width, static.height)  # its constant is made here, not in the capture
                for opt in tr.optimizers:
                    opt.zero_grad(set_to_none=True)
                del out
            torch.cuda.current_stream(tr.device).wait_stream(self.stream)
            for (holder, name), state in zip(gens, drawn):
                getattr(holder, name).set_state(state)
            # capture_begin / capture_end rather than torch.cuda.graph, whose entry collects Python's garbage and
            # empties the allocator's cache each time (tens of milliseconds a recording)
            graph = torch.cuda.CUDAGraph()
            for holder, name in gens:
                graph.register_generator_state(getattr(holder, name))
            with torch.cuda.stream(self.stream):
                # thread_local: CUDA calls of other threads (a user's, a library's) do not void this thread's capture
                graph.capture_begin(pool=previous.pool() if previous is not None else None,
                                    capture_error_mode="thread_local")
                try:
                    self.record = self._body(static, capacity)
                except BaseException:  # the op the capture refused, not capture_end's "previous error during capture"
                    try:
                        graph.capture_end()
                    except Exception:  # noqa: BLE001 - the capture is void already
                        pass
                    raise
                graph.capture_end()
            torch.cuda.current_stream(tr.device).wait_stream(self.stream)
        except Exception as e:  # noqa: BLE001 - anything the capture refuses: the step runs without it
            first = str(e).strip().splitlines()
            self.off = f"{type(e).__name__}: {first[0] if first else ''}"  # one line (CUDA's errors add advice lines)
            self.graph = self.record = None
            for opt in tr.optimizers:
                opt.zero_grad(set_to_none=True)
            if drawn is not None:
                # a generator registered with a capture that failed can refuse the eager steps' draws ("Offset
                # increment outside graph capture"): the run goes on with fresh ones at the states this step starts
                # from, so they draw what they would have
                for (holder, name), state in zip(gens, drawn):
                    fresh = torch.Generator(device=tr.device)
                    fresh.set_state(state)
                    setattr(holder, name, fresh)
            tr.log(f"warpgs: CUDA graphs off for this run (train.cuda_graph): recording the step failed: {self.off}")
            return False
        finally:
            tr.method.graph_bind(None)
        self.graph, self.capacity = graph, capacity
        self.key = self._key(cam, bg) + (extra_key,)  # as it is now: the warm-up may have grown the backward's zeros
        self.captures += 1
        return True

    def _body(self, cam, capacity: int) -> torch.Tensor:
        """What the graph holds: ``Trainer.train_step``'s deferred step (``forward_backward``, ``update_on_device``,
        the densification statistics of ``densify``, which does no more at a covered step); returns its record."""
        tr = self.tr
        step = tr.step
        out, loss, inputs = tr.forward_backward(step, cam, self.background, capacity)
        record, apply = tr.stepguard.update_on_device(None, loss, inputs)
        # a step without its update is one in which no Gaussian was seen, for the densification statistics
        tr.densify(tr.strategy, tr.model, tr.optimizer, tr.state, step, out._replace(radii=out.radii * apply), cam,
                   tr.split_gen)
        return record
