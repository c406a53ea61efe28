"""The report across a ladder of cost limits, against the fixed-multiplier frontier.

Spoor et al. ("Lagrangian methods in safe RL", 2026) show that a verdict at one cost limit can
reverse at another, and that automatic multiplier updates are never compared with the empirical
optimum: the return-cost front traced by runs at fixed multipliers. Per task, from the trials of a
ladder sweep (``cost_limits``: each configuration × limit × seed a trial) and, where it ran, its
frontier (``frontier``: an algorithm at fixed ν values, group ``frontier``), every verdict decided
by sweeps/reports/verdicts.py:

- the frontier's points: per fixed ν, its seeds' mean return (with its interval) and mean cost;
  R*(b): the ν of the best return among those feasible within b on half the frontier's seeds,
  measured on the other half (so choosing the best of noisy points does not flatter it); which
  algorithm's frontier it is;
- per configuration and limit: its return with its interval, its feasible seeds and P(feasible)
  (Wilson), feasible or not by the one rule; its regret R*(b) − R(b) with its interval where it is
  feasible, its mean violation where it is not (an infeasible row has no regret); its rank at b,
  ties where the return intervals overlap;
- where the ranking changes between consecutive limits, and each configuration's wins: first
  (ties included) at k of the n limits;
- the worst and the mean regret over the ladder, defined for configurations feasible at every
  limit: by them a confirmation may choose its winners, never an infeasible one.

Tasks are never ranked together: every table is per task.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from lac_rllib.constrained.metrics import COST_LIMIT, EPISODE_COST, EPISODE_RETURN
from sweeps.reports import verdicts
from sweeps.reports.configurations import fmt_num, fmt_value, is_na, metric_name, prepared, text_column

#: The group of a sweep's fixed-multiplier runs, and the field they fix.
FRONTIER_GROUP, FRONTIER_FIELD = "frontier", "nu_fixed"
#: A configuration across the ladder (its limit aside).
CONFIG_KEYS = ["task", "group", "param", "value", "algo"]
#: How confirmation may pick its winners over a ladder (sweeps/reports/confirm.py).
REGRET_CHOICES = ("worst", "mean")


def _scored(trials: pd.DataFrame) -> pd.DataFrame:
    df, failed = prepared(trials)
    df = df[~failed & ~df["status"].astype(str).eq("STOPPED")].copy()
    for col in (EPISODE_RETURN, EPISODE_COST, COST_LIMIT):
        df[col] = pd.to_numeric(df[col], errors="coerce")
    df["algo"] = text_column(df, "algo")
    df["value"] = df["value"].map(lambda v: "" if is_na(v) else fmt_value(v))
    return df


def frontier_seeds(trials: pd.DataFrame) -> pd.DataFrame:
    """The frontier's runs, one row per seed: task, algo, nu, seed, return, cost."""
    df = _scored(trials)
    df = df[df["group"].astype(str).eq(FRONTIER_GROUP)]
    out = pd.DataFrame({"task": df["task"], "algo": df["algo"], "nu": df["value"],
                        "seed": pd.to_numeric(df["seed"], errors="coerce") if "seed" in df else np.nan,
                        "return": df[EPISODE_RETURN], "cost": df[EPISODE_COST]})
    return out.reset_index(drop=True)


def frontier_points(trials: pd.DataFrame) -> pd.DataFrame:
    """Per task and fixed ν: seeds, mean return (with its interval) and mean cost."""
    rows = []
    for (task, algo, nu), g in frontier_seeds(trials).groupby(["task", "algo", "nu"], sort=False):
        ret, ret_low, ret_high = verdicts.mean_interval(g["return"])
        rows.append({"task": task, "algo": algo, "nu": nu, "n_seeds": len(g), "return_mean": ret,
                     "return_low": ret_low, "return_high": ret_high, "cost_mean": g["cost"].mean()})
    return pd.DataFrame(rows, columns=["task", "algo", "nu", "n_seeds", "return_mean", "return_low", "return_high",
                                       "cost_mean"])


def best_within(seeds: pd.DataFrame, limit: float) -> dict:
    """R*(b) of one task's frontier (:func:`frontier_seeds` rows): sweeps/reports/verdicts.py."""
    star = verdicts.best_within(seeds, limit)
    star["r_star_algo"] = ", ".join(sorted(set(seeds["algo"]))) if len(seeds) else ""
    return star


