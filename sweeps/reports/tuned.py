"""The report of a tuned comparison (sweeps/tuned.py): what tuning changed, per algorithm, every
verdict decided by sweeps/reports/verdicts.py.

On the confirmation's fresh seeds, per environment (a task the env fingerprint split is two; runs of
two environments are never pooled or ranked together) and per algorithm:

- **default against tuned**: both scores with their intervals, the seeds each rests on and the
  seeds that failed; the gap tuned − default in return, **paired** by seed (both ran on the same
  fresh seeds: the per-seed differences' t-interval) and P(improvement), the chance a tuned seed
  beats a default one; **improved**: the tuned configuration is feasible and the paired interval
  lies wholly above 0 (the registry keeps an entry only then, sweeps/tuned_registry.py);
- **the winner's curse**: the winner's score on the search's seeds minus its score on the fresh ones
  (a search's best is the best of many noisy draws: its search score is biased upward);
- **the search's spread**: how far the search's configurations spread on one task: for return and
  cost, the best configuration's mean minus the median configuration's and the interquartile range
  of the configurations' means (search spread plus seed noise); for feasibility the share of
  configurations feasible by the rule. It is not Adkins, Bowling & White's sensitivity (NeurIPS
  2024), which compares per-environment tuning with the best cross-environment setting and is 0 on
  one task by definition;
- **the ranking** of the tuned algorithms (and of the defaults) on the fresh seeds: feasible first,
  then by return, ties where the return intervals overlap;
- **the budgets as they ran**: each search's env steps over its completed trials, flagged where
  they are not equal (a failed trial shrinks its algorithm's budget).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from lac_rllib.constrained.metrics import EPISODE_COST, EPISODE_RETURN
from sweeps.reports import verdicts
from sweeps.reports.configurations import fmt_num

#: How the confirmation labels its groups: ``ALGO-tuned1`` (the search's best, then the next) and
#: ``ALGO-default`` (sweeps/tuned.py writes them, this report reads them).
TUNED, DEFAULT = "tuned", "default"


def winners_curse(search_return: float, fresh_return: float) -> float:
    """The winner's score on the search's seeds minus its score on fresh ones (> 0: it was flattered)."""
    return float(search_return - fresh_return)


def search_spread(summary: pd.DataFrame) -> dict:
    """How much return, cost and feasibility move across a search's configurations (``summary``: one
    row per configuration, sweeps/reports/report.py ``summarize``)."""
    done = summary[summary["n_seeds"] > 0]
    out = {"configurations": int(len(done))}
    for name, col, best in (("return", "return_mean", max), ("cost", "cost_mean", min)):
        x = pd.to_numeric(done[col], errors="coerce").dropna().to_numpy()
        if not x.size:
            out |= {f"{name}_best_minus_median": math.nan, f"{name}_iqr": math.nan}
            continue
        q1, med, q3 = np.quantile(x, [0.25, 0.5, 0.75])
        out |= {f"{name}_best_minus_median": float(best(x) - med), f"{name}_iqr": float(q3 - q1)}
    out["feasible_share"] = float(done["feasible"].astype(bool).mean()) if len(done) else math.nan
    return out


def _group(trials: pd.DataFrame, group: str) -> pd.DataFrame:
    return trials[trials["group"].astype(str) == group]


def _figures(rows: pd.DataFrame) -> dict:
    """A group's figures on the fresh seeds (finished seeds; the failed ones named)."""
    done = rows[rows["status"].eq("TERMINATED")]
    ret, cost = (pd.to_numeric(done[c], errors="coerce") for c in (EPISODE_RETURN, EPISODE_COST))
    ok = ret.notna() & cost.notna()
    limit = float(pd.to_numeric(rows["cost_limit"], errors="coerce").median()) if len(rows) else math.nan
    v = verdicts.verdict(ret, cost, limit)
    return {**v, "p_feasible": v["p_feasible"][0], "p_feasible_ci": v["p_feasible"], "limit": limit,
            "seeds": sorted(int(s) for s in done.loc[ok, "seed"]),
            "failed_seeds": sorted(int(s) for s in rows.loc[~rows.index.isin(done.index[ok]), "seed"]),
            "tasks": sorted(set(rows["task"].astype(str))),
            "by_seed": dict(zip(done.loc[ok, "seed"].astype(int), ret[ok].astype(float)))}


