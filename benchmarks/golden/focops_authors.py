"""Record the FOCOPS authors' own update step (ymzhang01/focops, the paper's App. D source) on one
seeded batch: the project's FOCOPS ``paper`` preset against it (tests/algorithms/focops/
test_focops_paper_golden.py).

Run with a venv holding torch, numpy and gym 0.26 (their focops_main.py imports gym; nothing of it
is called), from the repository root, on a mirror fetched outside it:

    PAPER_REF_PY benchmarks/golden/focops_authors.py --mirror /work/.mirror/ymzhang01+focops/repo

The commit's focops_main.py, models.py and utils/ are extracted to a temporary folder and imported
from there (reference_source.py). Their nets are built as ``train()`` builds them
(focops_main.py:195-212: GaussianPolicy, two Value, an Adam each, the LambdaLR at iteration 0) with
(16, 16) layers, in float64 (``torch.set_default_dtype``: their ``torch.Tensor(...)`` conversions
then keep float64); every other hyperparameter is their argparse default (focops_main.py:266-316).
Their own ``FOCOPS.update_params`` (focops_main.py:74-152) then takes the step, with
``num_epochs=1`` and ``mb_size`` = the batch's 64 rows, so its loop runs exactly once: ν's clipped
step on the batch's episode cost (:97-102), the reward and cost critics' Adam steps (:111-130),
the policy's loss, its clip at 40 and Adam step (:133-143).

One injection: π_old. ``update_params`` takes π_old from the policy itself (:85), which makes the
first minibatch trivial (KL 0, ratio 1, every row inside η). Its first ``policy.logprob`` call
returns instead the batch's behaviour policy (the starting policy moved by noise, as
omnisafe_first_order.py's ``_p_dist``): the state of any later minibatch, after the policy has
moved, with some rows beyond η. Every later call is the policy's own.
Written to tests/fixtures/golden/focops-paper.npz (fixture.py)."""

from __future__ import annotations

import sys
from collections import deque
from pathlib import Path

import numpy as np
import torch
from torch.distributions import Normal

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fixture  # noqa: E402
import reference_source  # noqa: E402

REPO, COMMIT = "ymzhang01/focops", "fc92fcee1500d1b0dbe45a23c66188f22e463371"  # HEAD; its update = 7d3865e's
FILES = ["focops_main.py", "models.py", "environment.py", "utils/__init__.py", "utils/math.py",
         "utils/pytorch.py", "utils/misc.py", "utils/logger.py", "utils/running_stats.py", "data_generator.py"]
ENV_ID, TASK = "Swimmer-v3", "focops/SwimmerVelocity-v0"  # obs 8, act 2; the project's task of it
OBS_DIM, ACT_DIM, ROWS, HIDDEN, EP_COST, SEED = 8, 2, 64, (16, 16), 60.0, 0


def build(src: Path, args: dict):
    sys.path.insert(0, str(src))
    import focops_main  # their module: FOCOPS, GaussianPolicy, Value, get_threshold, Logger

    torch.manual_seed(SEED)  # train(): focops_main.py:191, then the nets in its order
    policy = focops_main.GaussianPolicy(OBS_DIM, ACT_DIM, HIDDEN, args["activation"], args["logstd"])
    value_net = focops_main.Value(OBS_DIM, HIDDEN, args["activation"])
    cvalue_net = focops_main.Value(OBS_DIM, HIDDEN, args["activation"])
    optims = [torch.optim.Adam(net.parameters(), lr) for net, lr in
              ((policy, args["pi_lr"]), (value_net, args["vf_lr"]), (cvalue_net, args["cvf_lr"]))]
    for optim in optims:  # iteration 0 of their linear decay: factor 1
        torch.optim.lr_scheduler.LambdaLR(optim, lr_lambda=lambda it: max(1.0 - it / args["max_iter_num"], 0))
    agent = focops_main.FOCOPS(None, policy, value_net, cvalue_net, *optims, 1, ROWS, args["c_gamma"], args["lam"],
                               args["delta"], args["eta"], float(args["nu"]), args["nu_lr"], args["nu_max"],
                               focops_main.get_threshold(ENV_ID, args["constraint"]), args["l2_reg"],
                               deque([0.0]), deque([0.0]), focops_main.Logger(args))
    return agent


def nets(agent) -> dict:
    return {"policy": agent.policy, "value_net": agent.value_net, "cvalue_net": agent.cvalue_net}


def make_batch(policy, rng: np.random.Generator) -> dict:
    """Observations N(0, 1); a behaviour policy = the starting policy with its mean moved by
    N(0, 0.08²) and log σ by N(0, 0.05²) per row; actions and logp from it; advantages N(0, 1),
    value targets N(0, 1) and N(2, 1)."""
    obs = torch.as_tensor(rng.normal(size=(ROWS, OBS_DIM)))
    with torch.no_grad():
        mean, log_std, _ = policy(obs)
        old_mean = mean + torch.as_tensor(rng.normal(scale=0.08, size=(ROWS, ACT_DIM)))
        old_log_std = log_std + torch.as_tensor(rng.normal(scale=0.05, size=(ROWS, ACT_DIM)))
        behaviour = Normal(old_mean, old_log_std.exp())
        act = behaviour.mean + behaviour.stddev * torch.as_tensor(rng.normal(size=(ROWS, ACT_DIM)))
        logp = behaviour.log_prob(act).sum(-1)
    return {"obs": obs, "act": act, "logp": logp, "old_mean": old_mean, "old_log_std": old_log_std,
            "adv_r": torch.as_tensor(rng.normal(size=ROWS)), "adv_c": torch.as_tensor(rng.normal(size=ROWS)),
            "target_value_r": torch.as_tensor(rng.normal(size=ROWS)),
            "target_value_c": torch.as_tensor(rng.normal(loc=2.0, size=ROWS))}


