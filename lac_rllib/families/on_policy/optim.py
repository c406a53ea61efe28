"""Adam with torch's multi-tensor ops and the per-tensor loop's arithmetic, learning-rate tensors
included.

The baselines step three or four small networks' optimizers on every minibatch, and
``torch.optim.Adam``'s per-tensor loop (the CPU default) spends its time in Python, ~10 tensor
calls per parameter. ``foreach=True`` would make a few calls per network instead, but refuses the
learning rate RLlib's scheduler sets, a 0-d tensor, and with a float rate rounds the step size
differently from the loop (the loop divides the float32 tensor rate by the bias correction in
float32): every seeded run would change. :class:`ForeachAdam` is ``torch.optim.Adam`` (its state,
``state_dict``, defaults) whose step does the loop's arithmetic (``_single_tensor_adam``, torch
2.13, ``amsgrad``, ``maximize``, weight decay and ``capturable`` off) with ``torch._foreach_*``
ops: bit for bit the same weights and moments, float or tensor rate
(tests/families/on_policy/test_optim.py).

Plain torch, no RLlib.
"""

from __future__ import annotations

import torch


class ForeachAdam(torch.optim.Adam):
    def __init__(self, params, lr=1e-3, betas=(0.9, 0.999), eps=1e-8):
        super().__init__(params, lr=lr, betas=betas, eps=eps, foreach=False)

    @torch.no_grad()
    def step(self, closure=None):
        if closure is not None:
            raise ValueError("ForeachAdam.step takes no closure")
        step_adams([self])

    def _live_groups(self):
        """(group, its parameters that have a gradient, their states initialised as Adam's)."""
        for group in self.param_groups:
            if group["amsgrad"] or group["maximize"] or group["weight_decay"] or group["capturable"]:
                raise ValueError("ForeachAdam implements plain Adam only (no amsgrad, maximize, "
                                 "weight_decay or capturable)")
            params = [p for p in group["params"] if p.grad is not None]  # None: not stepped, as Adam
            for p in params:
                state = self.state[p]
                if not state:  # torch.optim.Adam's _init_group
                    state["step"] = torch.tensor(0.0, dtype=torch.float32)
                    state["exp_avg"] = torch.zeros_like(p, memory_format=torch.preserve_format)
                    state["exp_avg_sq"] = torch.zeros_like(p, memory_format=torch.preserve_format)
            if params:
                yield group, params


@torch.no_grad()
def step_adams(optimizers) -> None:
    """One step of every :class:`ForeachAdam` in ``optimizers``, all their parameters in one
    pass of foreach ops: per parameter the arithmetic of ``_single_tensor_adam`` with its own
    group's rate, betas and step count (the learners step three or four optimizers a minibatch)."""
    params, grads, exp_avgs, exp_avg_sqs, steps, hyper = [], [], [], [], [], []
    for optimizer in optimizers:
        for group, group_params in optimizer._live_groups():
            for p in group_params:
                state = optimizer.state[p]
                params.append(p)
                grads.append(p.grad)
                exp_avgs.append(state["exp_avg"])
                exp_avg_sqs.append(state["exp_avg_sq"])
                steps.append(state["step"])
                hyper.append(group)
    if not params:
        return
    # Scalars go in as 0-d float32 tensors, one per distinct value: on CPU a foreach op loops over
    # its tensors, and a Python number is wrapped into a tensor again for each of them. The
    # kernels cast a number to the tensors' float32 first, so the arithmetic is the same.
    scalar = _Scalars(params[0].dtype)
    torch._foreach_add_(steps, [scalar(1.0)] * len(steps))
    # Moments, per parameter with its group's betas (one call per distinct pair, usually one).
    for (beta1, beta2), idx in _by(hyper, lambda g: tuple(g["betas"])).items():
        torch._foreach_lerp_([exp_avgs[i] for i in idx], [grads[i] for i in idx], 1 - beta1)
        torch._foreach_mul_([exp_avg_sqs[i] for i in idx], scalar(beta2))
        torch._foreach_addcmul_([exp_avg_sqs[i] for i in idx], [grads[i] for i in idx],
                                [grads[i] for i in idx], value=1 - beta2)
    step_counts = torch.stack(steps).tolist()  # one read-back for every parameter's count
    bias2_sqrt, step_size, eps, known = [], [], [], {}
    for group, step in zip(hyper, step_counts):
        beta1, beta2 = group["betas"]
        if (id(group), step) not in known:
            size = group["lr"] / (1 - beta1**step)  # a float32 tensor op when lr is a tensor, as Adam's loop
            known[id(group), step] = -(size.item() if isinstance(size, torch.Tensor) else size)
        step_size.append(known[id(group), step])
        bias2_sqrt.append(scalar((1 - beta2**step) ** 0.5))
        eps.append(scalar(group["eps"]))
    denom = torch._foreach_sqrt(exp_avg_sqs)
    torch._foreach_div_(denom, bias2_sqrt)
    torch._foreach_add_(denom, eps)
    torch._foreach_addcdiv_(params, exp_avgs, denom, step_size)


class _Scalars:
    """0-d tensors of ``dtype``, one per distinct value asked for (a step's few constants)."""

    def __init__(self, dtype: torch.dtype):
        self.dtype, self.made = dtype, {}

    def __call__(self, value: float) -> torch.Tensor:
        if value not in self.made:
            self.made[value] = torch.tensor(value, dtype=self.dtype)
        return self.made[value]


def _by(items, key) -> dict:
    out: dict = {}
    for i, item in enumerate(items):
        out.setdefault(key(item), []).append(i)
    return out