def ladder_table(trials: pd.DataFrame) -> pd.DataFrame:
    """One row per task, configuration and limit (the frontier's runs aside): the module
    docstring's figures."""
    df = _scored(trials)
    seeds = frontier_seeds(trials)
    df = df[~df["group"].astype(str).eq(FRONTIER_GROUP)]
    rows = []
    for key, g in df.groupby([*CONFIG_KEYS, COST_LIMIT], sort=False):
        limit = float(key[-1])
        v = verdicts.verdict(g[EPISODE_RETURN], g[EPISODE_COST], limit)
        star = best_within(seeds[seeds["task"] == key[0]], limit)
        reg = verdicts.regret(star, g[EPISODE_RETURN], v["feasible"])
        rows.append({**dict(zip([*CONFIG_KEYS, COST_LIMIT], key)), "n_seeds": v["n_seeds"],
                     "return_mean": v["return"][0], "return_low": v["return"][1], "return_high": v["return"][2],
                     "cost_mean": v["cost"][0], "n_feasible": v["n_feasible"], "p_feasible": v["p_feasible"][0],
                     "p_feasible_low": v["p_feasible"][1], "p_feasible_high": v["p_feasible"][2],
                     "feasible": v["feasible"], "violation": v["violation"], "r_star": star["r_star"],
                     "r_star_nu": star["r_star_nu"], "r_star_seeds": len(star["r_star_scores"]),
                     "r_star_algo": star["r_star_algo"], "r_star_why": star["why"],
                     "regret": reg[0], "regret_low": reg[1], "regret_high": reg[2]})
    table = pd.DataFrame(rows)
    if table.empty:
        return table
    table["rank"] = 0
    for _, g in table.groupby(["task", COST_LIMIT], sort=False):
        table.loc[g.index, "rank"] = verdicts.rank_table(g)
    table = table.assign(_label=table.apply(label, axis=1))
    return (table.sort_values(["task", COST_LIMIT, "rank", "_label"], kind="stable").drop(columns="_label")
            .reset_index(drop=True))


def label(row) -> str:
    """A configuration's name across the ladder: its algorithm, group and swept value."""
    parts = [str(row["algo"]), "" if str(row["group"]) in ("", "paper", "compare") else str(row["group"])]
    if str(row["param"]) and str(row["param"]) != "algo":
        parts.append(f"{row['param']}={row['value']}")
    return " ".join(p for p in parts if p)


def wins(table: pd.DataFrame) -> pd.DataFrame:
    """Per task and configuration: first (ties included) at k of the n limits, feasible at how many,
    and the worst and mean regret over the ladder: defined only where the configuration is feasible
    at every limit and R*(b) exists at each (``why`` says which limit it fails where not)."""
    rows = []
    for (task, name), g in table.assign(name=table.apply(label, axis=1)).groupby(["task", "name"], sort=False):
        regret = g["regret"].to_numpy(dtype=float)
        over = [fmt_value(b) for b, ok in zip(g[COST_LIMIT], g["feasible"]) if not ok]
        no_star = [fmt_value(b) for b, r in zip(g[COST_LIMIT], g["r_star"]) if not np.isfinite(r)]
        why = (f"infeasible at b = {', '.join(over)}" if over else
               f"no R*(b) at b = {', '.join(no_star)}" if no_star else "")
        defined = not why and len(regret) and np.isfinite(regret).all()
        rows.append({"task": task, "configuration": name, "wins": int((g["rank"] == 1).sum()),
                     "feasible_at": int(g["feasible"].astype(bool).sum()), "limits": g[COST_LIMIT].nunique(),
                     "worst_regret": float(np.max(regret)) if defined else math.nan,
                     "mean_regret": float(np.mean(regret)) if defined else math.nan, "why": why})
    return pd.DataFrame(rows, columns=["task", "configuration", "wins", "feasible_at", "limits", "worst_regret",
                                       "mean_regret", "why"])


def flat_frontier(table: pd.DataFrame) -> list[str]:
    """One line per pair of consecutive limits whose R*(b) is the same fixed ν: there the frontier's
    grid has no point between them, so the two rungs test the same yardstick (add ν values whose
    cost falls between the limits)."""
    rungs = table.drop_duplicates(COST_LIMIT).sort_values(COST_LIMIT)
    lines = []
    for (b0, nu0), (b1, nu1) in zip(zip(rungs[COST_LIMIT], rungs["r_star_nu"]),
                                    list(zip(rungs[COST_LIMIT], rungs["r_star_nu"]))[1:]):
        if nu0 != "" and nu0 == nu1:
            lines.append(f"- R*(b) is the same point (ν = {nu0}) at b = {fmt_value(b0)} and {fmt_value(b1)}: the "
                         "frontier has no ν between them")
    return lines


def ranking_changes(table: pd.DataFrame) -> list[str]:
    """One line per pair of consecutive limits of a task whose ranking differs (ties as ``=``)."""
    lines = []
    for task, t in table.groupby("task", sort=False):
        orders = [(b, verdicts.ordered_with_ties([label(r) for _, r in g.iterrows()], g["rank"].tolist()))
                  for b, g in t.groupby(COST_LIMIT, sort=True)]
        for (b0, o0), (b1, o1) in zip(orders, orders[1:]):
            if o0 != o1:
                lines.append(f"{task}: b = {fmt_value(b0)} → {fmt_value(b1)}: {o0} becomes {o1}")
    return lines