def step(agent, batch: dict) -> tuple[dict, dict]:
    """Their ``update_params`` on the batch (a rollout dict as DataGenerator.run_traj returns it,
    (B, 1) columns), π_old injected at its first logprob call; what it computed, and side facts."""
    b = {k: v.numpy() for k, v in batch.items()}
    col = lambda x: x.reshape(-1, 1)  # noqa: E731  their buffers are (B, 1)
    rollout = {"states": b["obs"], "actions": b["act"], "v_targets": col(b["target_value_r"]),
               "advantages": col(b["adv_r"]), "cv_targets": col(b["target_value_c"]),
               "c_advantages": col(b["adv_c"]), "avg_cost": EP_COST}
    policy, own = agent.policy, agent.policy.logprob

    def behaviour_logprob(obs, act):  # :85 only; the loop's calls (:134, :147) are the policy's own
        policy.logprob = own
        return col(batch["logp"]), batch["old_mean"], batch["old_log_std"].exp()

    policy.logprob = behaviour_logprob
    clip, norms = torch.nn.utils.clip_grad_norm_, {}

    def recording_clip(params, max_norm, *a, **kw):  # :142, the policy's clip: its norm before
        norms["policy"] = float(clip(params, max_norm, *a, **kw))
        return norms["policy"]

    torch.nn.utils.clip_grad_norm_ = recording_clip
    try:
        with torch.no_grad():  # the rows inside η (a fact for the meta; their loss computes its own)
            mean, _, std = policy(batch["obs"])
            kl = torch.distributions.kl.kl_divergence(Normal(mean, std), Normal(
                batch["old_mean"], batch["old_log_std"].exp())).sum(-1)
        agent.update_params(rollout, torch.float64, torch.device("cpu"))
    finally:
        torch.nn.utils.clip_grad_norm_ = clip
    out = {"nu": float(agent.nu), "loss_pi": agent.pi_loss.item(), "loss_reward_critic": agent.vf_loss.item(),
           "loss_cost_critic": agent.cvf_loss.item()}
    for net, module in nets(agent).items():
        out.update({f"grad/{net}.{k}": p.grad.detach().clone() for k, p in module.named_parameters()})
        out.update({f"after/{net}.{k}": v.detach().clone() for k, v in module.state_dict().items()})
        if net != "policy":
            norms[net] = float(torch.cat([p.grad.flatten() for p in module.parameters()]).norm())
    facts = {"grad_norms_before_clip": norms, "rows_inside_eta": int((kl <= agent.eta).sum())}
    return out, facts


def record(mirror: Path, commit: str, out_dir: Path) -> Path:
    src = reference_source.extract(mirror, commit, ["focops_main.py", "models.py", "environment.py", "utils",
                                                    "data_generator.py"])
    args = reference_source.argparse_defaults(src / "focops_main.py")
    torch.set_default_dtype(torch.float64)  # train() sets float32 (:180-181); float64 here, everywhere
    agent = build(src, args)
    before = {f"{net}.{k}": v.detach().clone() for net, m in nets(agent).items() for k, v in m.state_dict().items()}
    batch = make_batch(agent.policy, np.random.default_rng(SEED))
    torch.manual_seed(SEED)  # their DataLoader's shuffle (one minibatch: the whole batch, permuted)
    outputs, facts = step(agent, batch)
    hyper = {k: args[k] for k in ("lam", "delta", "eta", "nu", "nu_lr", "nu_max", "l2_reg", "pi_lr", "vf_lr",
                                  "cvf_lr", "activation", "logstd", "c_gamma", "max_iter_num", "batch_size")}
    meta = {"reference": f"{REPO} (the FOCOPS paper's code)", "reference_version": commit,
            "reference_files": reference_source.sha256(src, FILES), "algorithm": "focops", "preset": "paper",
            "task": TASK, "reference_env": ENV_ID, "cost_limit": agent.cost_lim, "hidden": list(HIDDEN), "rows": ROWS,
            "torch": torch.__version__, "hyperparameters": hyper, **facts,
            "command": "PAPER_REF_PY benchmarks/golden/focops_authors.py --mirror MIRROR_OF_ymzhang01/focops",
            "step": "FOCOPS.update_params (focops_main.py:74-152) with num_epochs=1, mb_size=64 = the batch; "
                    "pi_old = the batch's behaviour policy (its first policy.logprob call)"}
    inputs = {**batch, "ep_cost": EP_COST, "nu_before": float(args["nu"])}
    print({k: v for k, v in outputs.items() if not k.startswith(("grad", "after"))}, facts, file=sys.stderr)
    return fixture.save(out_dir / "focops-paper.npz", meta, inputs, before, outputs)


def main() -> None:
    fixture.run_from_mirror(__doc__, REPO, COMMIT, record)


if __name__ == "__main__":
    main()
