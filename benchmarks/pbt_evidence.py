"""Population-based training against the constrained TPE and random search at equal env steps, on
one task and algorithm: four searches, each winner confirmed on fresh seeds (results in ``--out``).

    python benchmarks/pbt_evidence.py --task lac/PointHazard-v0 --algo ppo_lag --budget quick \\
        --members 8 --interval 5000 --out RUN_DIR/pbt-pointhazard-ppo_lag

The searches, each a sweep of the project's own (``sweeps/run.py``, one after another, resumable:
the same command goes on where it stopped):

- ``pbt``: ``search: pbt``, ``--members`` members × the budget (sweeps/pbt.py);
- ``pbt-half``: the same with half the members: half the env steps;
- ``tpe``: the constrained TPE with its scheduler (``scheduler: asha``) over the same fields, one
  seed per sample, drawing until it has spent PBT's env steps (``env_steps_budget``: members ×
  the budget; an early stop frees its rest for more samples, at most 4 × members);
- ``random``: Optuna's random sampler under the same budget of spent env steps.

Each winner (its best feasible configuration, or schedule for PBT) is confirmed beside the default
on ``--confirm-seeds`` fresh seeds (``--confirm-top 1``). Each search's trials and its
confirmation's are exported to ``search-METHOD.csv`` and ``confirm-METHOD.csv``, and the table is
rendered from them alone (``--report-only --from-csv`` renders a committed folder again):
``results.csv`` and ``results.md`` in ``--out``: per search the env steps it spent (every trial's
last env steps, summed, ASHA's early stops included), its winner's fresh-seed return and cost with
their intervals and P(feasible) with Wilson's (sweeps/reports/verdicts.py ``verdict``), and
whether it meets P(feasible) ≥ 0.8; and the goal's verdict: PBT-half against TPE (PBT reaches
TPE's fresh-seed return at the same P(feasible) in at most half the env steps) by the interval
rule: overlapping intervals are ties.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[1]
METHODS = ("pbt", "pbt-half", "tpe", "random")


def sweep_text(method: str, task: str, algo: str, budget, members: int, interval: int, extra: str) -> str:
    """The sweep file of one search."""
    head = f"task: {task}\nalgo: {algo}\nbudget: {budget}\n{extra}"
    if method.startswith("pbt"):
        n = members if method == "pbt" else max(2, members // 2)
        return head + f"search: pbt\npbt: {{members: {n}, interval: {interval}}}\n"
    import yaml

    from sweeps.spaces import declared_search

    # The fields PBT changes, with the same ranges (an algorithm's rates outside its search space too).
    search = declared_search(algo, task, budget, {"algo": algo}, "default", changeable=True)
    from sweeps.spaces import get_budget

    # The env steps PBT spends (members × budget) as this search's budget of spent env steps: an early
    # stop (ASHA) frees its rest for more draws, up to 4 × members samples.
    spend = members * get_budget(budget).for_task(task)
    searcher = "tpe\nscheduler: asha" if method == "tpe" else "random"
    return (head + yaml.safe_dump({"search": search}, sort_keys=False, width=110)
            + f"searcher: {searcher}\nnum_samples: {4 * members}\nseeds: 1\nenv_steps_budget: {spend}\n")


def run_search(out: Path, method: str, args) -> int:
    path = out / f"{method}.yaml"
    path.write_text(sweep_text(method, args.task, args.algo, args.budget, args.members, args.interval, args.extra))
    name = f"pbt-evidence-{method}"
    resume = (out / "ray_results" / name / "sweep.json").exists()
    cmd = [sys.executable, str(REPO / "sweeps" / "run.py"), "--config", str(path), "--name", name,
           "--tracking-uri", f"sqlite:///{out / 'mlflow.db'}", "--storage", str(out / "ray_results"),
           "--confirm-top", "1", "--confirm-seeds", str(args.confirm_seeds), *(["--resume"] if resume else [])]
    print("running:", " ".join(cmd), flush=True)
    with open(out / f"{method}.log", "a") as log:
        return subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=REPO)


#: The data a folder's table is rendered from: each search's trials and its confirmation's.
SEARCH_CSV, CONFIRM_CSV = "search-{method}.csv", "confirm-{method}.csv"


def export(out: Path) -> list[str]:
    """Each search's trials (with each one's last env steps) and its confirmation's, read back from
    the MLflow store in ``out`` into CSVs beside it: the data :func:`results` renders the table from.
    Returns the searches found."""
    from sweeps.reports.results import sweep_results
    from sweeps.tracking import SweepTracker

    tracker = SweepTracker(f"sqlite:///{out / 'mlflow.db'}", "lac-sweeps")
    exps = [e.experiment_id for e in tracker.client.search_experiments()]
    parents = {r.data.tags.get("mlflow.runName"): r.info.run_id
               for r in tracker.client.search_runs(exps, filter_string="tags.`lac.sweep` = '1'", max_results=1000)}
    found = []
    for method in METHODS:
        name = f"pbt-evidence-{method}"
        if name not in parents:
            continue
        trials, _ = sweep_results(tracker, parents[name])
        if method.startswith("pbt"):  # each member's schedule: what its winner replayed
            from sweeps.pbt import with_schedules

            trials = with_schedules(trials, tracker.client, parents[name])
        # Each trial's last env steps: where ASHA stopped it, or its budget (a PBT member trains its own once).
        steps = {r.data.tags.get("lac.trial_id"): int(r.data.metrics.get("env_steps", 0))
                 for r in tracker.children(parents[name])}
        trials.assign(env_steps=[steps.get(t, 0) for t in trials["trial_id"]]).to_csv(
            out / SEARCH_CSV.format(method=method), index=False)
        if f"{name}-confirm" in parents:
            sweep_results(tracker, parents[f"{name}-confirm"])[0].to_csv(out / CONFIRM_CSV.format(method=method),
                                                                        index=False)
        found.append(method)
    return found


def results(folder: Path, confirm_seeds: int) -> pd.DataFrame:
    """Per search, from the CSVs :func:`export` wrote: the env steps it spent and its winner's
    fresh-seed figures (sweeps/reports/verdicts.py ``verdict``: t at 98%, Wilson)."""
    from sweeps.reports.verdicts import FEASIBLE_SHARE, verdict

    rows = []
    for method in METHODS:
        search = folder / SEARCH_CSV.format(method=method)
        if not search.exists():
            continue
        trials = pd.read_csv(search)
        path = folder / CONFIRM_CSV.format(method=method)
        confirm = (pd.read_csv(path) if path.exists() else
                   pd.DataFrame(columns=["default", "status", "episode_return", "episode_cost", "cost_limit",
                                         "config"]))
        winner = confirm[~confirm["default"].astype(bool) & confirm["status"].eq("TERMINATED")]  # ran to its end
        limit = float(winner["cost_limit"].iloc[0]) if len(winner) else float("nan")
        v = verdict(winner["episode_return"], winner["episode_cost"], limit)
        m = winner.to_dict("records")
        rows.append({"method": method, "trials": len(trials), "env_steps_spent": int(trials["env_steps"].sum()),
                     "winner": m[0]["config"] if m else None,
                     "fresh_seeds": v["n_seeds"], "return": v["return"][0], "return_low": v["return"][1],
                     "return_high": v["return"][2], "cost": v["cost"][0], "p_feasible": v["p_feasible"][0],
                     "p_feasible_low": v["p_feasible"][1], "p_feasible_high": v["p_feasible"][2],
                     "meets_p_feasible": bool(m) and v["n_feasible"] >= FEASIBLE_SHARE * v["n_seeds"] - 1e-12,
                     "confirmed": len(m) >= confirm_seeds})
    return pd.DataFrame(rows)


def markdown(table: pd.DataFrame) -> str:
    lines = ["| search | env steps spent | winner's fresh-seed return [interval] | cost | P(feasible) [Wilson] | "
             "P(feasible) ≥ 0.8 |", "|---|---:|---:|---:|---:|---|"]
    for r in table.to_dict("records"):
        if not r["fresh_seeds"]:  # the search found nothing feasible: there was no winner to confirm
            lines.append(f"| {r['method']} | {r['env_steps_spent']:,} | – (no feasible winner to confirm) "
                         "| – | – | no |")
            continue
        lines.append(f"| {r['method']} | {r['env_steps_spent']:,} | {r['return']:.3g} [{r['return_low']:.3g}, "
                     f"{r['return_high']:.3g}] | {r['cost']:.3g} | {r['p_feasible']:.2f} [{r['p_feasible_low']:.2f}, "
                     f"{r['p_feasible_high']:.2f}] | {'yes' if r['meets_p_feasible'] else 'no'} |")
    by = table.set_index("method")
    if {"pbt-half", "tpe"} <= set(by.index) and by.loc["tpe", "confirmed"]:
        half, tpe = by.loc["pbt-half"], by.loc["tpe"]
        ratio = half["env_steps_spent"] / max(1, tpe["env_steps_spent"])
        if not half["fresh_seeds"]:
            ret = "had no feasible winner to confirm"
        else:
            overlap = half["return_high"] >= tpe["return_low"] and tpe["return_high"] >= half["return_low"]
            ret = ("ties TPE's fresh-seed return (the intervals overlap)" if overlap else
                   "is above TPE's fresh-seed return" if half["return"] > tpe["return"] else
                   "is below TPE's fresh-seed return")
        feasible = "meets" if half["meets_p_feasible"] else "does not meet"
        met = (ratio <= 0.5 and half["meets_p_feasible"] and bool(half["fresh_seeds"])
               and not ret.startswith("is below"))
        theirs = "meets" if tpe["meets_p_feasible"] else "does not meet"
        lines += ["", f"Goal (PBT reaches the TPE winner's fresh-seed return at P(feasible) ≥ 0.8 in at most half "
                      f"the env steps): PBT with half the members spent {ratio:.2f}x the env steps TPE spent, "
                      f"{ret}, and {feasible} P(feasible) ≥ 0.8 (TPE's winner {theirs} it): "
                      + ("met." if met else "not met.")]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--task", required=True)
    p.add_argument("--algo", required=True)
    p.add_argument("--budget", default="quick", help="env steps per member / trial (a budget name or a number)")
    p.add_argument("--members", type=int, default=8)
    p.add_argument("--interval", type=int, required=True, help="env steps between PBT's exploits")
    p.add_argument("--confirm-seeds", type=int, default=5)
    p.add_argument("--extra", default="", help="sweep-file lines every search takes (e.g. 'eval_episodes: 5\\n')")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--only", choices=METHODS, action="append", help="run these searches (default: all four)")
    p.add_argument("--report-only", action="store_true", help="no search run: the table from what is in --out")
    p.add_argument("--from-csv", action="store_true", help="with --report-only: the table from --out's CSVs alone "
                                                            "(a committed folder), not its MLflow store")
    args = p.parse_args(argv)
    args.extra = args.extra.replace("\\n", "\n")
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.report_only:
        (args.out / "command.json").write_text(json.dumps(vars(args), default=str, indent=1))
    if not args.report_only:
        for method in args.only or METHODS:
            rc = run_search(args.out, method, args)
            if rc != 0:
                print(f"{method}: exit {rc}; see {args.out / (method + '.log')}", file=sys.stderr)
                return rc
    if not args.from_csv:
        export(args.out)
    table = results(args.out, args.confirm_seeds)
    table.to_csv(args.out / "results.csv", index=False)
    (args.out / "results.md").write_text(markdown(table))
    print(markdown(table))
    return 0


if __name__ == "__main__":
    sys.exit(main())
