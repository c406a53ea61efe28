"""Each baseline beside OmniSafe 0.5.0's own on the same CPU, interleaved: CPU seconds per 20k-step
epoch (PPO-Lag, TRPO-Lag, CPO, PCPO, FOCOPS, CUP, P3O) and per 1,000 updates (SAC-Lag), ours / theirs.

    python benchmarks/peers.py --omnisafe-python OMNISAFE_VENV/bin/python            # all eight, 2 rounds
    python benchmarks/peers.py --omnisafe-python ... --algos ppo_lag,cpo --rounds 1

OmniSafe runs in a venv of its own (benchmarks/golden/omnisafe_venv.sh; docs/golden.md),
never imported here: each side runs in a fresh process of its own venv (this file with ``--side``),
ours first then theirs, per algorithm and round, each pinned to one core (``taskset``) with one
torch thread, on SafetyPointGoal1-v0 at each side's defaults for it:

- **theirs**: ``omnisafe.Agent(NAME, "SafetyPointGoal1-v0")`` with one env (``vector_env_nums`` 1,
  its default), trains 2 epochs; the CPU seconds (``time.process_time``) of the second, between its
  logger's dumps. On-policy and trust-region epochs are its 20,000 steps. SAC-Lag's are its 2,000
  steps with one update each, its random warm-up (``start_learning_steps``) cut to the first epoch.
- **ours**: the algorithm at its ``safety_gym`` preset (10 envs on the batched backend, the
  default), built in one process (no env runners), 2 iterations; the CPU seconds of the second.
  SAC-Lag's iterations are its 2,000 env steps with 2,000 updates, its random warm-up
  (``random_env_steps``) cut to the first iteration.

A figure is the CPU seconds per 20,000 env steps of an epoch (SAC-Lag: per 1,000 updates, env steps
included on both sides), and ours / theirs < 1 is faster (0.33: 3×). Prints a Markdown table and the
CPU it ran on (``lscpu``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

TASK = "SafetyPointGoal1-v0"
EPOCH = 20_000  # on-policy env steps per epoch, both sides
SAC_EPOCH = 2_000  # an off-policy epoch: OmniSafe's steps (and updates) per epoch, ours per iteration


def peers() -> dict[str, str]:
    """Each algorithm of the registry that OmniSafe implements → OmniSafe's name for it."""
    from lac_rllib.algorithms.registry import ALGOS, algo_config

    return {a: algo_config(a).OMNISAFE_NAME for a in ALGOS if algo_config(a).OMNISAFE_NAME}


def off_policy(algo: str) -> bool:
    """Measured per 1,000 updates: an algorithm that updates from a replay buffer."""
    from lac_rllib.algorithms.registry import algo_config

    return "random_env_steps" in algo_config(algo).FIELDS.names


def theirs(name: str, sac: bool) -> dict:
    """OmniSafe's ``name``'s second epoch (run under its venv; ``sac``: an off-policy one)."""
    import tempfile

    import omnisafe
    from omnisafe.common.logger import Logger

    dumps = []
    original = Logger.dump_tabular

    def dump(self):
        dumps.append(time.process_time())
        return original(self)

    Logger.dump_tabular = dump
    epoch = SAC_EPOCH if sac else EPOCH
    algo_cfgs = {"steps_per_epoch": epoch} | ({"start_learning_steps": SAC_EPOCH} if sac else {})
    cfgs = {"seed": 0, "train_cfgs": {"total_steps": 2 * epoch, "vector_env_nums": 1, "parallel": 1,
                                      "torch_threads": 1, "device": "cpu"},
            "algo_cfgs": algo_cfgs,
            "logger_cfgs": {"use_wandb": False, "use_tensorboard": False, "log_dir": tempfile.mkdtemp()}}
    omnisafe.Agent(name, TASK, custom_cfgs=cfgs).learn()
    cpu = dumps[1] - dumps[0]
    return {"cpu_s": cpu, "per": (cpu / (SAC_EPOCH / 1000)) if sac else cpu * EPOCH / epoch}


def ours(algo: str) -> dict:
    """Our second iteration (run under the project's venv)."""
    import ray
    import torch

    from lac_rllib.algorithms.registry import build_config

    torch.set_num_threads(1)
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    # Off-policy: its random warm-up cut to the first iteration, as OmniSafe's is to its first epoch.
    sets = {"random_env_steps": SAC_EPOCH} if off_policy(algo) else {}
    config = build_config(algo, TASK, 0, sets, timesteps=10 * EPOCH)
    trainer = config.build_algo()
    try:
        trainer.train()
        start = time.process_time()
        trainer.train()
        cpu = time.process_time() - start
    finally:
        trainer.stop()
        ray.shutdown()
    if off_policy(algo):
        updates = int(config.updates_per_iteration)
        return {"cpu_s": cpu, "per": cpu / (updates / 1000), "updates": updates}
    steps = int(config.train_batch_size_per_learner)
    return {"cpu_s": cpu, "per": cpu * EPOCH / steps, "steps": steps}


def _run(python: str, side: str, algo: str, core: int) -> dict:
    what = ["--algo", algo] if side == "ours" else ["--omnisafe-name", peers()[algo]] + (
        ["--off-policy"] if off_policy(algo) else [])
    cmd = ["taskset", "-c", str(core), python, os.path.abspath(__file__), "--side", side, *what]
    out = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
    if out.returncode or not lines:
        raise RuntimeError(f"{side} {algo} failed ({out.returncode}): {out.stderr[-2000:]}")
    return json.loads(lines[-1])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--omnisafe-python", help="OmniSafe's venv's python (benchmarks/golden/omnisafe_venv.sh)")
    p.add_argument("--algos", default=None, help="default: every algorithm OmniSafe implements")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--core", type=int, default=0, help="the core both sides are pinned to")
    p.add_argument("--side", choices=("ours", "theirs"), help=argparse.SUPPRESS)
    p.add_argument("--algo", help=argparse.SUPPRESS)
    p.add_argument("--omnisafe-name", help=argparse.SUPPRESS)
    p.add_argument("--off-policy", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.side:  # one measurement, in the side's own venv
        result = ours(args.algo) if args.side == "ours" else theirs(args.omnisafe_name, args.off_policy)
        print(json.dumps(result), flush=True)
        return 0
    known = peers()
    algos = args.algos.split(",") if args.algos else list(known)
    bad = [a for a in algos if a not in known]
    if bad or not args.omnisafe_python:
        p.error(f"--algos {','.join(bad)}: accepted: {','.join(known)}" if bad else "--omnisafe-python is required")
    cpu = subprocess.run(["sh", "-c", "lscpu | grep 'Model name'"], capture_output=True, text=True).stdout
    print(f"CPU: {cpu.split(':')[-1].strip()}; {TASK}; {args.rounds} rounds, ours then theirs, core {args.core}\n")
    print("| algorithm | unit | ours (CPU s) | OmniSafe (CPU s) | ours / theirs |\n|---|---|---|---|---|")
    for algo in algos:
        mine, theirs_ = [], []
        for _ in range(args.rounds):
            mine.append(_run(sys.executable, "ours", algo, args.core)["per"])
            theirs_.append(_run(args.omnisafe_python, "theirs", algo, args.core)["per"])
        unit = "1,000 updates" if off_policy(algo) else "20k-step epoch"
        a, b = min(mine), min(theirs_)
        print(f"| {algo} | {unit} | {' / '.join(f'{x:.1f}' for x in mine)} | "
              f"{' / '.join(f'{x:.1f}' for x in theirs_)} | {a / b:.2f} (best of each) |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
