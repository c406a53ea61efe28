"""Record the RESPO authors' own update step (milanganai/milanganai.github.io, NeurIPS2023/code/
respo.py and core_respo.py) on one seeded batch: the project's RESPO against it
(tests/algorithms/respo/test_respo_golden.py).

Run with a venv holding torch, numpy, scipy, gym 0.26 and mpi4py + mpich (their imports; one MPI
process, as a run without mpirun), from the repository root, on a mirror fetched outside it:

    PAPER_REF_PY benchmarks/golden/respo_authors.py --mirror /work/.mirror/milanganai+milanganai.github.io/repo

The commit's NeurIPS2023/code is extracted to a temporary folder and imported from there
(reference_source.py); two of its imports are stubbed, never called on this path: ``safety_gym``
(the envs) and ``utils.logx`` (its EpochLogger imports tensorflow; a recorder stands in for the
logger). Their ``MLPActorCritic`` (core_respo.py:108-126, (16, 16) here) is built under a seed; the
batch goes through their ``RESPOBuffer`` (respo.py:16-105: store, finish_path for a 40-step path
ended by a terminal and a 24-step path cut by the epoch's end, get), whose ``ac.vp`` gives V_p at
collection in float32 as theirs does (:63); from there on everything is float64 (the batch and the
actor-critic, ``.double()``). The statements of ``respo()`` from ``def compute_loss_pi`` to
``def update`` (:147-281: the losses, the penalty parameter 0.25 and its Adam at 5e-5, the five
Adams and their LinearLR, ``update``) then run as written, with ``range`` bound to one iteration:
their ``update()`` (:217-280) takes the penalty's step on −p·EpCost·mean(1 − V_p) (cost_limit 0,
:153, :172, :223-229), its first policy step (the KL check, the loss, Adam: :241-251) and its
first step of the three critics (:257-273).
Written to tests/fixtures/golden/respo-authors.npz (fixture.py)."""

from __future__ import annotations

import builtins
import copy
import inspect
import sys
import types
from pathlib import Path

import numpy as np
import torch
from torch.distributions import Normal

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fixture  # noqa: E402
import reference_source  # noqa: E402

REPO, COMMIT = "milanganai/milanganai.github.io", "7c194db2098d28dee7336c493e3471c14c0186fe"
CODE = "NeurIPS2023/code"
FILES = [f"{CODE}/respo.py", f"{CODE}/core_respo.py", f"{CODE}/utils/mpi_tools.py", f"{CODE}/utils/mpi_pytorch.py"]
TASK, OBS_DIM, ACT_DIM = "SafetyPointGoal1-v0", 60, 2
PATHS, HIDDEN, EP_COST, SEED = (40, 24), (16, 16), 40.0, 0  # the first path terminal, the second cut
ROWS = sum(PATHS)
EPOCHS = int(9e6 / 30000)  # respo.py __main__ (:384-386): the LinearLR horizon; factor 1 at this first step


class Recorder:
    """Stands in for their EpochLogger: ``get_stats('EpCost')`` is the batch's episode cost, and
    what ``update`` stores is kept."""

    def __init__(self, ep_cost: float):
        self.ep_cost, self.stored, self.lines = ep_cost, {}, []

    def get_stats(self, key):
        assert key == "EpCost", key
        return [self.ep_cost, 0.0]

    def store(self, **kw):
        self.stored.update(kw)

    def log(self, msg, *_, **__):
        self.lines.append(msg)

    def setup_pytorch_saver(self, *_):
        pass


def import_theirs(src: Path):
    code = str(src / CODE)
    sys.path.insert(0, code)
    sys.modules["safety_gym"] = types.ModuleType("safety_gym")  # registers the envs; none is made here
    import utils  # their package (mpi_tools, mpi_pytorch: real mpi4py, one process)

    logx = types.ModuleType("utils.logx")  # EpochLogger imports tensorflow; Recorder replaces it
    logx.EpochLogger = Recorder
    sys.modules["utils.logx"] = utils.logx = logx
    import core_respo
    import respo

    return respo, core_respo


