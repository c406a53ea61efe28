"""SweepTrial: one sweep trial = one run of LAC or a baseline inside a Tune trial, tracked in its
MLflow child run.

Tune owns scheduling, checkpoints (``save_checkpoint`` writes the RLlib checkpoint), restore and
failure handling; this class only adapts LAC to it and reports. A trial that raises or produces
NaN is marked FAILED in MLflow with the error before Tune marks it ERROR.
"""

from __future__ import annotations

import json
import math
import os
import socket
import tempfile
import time
import traceback

import ray
from ray import tune
from ray.tune.result import TIME_TOTAL_S

from lac_rllib.algorithms.registry import add_module_dir, build_config, split_algo
from lac_rllib.constrained.changeable import reapply_learning_rates
from lac_rllib.constrained.metrics import (
    COST_LIMIT,
    ENV_STEPS,
    EPISODE_RETURN,
    ITERATION,
    iteration_row,
    non_finite,
)
from lac_rllib.tasks.user import FACTORY as USER_FACTORY
from lac_rllib.tasks.user import register_definition
from sweeps import spaces
from sweeps.integrity import CHECKSUM_TAG, manifest_tag
from sweeps.objective import CONSTRAINT, OBJECTIVE, OBJECTIVE_WINDOW, WALL_TIME_S, objective
from sweeps.pbt import COPIES_TAG, MEMBER_FILE, PARENTS_TAG, SCHEDULE_PREFIX, fields_at, window_row
from sweeps.score import (
    SCORE_COST,
    SCORE_RETURN,
    SCORE_TAG,
    SCORES,
    TRAIN_COST,
    TRAIN_RETURN,
    declared,
    eval_score,
    joint_curve,
    joint_score,
    row_cost,
    train_score,
)
from sweeps.seeds import EVAL_SEED_BASE, check_streams, eval_seed  # noqa: F401 (EVAL_SEED_BASE: named here before)
from sweeps.tracking import (
    ALGO_TAG,
    CHECKPOINT_TAG,
    CONFIG_ID_TAG,
    CONFIG_TAG,
    DEFAULT_TAG,
    ENV_FINGERPRINT_JSON_TAG,
    ENV_FINGERPRINT_TAG,
    ERROR_TAG,
    LADDER_CONSTRAINT_TAG,
    NODE_TAG,
    P_ALGO,
    P_GROUP,
    P_SEED,
    P_SWEPT_PARAM,
    P_SWEPT_VALUE,
    P_TASK,
    P_TASK_SOURCE,
    P_TIMESTEPS,
    RESOLVED_TAG_PREFIX,
    TrialTracker,
    learning_curve,
)

#: Episodes of the evaluation block at a trial's end unless the sweep file says (``eval_episodes``).
EVAL_EPISODES = 10

#: The evaluation block's modes unless the sweep file says (``eval_modes``): deterministic, then stochastic.
EVAL_MODES = ("generator", "stochastic")


def evaluation_block(checkpoint: str, episodes: int, seed: int, modes=EVAL_MODES) -> list[dict]:
    """The evaluation block (issue 36): ``episodes`` episodes of the checkpoint's policy in each of
    ``modes`` it can act in (the deterministic action ``generator``, the stochastic policy
    ``stochastic``, LAC's ``langevin``: lac-eval's ``--actions``), on seeds :func:`eval_seed` on;
    one ``lac_rllib.evaluation.evaluate`` result per mode."""
    from lac_rllib.evaluation import evaluate, restore_policy

    policy = restore_policy(checkpoint)
    return [evaluate(policy, episodes, eval_seed(seed), mode, progress=False)
            for mode in modes if mode in policy.actions]


def fingerprint_tags(task: str, params: dict) -> dict:
    """The trial's env fingerprint as its MLflow tags (its id, and the whole as JSON). A trial on
    several CPUs splits its ``num_envs_per_env_runner`` envs over its runners (constrained/cpus.py):
    the envs of an iteration, what the fingerprint counts, do not change with its CPUs."""
    from lac_rllib.tasks.fingerprint import fingerprint, fingerprint_id

    fp = fingerprint(task, params)
    return {ENV_FINGERPRINT_TAG: fingerprint_id(fp), ENV_FINGERPRINT_JSON_TAG: json.dumps(fp, default=str)}