def paired_gap(tuned: dict, default: dict) -> tuple[float, float, float, int]:
    """(mean tuned − default over the seeds both finished, low, high, pairs): the paired t-interval."""
    common = sorted(set(tuned["by_seed"]) & set(default["by_seed"]))
    a = [tuned["by_seed"][s] for s in common]
    b = [default["by_seed"][s] for s in common]
    return (*verdicts.paired_difference_interval(a, b), len(common))


def _ranked(figures: dict) -> tuple[list[str], list[int]]:
    names = list(figures)
    table = pd.DataFrame([{"feasible": f["feasible"], "return_mean": f["return"][0], "return_low": f["return"][1],
                           "return_high": f["return"][2], "n_feasible": f["n_feasible"], "n_seeds": f["n_seeds"],
                           "violation": f["violation"]} for f in figures.values()])
    return names, (verdicts.rank_table(table).tolist() if len(table) else [])


def rank(figures: dict) -> str:
    """Algorithms as the report ranks them (``a > b = c``): sweeps/reports/verdicts.py."""
    return verdicts.ordered_with_ties(*_ranked(figures))


def budgets_ran(searched: dict) -> dict:
    """Per algorithm: its search's completed trials and their env steps (the planned steps per trial
    × completed trials), and whether the algorithms' are equal."""
    per = {}
    for algo, (trials, _summary, steps) in searched.items():
        done = int(trials["status"].eq("TERMINATED").sum()) if len(trials) else 0
        per[algo] = {"completed": done, "planned": int(len(trials)), "env_steps": done * int(steps)}
    equal = len({v["env_steps"] for v in per.values()}) <= 1
    return {"algorithms": per, "equal": equal}


def comparison(searched: dict, winners: dict, confirmation: pd.DataFrame) -> dict:
    """Per environment and algorithm: its default and tuned figures on the fresh seeds, the paired gap
    and P(improvement), whether tuning improved it, the winner's curse, its search's spread; both
    rankings per environment; the budgets as they ran. ``searched``: algo → (trials, summary, env
    steps per trial)."""
    per = {}
    for algo, tops in winners.items():
        tuned = _figures(_group(confirmation, f"{algo}-{TUNED}1"))
        default = _figures(_group(confirmation, f"{algo}-{DEFAULT}"))
        apart = tuned["tasks"] != default["tasks"]
        gap = (math.nan, math.nan, math.nan, 0) if apart else paired_gap(tuned, default)
        per[algo] = {"tuned": tuned, "default": default, "winner": tops[0], "gap": gap[:3], "pairs": gap[3],
                     "environment": ", ".join(tuned["tasks"]), "apart": apart,
                     "improved": bool(tuned["feasible"] and not apart and np.isfinite(gap[1]) and gap[1] > 0),
                     "p_improvement": verdicts.probability_of_improvement(list(tuned["by_seed"].values()),
                                                                          list(default["by_seed"].values())),
                     "curse": winners_curse(tops[0]["search"]["return_mean"], tuned["return"][0]),
                     "spread": search_spread(searched[algo][1])}
    environments = {}
    for algo, v in per.items():
        environments.setdefault(v["environment"], []).append(algo)
    ranks = {env: {"tuned": rank({a: per[a]["tuned"] for a in algos}),
                   "default": rank({a: per[a]["default"] for a in algos})} for env, algos in environments.items()}
    for r in ranks.values():
        r["changed"] = r["tuned"] != r["default"]
    return {"algorithms": per, "rankings": ranks, "budgets": budgets_ran(searched)}


def _ci(t: tuple) -> str:
    point, lo, hi = t
    if point is None or (isinstance(point, float) and math.isnan(point)):
        return "–"
    return fmt_num(point) + ("" if math.isnan(lo) else f" [{fmt_num(lo)}, {fmt_num(hi)}]")


def _seeds_cell(f: dict) -> str:
    return f"{f['n_seeds']}" + (f" (failed: {', '.join(map(str, f['failed_seeds']))})" if f["failed_seeds"] else "")