def make_batch(respo, ac, ac32, hyper: dict, rng: np.random.Generator):
    """Their buffer filled with: observations N(0, 1); actions from a behaviour policy (the
    starting policy's mean moved by N(0, 0.05²) and log σ by N(0, 0.03²) per row) and its logp;
    rewards N(0, 1); costs 1 with probability 0.15, else 0; V and V_C at collection from their
    critics (as ``ac.step``, :291). Returns the buffer's ``get()`` and the raw columns."""
    buf = respo.RESPOBuffer((OBS_DIM,), (ACT_DIM,), ROWS, hyper["gamma"], hyper["lam"])
    buf.ac = ac32  # finish_path evaluates V_p in float32 (:63)
    obs = rng.normal(size=(ROWS + 1, OBS_DIM))  # the last: s_T of the cut path
    with torch.no_grad():
        mu = ac.pi.mu_net(torch.as_tensor(obs[:ROWS]))
        old_mean = mu + torch.as_tensor(rng.normal(scale=0.05, size=(ROWS, ACT_DIM)))
        old_log_std = ac.pi.log_std + torch.as_tensor(rng.normal(scale=0.03, size=(ROWS, ACT_DIM)))
        behaviour = Normal(old_mean, old_log_std.exp())
        act = behaviour.mean + behaviour.stddev * torch.as_tensor(rng.normal(size=(ROWS, ACT_DIM)))
        logp = behaviour.log_prob(act).sum(-1)
        o32 = torch.as_tensor(obs, dtype=torch.float32)
        v, vc = ac32.v(o32).numpy(), ac32.vc(o32).numpy()
    rew, cost = rng.normal(size=ROWS), (rng.random(ROWS) < 0.15).astype(float)
    start, tails = 0, []
    for length, cut in zip(PATHS, (False, True)):
        for t in range(start, start + length):
            buf.store(obs[t], act[t].numpy(), rew[t], cost[t], v[t], vc[t], logp[t].item())
        last_v, last_vc = (float(v[ROWS]), float(vc[ROWS])) if cut else (0.0, 0.0)  # :315-320
        buf.finish_path(last_val=last_v, last_cval=last_vc)
        tails.append((last_v, last_vc))
        start += length
    data = buf.get()
    raw = {"cost": cost, "terminated": np.array([t == PATHS[0] - 1 for t in range(ROWS)]), "obs_T": obs[ROWS],
           "old_mean": old_mean, "old_log_std": old_log_std, "tail_value_c": tails[1][1]}
    return data, raw


def step(respo, path: Path, ac, hyper: dict, data: dict, ep_cost: float) -> tuple[dict, dict]:
    """Their respo() body from compute_loss_pi to update, executed; ``update()`` with each of its
    80-step loops taking one step; what it computed."""
    logger, calls = Recorder(ep_cost), {"pi": [], "v": []}
    stub_buf = types.SimpleNamespace(get=lambda: dict(data))
    ns = {**vars(respo), "ac": ac, "logger": logger, "buf": stub_buf,
          "clip_ratio": hyper["clip_ratio"], "target_kl": hyper["target_kl"], "epochs": EPOCHS}
    reference_source.run_body(path, "respo", "compute_loss_pi", "update", ns)
    own_pi, own_v = ns["compute_loss_pi"], ns["compute_loss_v"]
    ns["compute_loss_pi"] = lambda d: calls["pi"].append(own_pi(d)) or calls["pi"][-1]
    ns["compute_loss_v"] = lambda d: calls["v"].append(own_v(d)) or calls["v"][-1]
    ns["range"] = lambda n: builtins.range(min(n, 1))  # update's loops (:241, :257): their first step
    penalty = ns["penalty_param"]
    p_init = penalty.item()  # :193
    before_pi = [p.detach().clone() for p in ac.pi.parameters()]
    ns["update"]()
    stepped = not all(torch.equal(a, b) for a, b in zip(before_pi, ac.pi.parameters()))
    loss_pi, _, pi_info = calls["pi"][1]  # [0]: LossPi, before ν's step; [1]: the step's
    loss_v, loss_vc, loss_vp = calls["v"][1]  # [0]: v_l_old (:235); [1]: the critics' step
    out = {"penalty_param": penalty.item(), "nu": torch.nn.functional.softplus(penalty).item(),
           "grad/penalty_param": penalty.grad.item(), "loss_pi": loss_pi.item(),
           "loss_reward_critic": loss_v.item(), "loss_cost_critic": loss_vc.item(),
           "loss_reach_critic": loss_vp.item()}
    out.update({f"grad/{k}": p.grad.detach().clone() for k, p in ac.named_parameters()})
    out.update({f"after/{k}": v.detach().clone() for k, v in ac.state_dict().items()})
    facts = {"policy_stepped": stepped, "approx_kl_at_step": pi_info["kl"], "clip_fraction_at_step": pi_info["cf"],
             "logged_LossPi_before_penalty_step": logger.stored["LossPi"], "early_stop_lines": logger.lines,
             "learning_rates": {k: ns[k] for k in ("pi_lr", "penalty_lr", "vf_lr", "pvf_lr")},
             "penalty_param_init": p_init}
    assert stepped, f"their KL check stopped the policy before its step: {logger.lines}"
    return out, facts


