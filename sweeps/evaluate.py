"""Evaluate a trained policy: from a checkpoint path, an MLflow trial run, or a sweep's best trial.

    python sweeps/evaluate.py --checkpoint PATH [--episodes N] [--seed S]
        [--actions MODE] [--langevin-steps T] [--langevin-step-size ETA]
        [--video DIR] [--json]
    python sweeps/evaluate.py --run-id RUN_ID [--tracking-uri URI] ...
    python sweeps/evaluate.py --best-of SWEEP_RUN_ID [--tracking-uri URI] ...

A checkpoint is code: RLlib checkpoints are pickles, and restoring one runs what its bytes say.
Evaluate only checkpoints from a source you trust. Checkpoints from MLflow (``--run-id``,
``--best-of``) are checked file by file against the SHA-256 manifest the trial recorded on its
run when it logged them (tag ``lac.checkpoint_sha256``) before anything is unpickled; a
missing manifest or a mismatch stops with one line naming the file.

Episode i is reset with seed S+i; equal seeds give identical results. ``--actions`` takes the
modes the checkpoint's algorithm declares (its config's ``ACTIONS``), refused in one line naming
them: ``generator`` acts with the actor's mean; ``stochastic`` draws from the policy as the env
runners did in training (seeded per episode); ``langevin`` (LAC) refines each action with
Algorithm 1 (docs/spec.md §1) started from the target actor, with noise seeded from the seed.
Prints return, cost, cost limit and the fraction of episodes within the limit (mean ± std over
episodes); ``--json`` adds one JSON object as the last stdout line. Restoring needs no Ray cluster
(nothing calls ray.init).

MLflow layout (the sweep service's): a trial is a run whose tag ``lac.checkpoint_artifact_path``
names the artifact directory holding its RLlib checkpoint, with param ``task`` and metrics
``episode_return``, ``episode_cost``, ``cost_limit``, ``feasible`` and its score ``score_return``,
``score_cost``; a sweep is a parent run tagged ``lac.sweep=1`` whose trials carry
``mlflow.parentRunId``. ``--best-of`` evaluates the feasible trial with the highest return on the
score the sweep ranked it on (sweeps/score.py). After evaluating a run, the
results are logged back to it as metrics ``eval/<actions>/<name>`` (e.g.
``eval/generator/return_mean``), with tags ``lac.eval.<actions>.episodes`` / ``.seed``.

Exit codes: 0 success; 2 bad arguments, unusable checkpoint (missing, corrupt, other
lac-rllib version) or an MLflow run without a checkpoint; each error is one line on stderr.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import tempfile

from lac_rllib.algorithms.registry import DEFAULT_ALGO

#: The command's name in its help and errors: the console script, or "evaluate" (python sweeps/evaluate.py).
PROG = "lac-eval" if os.path.basename(sys.argv[0]) == "lac-eval" else "evaluate"
EVAL_PREFIX = "eval"
# The tag names (CHECKPOINT_TAG, SWEEP_TAG, PARENT_TAG) live in sweeps.tracking; it imports
# mlflow (seconds), so it is imported only when --run-id / --best-of need it.
#: Result keys logged back to the MLflow run as ``eval/<actions>/<key>``.
LOGGED_KEYS = ("return_mean", "return_std", "cost_mean", "cost_std", "cost_limit",
               "within_limit_fraction", "energy_generator_mean", "energy_refined_mean",
               "action_displacement_mean")


class UsageError(Exception):
    """A problem the user must fix (exit code 2): message is one line."""


@dataclasses.dataclass
class Resolved:
    checkpoint: str                # local path of the checkpoint to restore
    run_id: str | None = None      # the MLflow run it belongs to (results are logged back there)
    source: str = ""               # human description
    uri: str | None = None         # runs:/<run_id>/<artifact path> for MLflow checkpoints
    task_param: str | None = None  # the run's ``task`` param, cross-checked after restore


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--checkpoint", metavar="PATH",
                     help="RLlib checkpoint directory (or a lac-train --output directory)")
    src.add_argument("--run-id", metavar="ID", help="MLflow trial run whose checkpoint to evaluate")
    src.add_argument("--best-of", metavar="SWEEP_RUN_ID",
                     help="MLflow sweep (parent) run: evaluate its best feasible trial")
    p.add_argument("--tracking-uri", default=None,
                   help="MLflow tracking URI (default: the sweep service's, sqlite:///$PWD/mlflow.db)")
    p.add_argument("--episodes", type=int, default=10, help="episodes to run (>= 1; default 10)")
    p.add_argument("--seed", type=int, default=0, help="episode i is reset with seed+i (default 0)")
    p.add_argument("--actions", default="generator", metavar="MODE",
                   help="a mode the checkpoint's algorithm declares (its config's ACTIONS): generator, the "
                        "policy's mean (every algorithm); stochastic, a draw from it as in training; langevin, "
                        "LAC's Algorithm 1 from the target actor; a user algorithm's own")
    p.add_argument("--langevin-steps", type=int, default=None, metavar="T",
                   help="chain length T (default: the checkpoint's langevin_steps)")
    p.add_argument("--langevin-step-size", type=float, default=None, metavar="ETA",
                   help="step size η (default: the checkpoint's langevin_step_size)")
    p.add_argument("--video", default=None, metavar="DIR",
                   help="write one video per episode into DIR (needs a renderer and offscreen GL)")
    p.add_argument("--json", action="store_true", help="print the results as one JSON line last")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    return p


def check_args(args: argparse.Namespace) -> None:
    if args.episodes < 1:
        raise UsageError(f"--episodes {args.episodes} is invalid; accepted: an integer >= 1")
    if args.langevin_steps is not None and args.langevin_steps < 1:
        raise UsageError(f"--langevin-steps {args.langevin_steps} is invalid; accepted: an integer >= 1")
    if args.langevin_step_size is not None and not (
            math.isfinite(args.langevin_step_size) and args.langevin_step_size > 0):
        raise UsageError(f"--langevin-step-size {args.langevin_step_size} is invalid; accepted: a number > 0")
    if args.actions in ("generator", "stochastic") and (args.langevin_steps is not None
                                                         or args.langevin_step_size is not None):
        raise UsageError("--langevin-steps/--langevin-step-size need a chain mode (--actions langevin)")
    if args.tracking_uri and args.checkpoint:
        raise UsageError("--tracking-uri goes with --run-id or --best-of, not --checkpoint")


# ----------------------------------------------------------------------------- MLflow


def mlflow_client(tracking_uri: str | None):
    """A client on ``tracking_uri`` (default: the sweep service's local store), checked reachable."""
    from mlflow.tracking import MlflowClient

    from sweeps.tracking import check_reachable, default_tracking_uri

    uri = tracking_uri or default_tracking_uri()
    try:
        check_reachable(uri)
    except ValueError as e:
        raise UsageError(str(e)) from None
    return MlflowClient(tracking_uri=uri)


def get_run(client, run_id: str):
    from mlflow.exceptions import MlflowException

    try:
        return client.get_run(run_id)
    except MlflowException as e:
        raise UsageError(f"MLflow run {run_id} not found at {client.tracking_uri} ({_one_line(e)})") from None


def best_trial(client, sweep_run_id: str):
    """The sweep's feasible child run with the highest return, on the score each trial was ranked
    on (``score_return`` / ``score_cost`` against ``cost_limit``: sweeps/score.py); a trial of a
    version before the score, on its last iteration's (``episode_return``, ``feasible``)."""
    from lac_rllib.constrained.metrics import COST_LIMIT, EPISODE_RETURN, FEASIBLE
    from sweeps.score import SCORE_COST, SCORE_RETURN
    from sweeps.tracking import PARENT_TAG, SWEEP_TAG

    parent = get_run(client, sweep_run_id)
    if parent.data.tags.get(SWEEP_TAG) != "1":
        raise UsageError(f"MLflow run {sweep_run_id} is not a sweep (tag {SWEEP_TAG}=1 is missing)")
    children = client.search_runs(
        experiment_ids=[parent.info.experiment_id],
        filter_string=f"tags.`{PARENT_TAG}` = '{sweep_run_id}'", max_results=50_000)
    if not children:
        raise UsageError(f"sweep {sweep_run_id} has no trial runs")

    def scored(run) -> tuple[bool, float]:
        m = run.data.metrics
        if SCORE_RETURN in m and SCORE_COST in m and COST_LIMIT in m:
            ok, value = m[SCORE_COST] <= m[COST_LIMIT], m[SCORE_RETURN]
        else:
            ok, value = m.get(FEASIBLE) == 1.0, m.get(EPISODE_RETURN)
        return ok, -math.inf if value is None or math.isnan(value) else value

    feasible = [r for r in children if scored(r)[0]]
    if not feasible:
        raise UsageError(f"sweep {sweep_run_id} has no feasible trial (none of its {len(children)} "
                         "trials has its score's cost within its limit)")
    return max(feasible, key=lambda r: scored(r)[1])


def download_checkpoint(client, run, dst: str) -> str:
    """Download the run's checkpoint artifact directory; return its local path."""
    import mlflow.artifacts

    from sweeps.integrity import CHECKSUM_TAG, IntegrityError, verify
    from sweeps.tracking import CHECKPOINT_TAG

    run_id = run.info.run_id
    artifact_path = run.data.tags.get(CHECKPOINT_TAG)
    if not artifact_path:
        raise UsageError(f"MLflow run {run_id} has no checkpoint (tag {CHECKPOINT_TAG} is not set)")
    try:
        path = mlflow.artifacts.download_artifacts(
            run_id=run_id, artifact_path=artifact_path, dst_path=dst, tracking_uri=client.tracking_uri)
    except Exception as e:  # MlflowException, OSError, store-specific errors
        raise UsageError(f"MLflow run {run_id} has no checkpoint: artifact {artifact_path!r} cannot be "
                         f"downloaded ({_one_line(e)})") from None
    try:  # before anything is unpickled
        verify(path, run.data.tags.get(CHECKSUM_TAG))
    except IntegrityError as e:
        raise UsageError(f"MLflow run {run_id}: {e}") from None
    return path


def resolve_checkpoint(args: argparse.Namespace, workdir: str) -> Resolved:
    """Where the checkpoint comes from: ``--checkpoint`` as is; ``--run-id`` / ``--best-of``
    download the trial's checkpoint artifact into ``workdir``."""
    if args.checkpoint:
        return Resolved(checkpoint=args.checkpoint, source=f"checkpoint {args.checkpoint}")
    client = mlflow_client(args.tracking_uri)
    if args.run_id:
        run, source = get_run(client, args.run_id), f"MLflow run {args.run_id}"
    else:
        from lac_rllib.constrained.metrics import EPISODE_RETURN

        run = best_trial(client, args.best_of)
        source = (f"MLflow run {run.info.run_id} (best feasible trial of sweep {args.best_of}, "
                  f"{EPISODE_RETURN} {run.data.metrics.get(EPISODE_RETURN)})")
    from sweeps.tracking import CHECKPOINT_TAG, P_TASK

    path = download_checkpoint(client, run, workdir)
    return Resolved(checkpoint=path, run_id=run.info.run_id, source=source,
                    uri=f"runs:/{run.info.run_id}/{run.data.tags[CHECKPOINT_TAG]}",
                    task_param=run.data.params.get(P_TASK))


def log_eval_to_run(client, run_id: str, result: dict, step: int = 0) -> list[str]:
    """Log the evaluation back to the run as ``eval/<actions>/<key>`` metrics at ``step`` (a
    sweep's trial: the env steps it was evaluated at); return the keys."""
    import time

    from mlflow.entities import Metric, RunTag

    mode, now = result["actions"], int(time.time() * 1000)
    metrics = [Metric(f"{EVAL_PREFIX}/{mode}/{k}", float(result[k]), now, int(step))
               for k in LOGGED_KEYS if k in result and result[k] is not None]
    # Several constraints: each one's cost, limit and share of episodes within it, and the joint share.
    metrics += [Metric(f"{EVAL_PREFIX}/{mode}/{k}/{name}", float(c[k]), now, int(step))
                for name, c in (result.get("constraints") or {}).items()
                for k in ("cost_mean", "cost_std", "cost_limit", "within_limit_fraction")]
    if "within_all_limits_fraction" in result:
        metrics.append(Metric(f"{EVAL_PREFIX}/{mode}/within_all_limits_fraction",
                              float(result["within_all_limits_fraction"]), now, int(step)))
    tags = [RunTag(f"lac.eval.{mode}.episodes", str(result["episodes"])),
            RunTag(f"lac.eval.{mode}.seed", str(result["seed"]))]
    if mode == "langevin":
        tags += [RunTag("lac.eval.langevin.steps", str(result["langevin_steps"])),
                 RunTag("lac.eval.langevin.step_size", repr(result["langevin_step_size"]))]
    client.log_batch(run_id, metrics=metrics, tags=tags)
    for path in result.get("videos") or []:  # the rendered episodes, beside the trial's artifacts
        client.log_artifact(run_id, path, f"eval_videos/{mode}")
    return [m.key for m in metrics]


# ----------------------------------------------------------------------------- output


def _one_line(e) -> str:
    return " ".join(str(e).split())[:300]


def _pm(mean: float, std: float) -> str:
    return f"{mean:.4g} ± {std:.3g}"


def format_human(result: dict, source: str) -> str:
    n, inside = result["episodes"], sum(c <= result["cost_limit"] for c in result["costs"])
    gamma = result["episode_cost_discount"]
    convention = "summed" if gamma == 1.0 else f"discounted with {gamma:g}"
    lines = [
        f"{source}",
        f"task {result['task']}  algo {result.get('algo', DEFAULT_ALGO)}  actions {result['actions']}  episodes {n}  "
        f"seeds {result['seed']}..{result['seed'] + n - 1}",
        f"return         {_pm(result['return_mean'], result['return_std'])}",
        f"cost           {_pm(result['cost_mean'], result['cost_std'])}  ({convention} per episode)",
        f"cost limit     {result['cost_limit']:g}",
        f"within limit   {result['within_limit_fraction']:.0%} ({inside}/{n} episodes)",
    ]
    for name, c in (result.get("constraints") or {}).items():
        lines.append(f"  {name:<12} {_pm(c['cost_mean'], c['cost_std'])}  limit {c['cost_limit']:g}  "
                     f"within {c['within_limit_fraction']:.0%}")
    if "within_all_limits_fraction" in result:
        lines.append(f"within all     {result['within_all_limits_fraction']:.0%} (every constraint within its limit)")
    if result["actions"] == "langevin":
        nu = result["nu"]
        nu = ", ".join(f"{v:.3g}" for v in nu) if isinstance(nu, list) else f"{nu:.3g}"
        lines.append(
            f"energy         generator (chain start) {result['energy_generator_mean']:.4g} -> refined "
            f"{result['energy_refined_mean']:.4g}  (T={result['langevin_steps']}, "
            f"eta={result['langevin_step_size']:g}, nu={nu})")
    for path in result.get("videos") or []:
        lines.append(f"video          {path}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        check_args(args)
    except UsageError as e:
        parser.exit(2, f"{PROG}: error: {e}\n")

    import logging

    import torch

    # MLflow's own download bar floods logs with carriage returns; ours is enough.
    os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")

    torch.set_num_threads(1)
    # RLlib's own RLModule constructor logs a deprecation warning about RLModuleConfig.
    logging.getLogger("ray._common.deprecation").setLevel(logging.ERROR)
    from lac_rllib.evaluation import CheckpointError, evaluate, restore_policy

    with tempfile.TemporaryDirectory(prefix="lac-eval-") as workdir:  # MLflow downloads go here
        try:
            resolved = resolve_checkpoint(args, workdir)
            policy = restore_policy(resolved.checkpoint)
            if args.actions not in policy.actions:  # the modes its algorithm declares (its config's ACTIONS)
                raise UsageError(f"--actions {args.actions} is not a mode of {policy.algo} ({resolved.checkpoint}); "
                                 f"accepted: --actions {' | '.join(policy.actions)}")
        except (UsageError, CheckpointError) as e:
            parser.exit(2, f"{PROG}: error: {e}\n")
        if resolved.task_param and resolved.task_param != policy.task_id:
            print(f"{PROG}: notice: run param task={resolved.task_param} but the checkpoint's task is "
                  f"{policy.task_id}; evaluating on {policy.task_id}", file=sys.stderr)
        result = evaluate(policy, args.episodes, args.seed, actions=args.actions,
                          langevin_steps=args.langevin_steps,
                          langevin_step_size=args.langevin_step_size,
                          video_dir=args.video, progress=not args.no_progress)
        if resolved.run_id:
            # The download is a temporary copy: name the artifact instead.
            result["checkpoint"], result["run_id"] = resolved.uri, resolved.run_id
            result["logged_metrics"] = log_eval_to_run(mlflow_client(args.tracking_uri), resolved.run_id, result)
    print(format_human(result, resolved.source), flush=True)
    if args.json:
        print(json.dumps(result, default=str), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