def markdown(tp, comp: dict) -> str:
    """The report as Markdown (the confirmation's parent run: tuned/report.md)."""
    t = tp.sweep.tune
    first = next(iter(tp.searches.values()))
    n, seeds, steps = first.sweep.num_samples, len(first.seeds), first.timesteps
    fresh = sorted({s for v in comp["algorithms"].values() for s in v["tuned"]["seeds"] + v["default"]["seeds"]})
    m = verdicts.METHODS
    budget = (f"{n} {t.searcher.upper()} samples × {seeds} seeds × {steps:,} env steps; each one's best" if
              t.searcher != "pbt" else f"a population of {seeds} members (PBT, one seed each) × {steps:,} env steps; "
              "each one's best member's schedule")
    lines = [f"## Tuned comparison `{tp.name}` on `{tp.task}`", "",
             f"Every algorithm searched over its own space at the same planned budget: {budget} and its default then "
             f"rerun on {t.confirm_seeds} fresh seeds ({', '.join(map(str, fresh))}).", "",
             f"Intervals: return and cost, {m['mean']}; the gap, {m['paired']}; P(feasible), {m['proportion']}. "
             f"Feasible: ≥ {verdicts.FEASIBLE_SHARE:.0%} of the seeds within the limit. Improved: tuned is feasible "
             "and the paired gap's interval lies above 0.", ""]
    b = comp["budgets"]
    ran = "; ".join(f"{a} {v['completed']}/{v['planned']} trials, {v['env_steps']:,} env steps"
                    for a, v in b["algorithms"].items())
    lines += [f"Budgets as they ran: {ran}" + ("." if b["equal"] else
                                                ". **Unequal: a failed trial shrank a search; the comparison is "
                                                "not at equal budgets.**"), ""]
    for env, r in comp["rankings"].items():
        algos = [a for a, v in comp["algorithms"].items() if v["environment"] == env]
        lines += [f"### `{env}`" if len(comp["rankings"]) > 1 else "",
                  "| algorithm | default return | default cost | seeds | feasible | tuned return | tuned cost | seeds "
                  "| feasible | gap tuned − default (paired) | P(improvement) | improved | winner's curse |",
                  "|---" * 13 + "|"]
        for algo in algos:
            v = comp["algorithms"][algo]
            d, tu = v["default"], v["tuned"]
            gap = "– (tuned and default ran in different environments)" if v["apart"] else _ci(v["gap"])
            lines.append(f"| {algo} | {_ci(d['return'])} | {_ci(d['cost'])} | {_seeds_cell(d)} | "
                         f"{d['n_feasible']}/{d['n_seeds']} | {_ci(tu['return'])} | {_ci(tu['cost'])} | "
                         f"{_seeds_cell(tu)} | {tu['n_feasible']}/{tu['n_seeds']} | {gap} | "
                         f"{fmt_num(v['p_improvement'])} | {'yes' if v['improved'] else 'no'} | "
                         f"{fmt_num(v['curse'])} |")
        changed = "tuning changed it" if r["changed"] else "tuning did not change it"
        lines += ["", f"**Ranking on the fresh seeds** (feasible first, then by return; `=`: intervals overlap): "
                      f"tuned {r['tuned']}; defaults {r['default']}: {changed}.", ""]
    lines += ["Winner's curse: the winner's mean return on the search's seeds minus on the fresh ones. Search "
              "spread: over the search's configurations on this one task (not a sensitivity across tasks).", "",
              "| algorithm | tuned configuration | search return [95%] | configurations | return: best − median, IQR | "
              "cost: best − median, IQR | feasible configurations |", "|---|---|---|---|---|---|---|"]
    for algo, v in comp["algorithms"].items():
        w, s = v["winner"], v["spread"]
        fields = ", ".join(f"{k}={f'{x:.3g}' if isinstance(x, float) else x}" for k, x in w["fields"].items())
        if w.get("schedule"):  # a PBT winner: its schedule (sweeps/pbt.py)
            fields = " → ".join(f"from {step['at']:,}: " + ", ".join(
                f"{k}={f'{x:.3g}' if isinstance(x, float) else x}" for k, x in step["set"].items())
                for step in w["schedule"])
        search = (w["search"]["return_mean"], *(_nan(w["search"].get(k)) for k in ("return_mean_ci_low",
                                                                                     "return_mean_ci_high")))
        lines.append(f"| {algo} | {fields or '(its default)'}{'' if w['feasible'] else ' (none feasible: least cost)'}"
                     f" | {_ci(search)} | {s['configurations']} | {fmt_num(s['return_best_minus_median'])}, "
                     f"{fmt_num(s['return_iqr'])} | {fmt_num(s['cost_best_minus_median'])}, {fmt_num(s['cost_iqr'])} | "
                     f"{fmt_num(s['feasible_share'])} |")
    return "\n".join(lines) + "\n"


def _nan(v) -> float:
    return math.nan if v is None else float(v)