def record(mirror: Path, commit: str, out_dir: Path) -> Path:
    import gym

    src = reference_source.extract(mirror, commit, [CODE])
    respo, core_respo = import_theirs(src)
    torch.manual_seed(SEED)
    box = lambda n: gym.spaces.Box(-np.inf, np.inf, (n,), np.float32)  # noqa: E731
    ac32 = core_respo.MLPActorCritic(box(OBS_DIM), box(ACT_DIM), hidden_sizes=HIDDEN)
    ac = copy.deepcopy(ac32).double()
    before = {k: v.detach().clone() for k, v in ac.state_dict().items()}
    sig = inspect.signature(respo.respo).parameters  # respo()'s defaults (:109-112), as __main__ leaves them
    hyper = {k: sig[k].default for k in ("gamma", "lam", "clip_ratio", "target_kl")}
    data, raw = make_batch(respo, ac, ac32, hyper, np.random.default_rng(SEED))
    data = {k: v.double() for k, v in data.items()}
    outputs, facts = step(respo, src / CODE / "respo.py", ac, hyper, data, EP_COST)
    meta = {"reference": f"{REPO} {CODE} (the RESPO paper's code)", "reference_version": commit,
            "reference_files": reference_source.sha256(src, FILES), "algorithm": "respo", "task": TASK,
            "hidden": list(HIDDEN), "rows": ROWS, "paths": list(PATHS), "torch": torch.__version__,
            "hyperparameters": {**hyper, "epochs": EPOCHS, "cost_limit": 0, "reach_mu": 0.99},  # :153, :62
            **facts,
            "command": "PAPER_REF_PY benchmarks/golden/respo_authors.py --mirror MIRROR_OF_" + REPO,
            "step": "respo() :147-281 executed; update() with range bound to 1: the penalty's Adam step, the "
                    "policy's first step, the three critics' first step"}
    inputs = {"obs": data["obs"], "act": data["act"], "logp": data["logp"], "old_mean": raw["old_mean"],
              "old_log_std": raw["old_log_std"], "adv_r": data["adv"], "adv_c": data["cadv"],
              "target_value_r": data["ret"], "target_value_c": data["cret"], "reach_probs": data["pval"],
              "reach_targets": data["pret"], "cost": raw["cost"], "terminated": raw["terminated"],
              "tail_value_c": raw["tail_value_c"], "obs_T": raw["obs_T"], "ep_cost": EP_COST}
    print({k: v for k, v in outputs.items() if not k.startswith(("grad/pi", "grad/v", "after"))},
          {k: v for k, v in facts.items() if k != "early_stop_lines"}, file=sys.stderr)
    return fixture.save(out_dir / "respo-authors.npz", meta, inputs, before, outputs)


def main() -> None:
    fixture.run_from_mirror(__doc__, REPO, COMMIT, record)


if __name__ == "__main__":
    main()
