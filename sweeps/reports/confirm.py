"""Confirmation: a sweep's K best feasible configurations rerun on seeds it never saw.

A search's winner is the best of many noisy draws, so its score is biased upward (the winner's
curse; rl-baselines3-zoo#314, #323: tuned scores that do not reproduce). ``--confirm-top K``
ranks the finished sweep's mean-feasible configurations by the **lower bound** of their return
interval (a configuration backed by consistent seeds beats a lucky one), reruns the top K beside
the default configuration on fresh seeds (after the sweep's largest) at the same or a larger
budget, as a second sweep with its own parent run, and says of each whether it held up: its
confirmed mean return is at least the lower end of its search interval, and it stays within the
limit.
"""

from __future__ import annotations

import math

import pandas as pd

#: A confirmation group's name: top1 … topK, beside "default" and "baseline-ALGO".
TOP, DEFAULT_GROUP, BASELINE = "top", "default", "baseline-"


def varied_fields(sweep) -> list[str]:
    """The fields a sweep varies between its configurations: a search's distributions, or every
    grid field and group ``set`` field of its groups (the rest is the sweep's ``set``, kept)."""
    if sweep.search is not None:
        return list(sweep.search)
    groups = [*(sweep.groups or {}).values(), *(g for at in sweep.groups_at for g in at.groups.values())]
    return list(dict.fromkeys(f for g in groups for f in (*g.grid, *g.set)))


def rank(summary: pd.DataFrame, k: int) -> pd.DataFrame:
    """The ``k`` best mean-feasible configurations that are not the default, by the lower end of
    their return interval (then the mean: one seed has no interval)."""
    ok = summary[summary["mean_feasible"].astype(bool) & summary["return_mean"].notna() & ~summary["is_default"]]
    key = ok["return_mean_ci_low"].fillna(-math.inf)
    return ok.assign(_low=key).sort_values(["_low", "return_mean"], ascending=False).head(k).drop(columns="_low")


def winners(summary: pd.DataFrame, fields_of: dict[str, dict], k: int) -> list[dict]:
    """The top ``k`` configurations (:func:`rank`) as {label, fields, search: its statistics}.
    ``fields_of`` maps a configuration's ``config`` label to its varied fields' values."""
    out = []
    for i, r in enumerate(rank(summary, k).to_dict("records"), 1):
        out.append({"group": f"{TOP}{i}", "config": r["config"], "fields": fields_of[r["config"]],
                    "search": {c: _plain(r.get(c)) for c in ("return_mean", "return_mean_ci_low", "return_mean_ci_high",
                                                             "cost_mean", "n_seeds")}})
    return out


def confirmation_file(sweep, top: list[dict], seeds: int, budget, name: str, baselines: tuple[str, ...] = ()):
    """The confirmation sweep: one group per winner (its fields as the group's ``set``), the
    default and the ``baselines`` the sweep ran (each algorithm's own defaults, group
    ``baseline-ALGO``), on ``seeds`` seeds after the sweep's largest, at ``budget``."""
    from sweeps.sweep_file import SweepFile

    groups = {w["group"]: {"set": w["fields"]} for w in top} | {DEFAULT_GROUP: {}}
    groups |= {f"{BASELINE}{algo}": {"set": {"algo": algo}} for algo in baselines}
    data = sweep.model_dump(exclude_none=True, exclude={"search", "grid", "groups", "groups_at", "searcher",
                                                          "num_samples", "name", "seeds", "budget"})
    return SweepFile.model_validate({**data, "groups": groups, "budget": budget, "name": name,
                                     "seeds": {"count": seeds, "start": max(sweep.seed_list()) + 1},
                                     "searcher": "grid", "description": f"confirmation of {sweep.name}"})


def held_up(search: dict, confirmed: dict) -> bool:
    """A winner held up if its confirmed mean return reaches the lower end of its search interval
    (its mean where it had one seed) and its confirmed mean cost stays within the limit."""
    low = search.get("return_mean_ci_low")
    low = search["return_mean"] if low is None or (isinstance(low, float) and math.isnan(low)) else low
    return bool(confirmed.get("mean_feasible")) and confirmed.get("return_mean", -math.inf) >= low


def confirmation_markdown(top: list[dict], summary: pd.DataFrame) -> str:
    """The confirmation's verdict, one row per winner: its search interval against its confirmed one."""
    from sweeps.reports.configurations import ci as _ci
    from sweeps.reports.configurations import fmt_num as _fmt_num

    by_group = {r["group"]: r for r in summary.to_dict("records")}
    lines = ["**Confirmation on fresh seeds** (the search's best by the lower end of the return interval):", "",
             "| winner | configuration | search return [95% CI] | confirmed return [95% CI] | confirmed cost "
             "[95% CI] | feasible seeds | held up |", "|---|---|---:|---:|---:|---:|---|"]
    for w in top:
        s, c = w["search"], by_group.get(w["group"], {})
        verdict = ("yes" if held_up(s, c) else "no") if c.get("n_seeds") else "– (no seed finished)"
        lines.append("| " + " | ".join([
            w["group"], w["config"].replace("|", "\\|"),
            _ci(s["return_mean"], s["return_mean_ci_low"], s["return_mean_ci_high"]),
            _ci(c.get("return_mean"), c.get("return_mean_ci_low"), c.get("return_mean_ci_high")) if c else "–",
            _ci(c.get("cost_mean"), c.get("cost_mean_ci_low"), c.get("cost_mean_ci_high")) if c else "–",
            f"{round(c['feasible_fraction'] * c['n_seeds'])}/{c['n_seeds']}" if c.get("n_seeds") else "–",
            verdict]) + " |")
    default = by_group.get(DEFAULT_GROUP)
    if default and default.get("n_seeds"):
        lines += ["", f"The default on the same seeds: return {_fmt_num(default['return_mean'])}, cost "
                      f"{_fmt_num(default['cost_mean'])}."]
    return "\n".join(lines) + "\n"


def _plain(v):
    return v.item() if hasattr(v, "item") else v
