"""benchmarks/reference_steps.py measures the same work as the learners: on one minibatch its
plain-torch loss and gradients are the project's (1e-6), so update_step.py's ratios compare like
with like."""

import importlib.util
import sys
from pathlib import Path

import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID as MID

from lac_rllib.algorithms.registry import build_config
from lac_rllib.algorithms.sac_lag.learner import actor_loss

ROOT = Path(__file__).resolve().parents[2]
TASK = "lac/PointHazard-v0"


@pytest.fixture(scope="module")
def reference():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    spec = importlib.util.spec_from_file_location("reference_steps", ROOT / "benchmarks" / "reference_steps.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _close(ours, theirs):
    assert len(ours) == len(theirs) > 0
    for a, b in zip(ours, theirs):
        torch.testing.assert_close(a, b, atol=1e-6, rtol=1e-6)


def test_ppo_lags_plain_torch_step_computes_the_learners_loss_and_gradients(ray_session, reference):
    algo = build_config("ppo_lag", TASK, 0, {"critic_l2": 0.01}, timesteps=100_000).build_algo()
    try:
        learner = algo.learner_group._learner
        module = learner.module[MID].unwrapped()
        with torch.no_grad():
            module.nu.fill_(0.7)  # ν weighs the cost advantage in
            module.pi.log_std.fill_(-0.3)
        ref = reference.PPOLagStep(module, learner.config)
        batch = reference.make_batch("ppo_lag", module, 64, seed=3)
        batch["advantages"] = batch["advantages"] * 3  # some ratios past the clip after a step
        losses = learner.compute_losses(fwd_out={MID: module.forward_train(batch)}, batch={MID: batch})
        learner.compute_gradients(losses)
        theirs = ref.loss(batch)
        theirs.backward()
        torch.testing.assert_close(losses[MID].detach(), theirs.detach(), atol=1e-6, rtol=1e-6)
        ours = {"policy": [*module.encoder.actor_encoder.parameters(), *module.pi.net.parameters(), module.pi.log_std],
                "critic": [*module.encoder.critic_encoder.parameters(), *module.vf.parameters()],
                "cost_critic": list(module.cost_vf.parameters())}
        for name, params in ours.items():
            ref_params = ([*ref.actor.parameters(), ref.log_std] if name == "policy" else ref.networks[name])
            _close([p.grad for p in params], [p.grad for p in ref_params])
        assert float(module.pi.log_std.grad.abs().sum()) > 0
    finally:
        algo.stop()


@pytest.mark.parametrize("critic_dtype", ["float32", "bfloat16"])
def test_sac_lags_plain_torch_step_computes_the_learners_losses_and_gradients(ray_session, reference, critic_dtype):
    algo = build_config("sac_lag", TASK, 0, {"critic_dtype": critic_dtype}, timesteps=100_000).build_algo()
    try:
        learner = algo.learner_group._learner
        module = learner.module[MID].unwrapped()
        assert str(module.reward_critics.matmul_dtype) == f"torch.{critic_dtype}"
        with torch.no_grad():
            module.nu.fill_(0.5)
        ref = reference.SACLagStep(module, learner.config)
        batch = reference.make_batch("sac_lag", module, 256, seed=4)
        torch.manual_seed(5)
        ours = learner.compute_loss_for_module(module_id=MID, config=learner.config, batch=batch,
                                               fwd_out=module.forward_train(batch))
        ours.backward()
        torch.manual_seed(5)
        theirs = ref.critic_loss(batch)
        theirs.backward()
        torch.testing.assert_close(ours.detach(), theirs.detach(), atol=1e-6, rtol=1e-6)
        _close([p.grad for p in [*module.reward_critics.parameters(), *module.cost_critic.parameters()]],
               [p.grad for params in ref.critics for p in params])
        torch.manual_seed(6)
        ours_pi = torch.autograd.grad(actor_loss(module.forward_actor(batch["obs"]), module.nu, learner.config.alpha),
                                      list(module.actor.parameters()))
        torch.manual_seed(6)
        theirs_pi = torch.autograd.grad(ref.actor_loss(ref.m.forward_actor(batch["obs"]), ref.m.nu, ref.config.alpha),
                                        list(ref.m.actor.parameters()))
        _close(list(ours_pi), list(theirs_pi))
    finally:
        algo.stop()


def _update_step_module():
    spec = importlib.util.spec_from_file_location("update_step", ROOT / "benchmarks" / "update_step.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_against_refuses_a_revision_that_is_not_a_commit_before_anything_starts(capsys):
    with pytest.raises(SystemExit) as e:
        _update_step_module().main(["--against", "no-such-revision", "--algos", "ppo_lag"])
    assert e.value.code == 2
    assert "--against 'no-such-revision': not a commit of this repository" in capsys.readouterr().err


@pytest.mark.slow
def test_against_times_the_step_of_another_commits_code_beside_todays(capsys):
    """--against HEAD: a child importing HEAD's lac_rllib from an unpacked tree (checked: not this
    checkout's) and one importing today's, timed in turn; the same code, so their ratio is ~1."""
    code = _update_step_module().main(["--against", "HEAD", "--algos", "ppo_lag", "--task", TASK, "--steps", "30",
                                       "--repeats", "3"])
    assert code == 0
    row = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ppo_lag |")][-1]
    old, new, ratio = (float(cell.strip().rstrip("x")) for cell in row.split("|")[2:5])
    assert old > 0 and new > 0 and abs(ratio - old / new) < 0.01 + 1e-9
    assert 0.5 < ratio < 2.0, row  # the same code on both sides