class SweepTrial(tune.Trainable):
    """One trial. config: ``trial`` (a grid trial's TrialSpec, its fields resolved at plan time)
    or, for a search, ``task``, ``budget``, ``sets``, ``seeds`` and the sampled ``overrides``
    (spaces.trial_spec makes both a TrialSpec); ``timesteps``, ``cpus``, ``user_tasks`` (a user env's
    TaskSpec as data, registered here), ``user_algos`` (a user's algorithm → the folder it is
    imported from), ``tracking`` {uri, experiment, parent_run_id}."""

    def setup(self, config: dict) -> None:
        for definition in config.get("user_tasks", {}).values():  # a user's env, registered in this process
            register_definition(definition)
        for folder in config.get("user_algos", {}).values():  # a user's algorithm, importable in this process
            add_module_dir(folder)
        self.spec = spec = spaces.trial_spec(config)
        self.timesteps = int(spec.timesteps or config["timesteps"])
        # The trial's algorithm and fields as resolved (spaces.trial_params), run on its CPUs (env
        # runners and torch threads: lac_rllib.algorithms.lac.config.use_cpus).
        # A replayed schedule (a PBT winner's, sweeps/pbt.py) starts at its first entry's fields.
        self.schedule = [(int(at), dict(fields)) for at, fields in (spec.schedule or ())]
        self.changes = fields_at(self.schedule, 0)
        self._build()
        algo = split_algo(spec.params)[0]
        tr = config["tracking"]
        self.tracker = TrialTracker(tr["uri"], tr["experiment"], tr.get("parent_run_id"), self.trial_id,
                                    spec.label())
        task = self.algo_config.task_spec
        user = task.factory == USER_FACTORY
        source = task.kwargs.get("factory") or task.kwargs.get("gym_id") if user else task.factory
        params = {P_TASK: spec.task, P_TASK_SOURCE: source, P_SEED: spec.seed, P_GROUP: spec.group,
                  P_SWEPT_PARAM: spec.param, P_SWEPT_VALUE: spec.value, P_TIMESTEPS: self.timesteps, P_ALGO: algo,
                  **self.algo_config.params()}
        tags = {NODE_TAG: ray.get_runtime_context().get_node_id(), "lac.host": socket.gethostname(),
                "lac.tune_trial_name": self.trial_name, "lac.group": spec.group,
                # MLflow's UI groups runs by a tag and averages their curves: one group per configuration.
                CONFIG_ID_TAG: spaces.config_id(spec.task, self.timesteps, {P_ALGO: algo, **self.algo_config.params()}),
                ALGO_TAG: algo,
                CONFIG_TAG: spec.config_label(), DEFAULT_TAG: "1" if spec.default else "0",
                # What environment it learned in: reports never rank runs of different ones together.
                **fingerprint_tags(spec.task, self.algo_config.params())}
        self.tracker.open(params, tags)
        prev = self.tracker.previous
        # A trial killed after its run FINISHED but before Tune persisted its last checkpoint is
        # complete: it must not train (and log) again on resume.
        self.already_finished = bool(prev and prev.info.status == "FINISHED" and CHECKPOINT_TAG in prev.data.tags)
        # Iterations replayed from the last checkpoint do not log steps MLflow already has, so
        # every metric history stays one point per step; the tag says where training picked up.
        self.logged_up_to = self.tracker.logged_up_to(ENV_STEPS)
        # The evaluation blocks' seconds so far (a trial paused at a rung, or resumed, goes on counting).
        self.eval_seconds = float(prev.data.metrics.get("eval_time_s", 0.0)) if prev else 0.0
        if self.logged_up_to and not self.already_finished:
            self.tracker.set_tags({"lac.resumed_after_env_steps": self.logged_up_to})
        # The node of the latest (re)start, and what rule-valued fields ("auto") resolved to there.
        self.tracker.set_tags({NODE_TAG: tags[NODE_TAG],
                               **{f"{RESOLVED_TAG_PREFIX}{k}": v for k, v in self.algo_config.resolved().items()}})
        self.tracker.log_text(json.dumps({**params, COST_LIMIT: self.algo_config.effective_cost_limit},
                                         indent=2, default=str), "config.json")
        # PBT (config ``pbt``: its window) and a replayed schedule: the member's record, carried in its
        # checkpoints (MEMBER_FILE): its recent rows, its fields' schedule and its parents.
        self.window = int((config.get("pbt") or {}).get("window", 0))
        self.member = {"trial_id": self.trial_id, "trial_name": self.trial_name, "env_steps": 0, "rows": [],
                       "schedule": [[0, self._changeable()]], "parents": []}

    def _build(self, checkpoint: str | None = None) -> None:
        """The trial's algorithm: its resolved fields with ``self.changes`` on top (a schedule's, or
        what an exploit set), on its CPUs; ``checkpoint``: the state restored into it (the learning
        rates set again from its own fields: lac_rllib/constrained/changeable.py)."""
        cpus = int(self.config.get("cpus", 1))  # a trial's torch threads are its CPUs, whatever --set says
        algo, fields = split_algo(self.spec.params)
        self.algo_config = build_config(algo, self.spec.task, self.spec.seed,
                                        {**fields, **self.changes, "torch_threads": cpus},
                                        timesteps=self.timesteps, cpus=cpus)
        # Its streams within the seed stride, or a confirmation's could meet them (sweeps/seeds.py).
        check_streams(self.algo_config.num_env_runners, self.algo_config.num_envs_per_env_runner)
        self.algo = self.algo_config.build_algo()
        if checkpoint is not None:
            self.algo.restore_from_path(checkpoint)
            reapply_learning_rates(self.algo)

    def _changeable(self) -> dict:
        """The values of the fields PBT may change, as this member runs them."""
        return {f: getattr(self.algo_config, f) for f in type(self.algo_config).changeable_fields()}

    def _switch(self, changes: dict) -> None:
        """A replayed schedule's change: the algorithm rebuilt with ``changes`` and its own state
        restored into it, as PBT's exploit rebuilt the member it copied into."""
        with tempfile.TemporaryDirectory() as tmp:
            self.algo.save_to_path(tmp)
            self.algo.stop()
            self.changes = changes
            self._build(tmp)

    def step(self) -> dict:
        if self.already_finished:
            final = {k: v for k, v in self.tracker.previous.data.metrics.items()}
            return {**final, "done": True}
        try:
            if self.iteration + 1 == self.spec.fail_at_iteration:
                raise RuntimeError(f"injected failure at iteration {self.iteration + 1} (fail_at_iteration)")
            due = fields_at(self.schedule, self.member["env_steps"])
            if due != self.changes:  # a replayed schedule's next entry
                self._switch(due)
            r = self.algo.train()
            metrics = iteration_row(r, self.algo.config.REPORTED_KEYS)
            del metrics[ITERATION]  # Tune counts its own (training_iteration); MLflow's step is env steps
            bad = non_finite(metrics)
            if bad:
                raise FloatingPointError(f"non-finite {', '.join(bad)} at iteration {self.iteration + 1}")
            cost, limit = row_cost(metrics)  # the joint rule's with several constraints (sweeps/score.py)
            metrics[OBJECTIVE] = objective(metrics[EPISODE_RETURN], cost, limit)
            metrics[CONSTRAINT] = cost - limit  # ≤ 0 is feasible
            metrics[WALL_TIME_S] = float(r.get(TIME_TOTAL_S, 0.0))
            self.member["env_steps"] = int(metrics[ENV_STEPS])
            if self.window or self.schedule:  # the member's fields as it runs them: its schedule's curve
                metrics.update({f"{SCHEDULE_PREFIX}{k}": float(v) for k, v in self._changeable().items()
                                if isinstance(v, (int, float))})
            if self.window:  # PBT ranks on the one rule over the last ``window`` iterations (sweeps/pbt.py)
                self.member["rows"] = [*self.member["rows"], {k: v for k, v in metrics.items()
                                                              if isinstance(v, (int, float))}][-self.window:]
                recent = window_row(self.member["rows"])
                metrics[OBJECTIVE_WINDOW] = objective(recent[EPISODE_RETURN], *row_cost(recent))
            done = metrics[ENV_STEPS] >= self.timesteps
            if metrics[ENV_STEPS] > self.logged_up_to:
                # The last step's objective is the trial's score's, logged when the trial finishes.
                self.tracker.log_metrics({k: v for k, v in metrics.items() if not (done and k == OBJECTIVE)},
                                         step=int(metrics[ENV_STEPS]))
            every = int(self.config.get("eval_every") or 0)
            if every and not done and (self.iteration + 1) % every == 0 and metrics[ENV_STEPS] > self.logged_up_to:
                with tempfile.TemporaryDirectory() as tmp:  # the block every K iterations, on a snapshot
                    self.algo.save_to_path(os.path.join(tmp, "checkpoint"))
                    self._evaluate(os.path.join(tmp, "checkpoint"), int(metrics[ENV_STEPS]))
            if done:
                # Tune's last result (what Optuna is told) carries the trial's score (sweeps/score.py).
                score = self._finish_run(int(metrics[ENV_STEPS]))
                metrics.update(score)
                metrics[COST_LIMIT] = limit  # what the score's cost is held to (0: the joint rule's)
                if all(math.isfinite(v) for v in score.values()):
                    metrics[OBJECTIVE] = objective(score[SCORE_RETURN], score[SCORE_COST], limit)
                elif metrics[ENV_STEPS] > self.logged_up_to:  # no score: the last iteration's, as every other
                    self.tracker.log_metrics({OBJECTIVE: metrics[OBJECTIVE]}, step=int(metrics[ENV_STEPS]))
            return {**metrics, "done": done}
        except Exception as e:
            self.tracker.set_tags({ERROR_TAG: f"{type(e).__name__}: {e}"[:4000]})
            self.tracker.log_text(traceback.format_exc(), "error.txt")
            self.tracker.finish("FAILED")
            raise

    def _finish_run(self, env_steps: int) -> dict:
        """Final checkpoint, evaluation block and learning curve as artifacts, the trial's declared
        score (sweeps/score.py: the sweep's ``score``) and its train score logged, the score used
        tagged, then the MLflow run closed; returns the declared score."""
        from sweeps.reports.multiplier import METRIC_PREFIX, constraint_behaviour, multiplier_behaviour
        from sweeps.reports.report import trial_curve

        with tempfile.TemporaryDirectory() as tmp:
            self.algo.save_to_path(os.path.join(tmp, "checkpoint"))
            self._evaluate(os.path.join(tmp, "checkpoint"), env_steps)
            # The manifest goes to the tracking store, the files to the artifact store: a restore
            # checks one against the other (sweeps/integrity.py).
            self.tracker.set_tags({CHECKSUM_TAG: manifest_tag(os.path.join(tmp, "checkpoint"))})
            self.tracker.log_artifacts(os.path.join(tmp, "checkpoint"), "checkpoint")
            several = self.algo_config.several_constraints
            names = several.names if several is not None else ()
            curve = learning_curve(self.tracker.client, self.tracker.run_id, self.algo_config.effective_cost_limit,
                                   names)
            trial_curve(curve, os.path.join(tmp, "learning_curve.png"), self.trial_name)
            self.tracker.client.log_artifact(self.tracker.run_id, os.path.join(tmp, "learning_curve.png"))
        train = train_score(curve)
        figures = multiplier_behaviour(joint_curve(curve, dict(zip(names, several.limits))) if names else curve)
        if names:  # several constraints: each one's multiplier against its own cost and limit too
            figures |= constraint_behaviour(curve, dict(zip(names, several.limits)))
        behaviour = {METRIC_PREFIX + k: v for k, v in figures.items() if math.isfinite(v)}
        try:  # the evaluation's metrics, logged above straight to the store
            metrics = self.tracker.client.get_run(self.tracker.run_id).data.metrics
        except Exception:  # the store away: ranked on train, and the tag says so
            metrics = {}
        (ret, cost), used = declared(self.config.get("score", SCORES[0]), train, eval_score(metrics))
        limit, per = self.algo_config.effective_cost_limit, {}
        if names:  # several constraints: the joint rule's cost max_k (J_k − b_k), held to 0 (sweeps/score.py)
            limits = dict(zip(names, several.limits))
            (ret, cost), used, per = joint_score(self.config.get("score", SCORES[0]), curve, metrics, limits)
            limit = 0.0
        score = {SCORE_RETURN: ret, SCORE_COST: cost}
        # The run's final objective is its score's (what it is ranked on, and what Optuna is told).
        final = objective(ret, cost, limit) if math.isfinite(ret + cost) else math.nan
        logged = {k: v for k, v in {**score, TRAIN_RETURN: train[0], TRAIN_COST: train[1], OBJECTIVE: final,
                                    **{f"{SCORE_COST}/{n}": c for n, c in per.items()},
                                    **behaviour}.items() if math.isfinite(v)}
        if logged:
            self.tracker.log_metrics(logged, step=int(curve[ENV_STEPS].max()))
        if self.window or self.schedule:  # the member's schedule and parents: what a replay reruns
            self.tracker.log_text(json.dumps({k: self.member[k] for k in ("schedule", "parents")}, default=float),
                                  MEMBER_FILE)
        self.tracker.set_tags({CHECKPOINT_TAG: "checkpoint", SCORE_TAG: used,
                               **({LADDER_CONSTRAINT_TAG: self.config["ladder_constraint"]}
                                  if names and self.config.get("ladder_constraint") else {})})
        self.tracker.finish("FINISHED")
        return score

    def _evaluate(self, checkpoint: str, step: int) -> None:
        """An evaluation block, logged to the trial's run as ``eval/<mode>/...`` at env step
        ``step`` (the final block at the last one, so it is what the run's metrics show), with the
        seconds all blocks took so far (``eval_time_s``); a failure is tagged, not raised: the
        trial trained."""
        from sweeps.evaluate import log_eval_to_run

        episodes = int(self.config.get("eval_episodes", EVAL_EPISODES))
        if not episodes:
            return
        start = time.time()
        try:
            for result in evaluation_block(checkpoint, episodes, self.spec.seed,
                                           tuple(self.config.get("eval_modes") or EVAL_MODES)):
                log_eval_to_run(self.tracker.client, self.tracker.run_id, result, step=step)
        except Exception as e:
            self.tracker.set_tags({"lac.eval_error": f"{type(e).__name__}: {e}"[:4000]})
        self.eval_seconds += time.time() - start
        self.tracker.log_metrics({"eval_time_s": self.eval_seconds}, step=step)

    def save_checkpoint(self, checkpoint_dir: str) -> None:
        self.algo.save_to_path(checkpoint_dir)
        with open(os.path.join(checkpoint_dir, MEMBER_FILE), "w") as f:
            json.dump(self.member, f, default=float)

    def load_checkpoint(self, checkpoint: str) -> None:
        """Its own checkpoint (a resume, a pause), or on PBT's exploit a donor's: the donor's whole
        state restored into this member as its (perturbed) fields build it, its learning rates set
        again (lac_rllib/constrained/changeable.py), the donor's record inherited and the copy
        recorded as this member's parent (``lac.pbt.parents``)."""
        path = os.path.join(checkpoint, MEMBER_FILE)
        saved = None
        if os.path.exists(path):
            with open(path) as f:
                saved = json.load(f)
        due = fields_at(self.schedule, saved["env_steps"]) if saved else self.changes
        if due != self.changes:  # a replay resumed past a change: built with the fields due there
            self.algo.stop()
            self.changes = due
            self._build(checkpoint)
        else:
            self.algo.restore_from_path(checkpoint)
            reapply_learning_rates(self.algo)
        if saved is None:
            return
        member = {**saved, "trial_id": self.trial_id, "trial_name": self.trial_name}
        if saved["trial_id"] != self.trial_id:  # an exploit (or a migration): the donor's lineage, then the copy
            at = int(saved["env_steps"])
            member["schedule"] = [*saved["schedule"], [at, self._changeable()]]
            member["parents"] = [*saved["parents"], [at, saved["trial_name"]]]
            previous = self.tracker.previous.data.tags.get(COPIES_TAG) if self.tracker.previous else None
            copies = [*json.loads(previous or "[]"), [at, saved["trial_name"]]]
            self.tracker.set_tags({PARENTS_TAG: json.dumps(member["parents"])[:4000],
                                   COPIES_TAG: json.dumps(copies)[:4000]})
        self.member = member

    def cleanup(self) -> None:
        self.tracker.flush()
        self.algo.stop()


#: The name this class had before 0.3: a Tune experiment state written then names it, and a
#: ``--resume`` of such a sweep finds it here.
LACTrainable = SweepTrial