def configs_by_label(trials: pd.DataFrame) -> dict[str, list[str]]:
    """Each configuration's name across the ladder (:func:`label`) → its trials' ``config`` labels
    (one per limit), the frontier's runs aside: how a name :func:`choose` returns finds its fields."""
    df = _scored(trials)
    df = df[~df["group"].astype(str).eq(FRONTIER_GROUP)]
    out: dict[str, list[str]] = {}
    for name, config in zip(df.apply(label, axis=1), df["config"].astype(str)):
        out.setdefault(name, [])
        if config not in out[name]:
            out[name].append(config)
    return out


def choose(table: pd.DataFrame, k: int, by: str = "worst") -> tuple[list[str], list[str]]:
    """The ``k`` configurations of least ``by`` regret over the ladder (``by``: worst | mean), per task,
    among those feasible at every limit; and one line per task where none qualifies (never a silent
    empty choice)."""
    if by not in REGRET_CHOICES:
        raise ValueError(f"regret choice {by!r}; accepted: {' | '.join(REGRET_CHOICES)}")
    chosen, notes = [], []
    for task, g in wins(table).groupby("task", sort=False):
        ok = g.dropna(subset=[f"{by}_regret"])
        chosen += list(ok.nsmallest(k, f"{by}_regret")["configuration"])
        if ok.empty:
            reasons = "; ".join(f"{r.configuration}: {r.why}" for r in g.itertuples())
            notes.append(f"{task}: no configuration has a {by} regret to choose by ({reasons})")
    return chosen, notes


def _ci(point, low, high) -> str:
    if is_na(point):
        return "–"
    return fmt_num(point) if is_na(low) else f"{fmt_num(point)} [{fmt_num(low)}, {fmt_num(high)}]"


def _regret_cell(r) -> str:
    if not r["feasible"]:
        return f"infeasible (over by {fmt_num(r['violation'])})"
    if is_na(r["regret"]):
        return "– (no R*)"
    return _ci(r["regret"], r["regret_low"], r["regret_high"])


def _rank_cell(r, ranks) -> str:
    return f"{int(r['rank'])}=" if (ranks == r["rank"]).sum() > 1 else str(int(r["rank"]))


def methods_lines() -> list[str]:
    """What each interval of the ladder's tables is (sweeps/reports/verdicts.py)."""
    m = verdicts.METHODS
    return [f"Feasible: at least {verdicts.FEASIBLE_SHARE:.0%} of a row's seeds end with cost ≤ b (the "
            "objective's rule, per seed); ranks: feasible rows by return, then the others by feasible seeds and "
            "violation; `=`: a tie (return intervals overlap).",
            f"Intervals: return, {m['mean']}; P(feasible), {m['proportion']}; regret, {m['regret']}."]


def ladder_markdown(table: pd.DataFrame) -> str:
    """The per-limit tables, the wins and worst regrets, and where the ranking changes."""
    if table.empty:
        return ""
    out = ["## Across the ladder of cost limits", "", *methods_lines(), ""]
    for task, t in table.groupby("task", sort=False):
        algo = next((a for a in t["r_star_algo"] if a), "")
        whose = "No frontier ran: no R*(b), no regret."
        if algo:
            whose = (f"R*(b): {algo}'s fixed-ν frontier (its ν chosen on half its seeds, R* measured on the rest); "
                     "for the other algorithms' rows it is that algorithm's frontier, not their own.")
        out += [f"### {task}", "", whose, "", "| b | rank | configuration | seeds | return [95%] | cost | feasible "
                "seeds | P(feasible) [Wilson] | R*(b) (ν, seeds) | regret [95%] |", "|---" * 10 + "|"]
        for _, r in t.iterrows():
            ranks = t.loc[t[COST_LIMIT] == r[COST_LIMIT], "rank"]
            star = (f"– ({r['r_star_why']})" if is_na(r["r_star"]) else
                    f"{fmt_num(r['r_star'])} (ν={r['r_star_nu']}, {int(r['r_star_seeds'])})")
            out.append(f"| {fmt_value(r[COST_LIMIT])} | {_rank_cell(r, ranks)} | {label(r)} | {int(r['n_seeds'])} | "
                       f"{_ci(r['return_mean'], r['return_low'], r['return_high'])} | {fmt_num(r['cost_mean'])} | "
                       f"{int(r['n_feasible'])}/{int(r['n_seeds'])} | "
                       f"{_ci(r['p_feasible'], r['p_feasible_low'], r['p_feasible_high'])} | {star} | "
                       f"{_regret_cell(r)} |")
        w = wins(t)
        out += ["", "| configuration | first at | feasible at | worst regret | mean regret |", "|---|---|---|---|---|"]
        out += [f"| {r.configuration} | {r.wins} of {r.limits} | {r.feasible_at} of {r.limits} | "
                f"{fmt_num(r.worst_regret) if r.why == '' else '– (' + r.why + ')'} | {fmt_num(r.mean_regret)} |"
                for r in w.itertuples()]
        changes = [f"- ranking changes at {c.split(': ', 1)[1]}" for c in ranking_changes(t)]
        out += ["", *(changes or ["- the ranking is the same at every limit"]), *flat_frontier(t), ""]
    return "\n".join(out)


def ladder_png(table: pd.DataFrame, points: pd.DataFrame, path) -> str | None:
    """Return and cost against b per configuration (one column per task), R*(b) and the line
    cost = b drawn."""
    if table.empty:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tasks = list(dict.fromkeys(table["task"]))
    fig, axes = plt.subplots(2, len(tasks), figsize=(5 * len(tasks), 7), squeeze=False)
    for j, task in enumerate(tasks):
        t = table[table["task"] == task]
        limits = np.sort(t[COST_LIMIT].unique())
        for name, g in t.assign(name=t.apply(label, axis=1)).groupby("name", sort=False):
            g = g.sort_values(COST_LIMIT)
            axes[0, j].errorbar(g[COST_LIMIT], g["return_mean"], yerr=[g["return_mean"] - g["return_low"],
                                g["return_high"] - g["return_mean"]], marker="o", capsize=3, label=name)
            axes[1, j].plot(g[COST_LIMIT], g["cost_mean"], marker="o", label=name)
        star = [best_within(points[points["task"] == task], b)["r_star"] for b in limits]  # per-seed points
        if np.isfinite(star).any():
            axes[0, j].step(limits, star, where="post", color="black", linestyle="--", label="R*(b), fixed ν")
        axes[1, j].plot(limits, limits, color="grey", linestyle=":", label="cost = b")
        axes[0, j].set(title=task, ylabel="return")
        axes[1, j].set(xlabel="cost limit b", ylabel="cost")
        axes[0, j].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return str(path)


def applies(trials: pd.DataFrame) -> bool:
    """Whether a sweep's trials hold a ladder (several limits on one task) or a frontier."""
    if trials.empty:
        return False
    limits = pd.to_numeric(trials[COST_LIMIT], errors="coerce")
    frontier = trials["group"].astype(str).eq(FRONTIER_GROUP)
    several = limits[~frontier].groupby(trials.loc[~frontier, "task"]).nunique().gt(1).any()
    return bool(frontier.any() or several)


def parent_metrics(table: pd.DataFrame) -> dict[str, float]:
    """What the parent run carries per configuration: its wins over the ladder and its worst regret
    (MLflow's runs table sorts sweeps by them); the task leads the name where there are several."""
    w = wins(table)
    several = w["task"].nunique() > 1
    out = {}
    for r in w.itertuples():
        name = metric_name(f"{r.task}/{r.configuration}" if several else r.configuration)
        out[f"ladder_wins/{name}"] = float(r.wins)
        if math.isfinite(r.worst_regret):
            out[f"ladder_worst_regret/{name}"] = float(r.worst_regret)
    return out


def write_ladder_report(trials: pd.DataFrame, out_dir) -> tuple[str, dict[str, float]]:
    """``ladder.csv``, ``ladder.md`` and ``ladder.png`` (the figures, the tables, the plot) and the
    frontier's points in ``frontier_points.csv``; returns the markdown and the parent's metrics."""
    from pathlib import Path

    out = Path(out_dir)
    table = ladder_table(trials)
    frontier_points(trials).to_csv(out / "frontier_points.csv", index=False)
    table.to_csv(out / "ladder.csv", index=False)
    text = ladder_markdown(table)
    (out / "ladder.md").write_text(text + "\n", encoding="utf-8")
    ladder_png(table, frontier_seeds(trials), out / "ladder.png")
    return text, parent_metrics(table) if not table.empty else {}


def by_limit(trials: pd.DataFrame) -> list[tuple[str, pd.DataFrame]]:
    """The trials a table is made of, per limit of a ladder: [(``table-bB``, that limit's trials,
    the frontier's left out)], so the paper's layout (one configuration per task and algorithm)
    holds at each; without a ladder [("", trials)]."""
    frontier = trials["group"].astype(str).eq(FRONTIER_GROUP)
    limits = pd.to_numeric(trials[COST_LIMIT], errors="coerce")
    if not applies(trials) or limits[~frontier].nunique() < 2:
        return [("", trials[~frontier] if frontier.any() else trials)]
    return [(f"table-b{fmt_value(b)}", trials[~frontier & (limits == b)]) for b in sorted(limits[~frontier].unique())]
