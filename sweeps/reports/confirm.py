"""Confirmation: a sweep's K best feasible configurations rerun on seeds it never saw.

A search's winner is the best of many noisy draws, so its score is biased upward (the winner's
curse; rl-baselines3-zoo#314, #323: tuned scores that do not reproduce). ``--confirm-top K``
ranks the finished sweep's feasible configurations by the **lower bound** of their return
interval (a configuration backed by consistent seeds beats a lucky one), reruns the top K beside
the default configuration on fresh seeds at the same or a larger budget, as a second sweep with
its own parent run (built by sweeps/followup.py), and says of each whether it held up: its
confirmed mean return is at least the lower end of its search interval, and it stays within the
limit.

Over a ladder of cost limits (``cost_limits``), a configuration is one across the ladder: the winners
are distinct configurations, each rerun at every limit and judged at each. With the frontier beside
the ladder, ``--confirm-by worst-regret | mean-regret`` picks them by their worst or mean regret
R*(b) − R(b) over the ladder instead (sweeps/reports/ladder.py, Spoor et al. 2026): the
configuration closest to the fixed-multiplier optimum at its worst limit, or on average.
"""

from __future__ import annotations

import math

import pandas as pd

from sweeps.reports import verdicts

#: A confirmation group's name: top1 … topK, beside "default" and "baseline-ALGO".
TOP, DEFAULT_GROUP, BASELINE = "top", "default", "baseline-"
#: How ``--confirm-by`` picks the winners: the lower end of the return interval, or the worst or
#: mean regret over a ladder (ladder.REGRET_CHOICES).
BY_RETURN, CONFIRM_BY = "return", ("return", "worst-regret", "mean-regret")


def varied_fields(sweep) -> list[str]:
    """The fields a sweep varies between its configurations: a search's distributions, or every
    grid field and group ``set`` field of its groups (the rest is the sweep's ``set``, kept)."""
    if sweep.search is not None:
        return list(sweep.search)
    groups = [*(sweep.groups or {}).values(), *(g for at in sweep.groups_at for g in at.groups.values())]
    return list(dict.fromkeys(f for g in groups for f in (*g.grid, *g.set)))


def rank(summary: pd.DataFrame, k: int) -> pd.DataFrame:
    """The ``k`` best feasible configurations that are not the default, each row as ranked
    (sweeps/reports/verdicts.py ``choose_winners``)."""
    return verdicts.choose_winners(summary, k)


def winners(summary: pd.DataFrame, fields_of: dict[str, dict], k: int) -> list[dict]:
    """The top ``k`` configurations (verdicts.choose_winners) as {group, config, fields, search: its
    statistics}. ``fields_of`` maps a configuration's ``config`` label to its varied fields' values;
    a configuration that ranks at several limits of a ladder is one winner (its best row)."""
    return [{"group": f"{TOP}{i}", "config": r["config"], "fields": fields_of.get(r["config"], {}), "search": _stats(r)}
            for i, r in enumerate(verdicts.choose_winners(summary, k, fields_of).to_dict("records"), 1)]


def regret_winners(trials: pd.DataFrame, fields_of: dict[str, dict], k: int, by: str) -> list[dict]:
    """``--confirm-by worst-regret | mean-regret``: the ``k`` configurations of least worst (or
    mean) regret over the ladder (ladder.choose), each with its regret and its figures per limit."""
    from sweeps.reports import ladder

    table = ladder.ladder_table(trials)
    if table.empty:
        return []
    summary = ladder.wins(table).set_index("configuration")
    configs = ladder.configs_by_label(trials)
    out = []
    chosen, notes = ladder.choose(table, k, by.removesuffix("-regret"))
    for note in notes:  # said, never a silent empty confirmation
        print(f"confirmation: {note}", flush=True)
    for name in chosen:
        config = configs[name][0]
        out.append({"group": f"{TOP}{len(out) + 1}", "config": config, "fields": fields_of.get(config, {}),
                    "search": {"worst_regret": _plain(summary.loc[name, "worst_regret"]),
                               "mean_regret": _plain(summary.loc[name, "mean_regret"])}, "by": by})
    return with_limits(out, trials, table)


def with_limits(top: list[dict], trials: pd.DataFrame, table: pd.DataFrame | None = None) -> list[dict]:
    """Over a ladder, each winner's name across it and its search figures at every limit
    (``by_limit``: limit → its return interval, cost and regret there), so the confirmation judges
    it at each; without a ladder ``top`` as it is."""
    from sweeps.reports import ladder

    if not ladder.applies(trials):
        return top
    table = ladder.ladder_table(trials) if table is None else table
    if table.empty or table["cost_limit"].nunique() < 2:
        return top
    name_of = {c: name for name, configs in ladder.configs_by_label(trials).items() for c in configs}
    names = table.apply(ladder.label, axis=1)
    for w in top:
        w["name"] = name_of.get(w["config"], w["config"])
        rows = table[names == w["name"]]
        w["by_limit"] = {float(r["cost_limit"]): {
            "return_mean": _plain(r["return_mean"]), "return_mean_ci_low": _plain(r["return_low"]),
            "return_mean_ci_high": _plain(r["return_high"]), "cost_mean": _plain(r["cost_mean"]),
            "regret": _plain(r["regret"])} for r in rows.to_dict("records")}
    return top


def _stats(r: dict) -> dict:
    return {c: _plain(r.get(c)) for c in ("return_mean", "return_mean_ci_low", "return_mean_ci_high", "cost_mean",
                                          "n_seeds")}


def held_up(search: dict, confirmed: dict) -> bool:
    """A winner held up if its confirmed mean return reaches the lower end of its search interval
    (its mean where it had one seed) and its confirmed mean cost stays within the limit."""
    low = search.get("return_mean_ci_low")
    low = search["return_mean"] if low is None or (isinstance(low, float) and math.isnan(low)) else low
    return bool(confirmed.get("feasible")) and confirmed.get("return_mean", -math.inf) >= low


def confirmation_markdown(top: list[dict], summary: pd.DataFrame, trials: pd.DataFrame | None = None) -> str:
    """The confirmation's verdict, one row per winner (per winner and limit over a ladder): its
    search interval against its confirmed one; by regret, its worst and mean regret on both."""
    if any(w.get("by_limit") for w in top):
        return _ladder_markdown(top, summary, trials)
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


def _ladder_markdown(top: list[dict], summary: pd.DataFrame, trials: pd.DataFrame | None) -> str:
    """Over a ladder: each winner at each limit (held up there or not), and by regret its worst and
    mean regret on the search's seeds beside the fresh seeds' (against the confirmation's own frontier)."""
    from sweeps.reports import ladder
    from sweeps.reports.configurations import ci as _ci
    from sweeps.reports.configurations import fmt_num as _fmt_num
    from sweeps.reports.configurations import fmt_value

    by = top[0].get("by", BY_RETURN)
    at = {(r["group"], float(r["cost_limit"])): r for r in summary.to_dict("records") if not _na(r.get("cost_limit"))}
    how = "the lower end of the return interval" if by == BY_RETURN else f"their {by.replace('-', ' ')} over the ladder"
    lines = [f"**Confirmation on fresh seeds** across the ladder (the search's best by {how}):", "",
             "| winner | configuration | b | search return [95% CI] | confirmed return [95% CI] | confirmed cost | "
             "feasible seeds | held up |", "|---|---|---:|---:|---:|---:|---:|---|"]
    tally = {}
    for w in top:
        for b, s in sorted(w.get("by_limit", {}).items()):
            c = at.get((w["group"], b), {})
            ok = held_up(s, c) if c.get("n_seeds") else None
            tally.setdefault(w["group"], []).append(ok)
            lines.append("| " + " | ".join([
                w["group"], w.get("name", w["config"]).replace("|", "\\|"), fmt_value(b),
                _ci(s["return_mean"], s["return_mean_ci_low"], s["return_mean_ci_high"]),
                _ci(c.get("return_mean"), c.get("return_mean_ci_low"), c.get("return_mean_ci_high")) if c else "–",
                _fmt_num(c.get("cost_mean")) if c else "–",
                f"{round(c['feasible_fraction'] * c['n_seeds'])}/{c['n_seeds']}" if c.get("n_seeds") else "–",
                {True: "yes", False: "no", None: "–"}[ok]]) + " |")
    lines.append("")
    fresh = ladder.wins(ladder.ladder_table(trials)) if trials is not None and len(trials) else pd.DataFrame()
    fresh = {r.configuration: r for r in fresh.itertuples()} if len(fresh) else {}
    for w in top:
        oks = tally.get(w["group"], [])
        line = f"- {w['group']} held up at {sum(o is True for o in oks)} of {len(oks)} limits"
        if by != BY_RETURN:
            f = fresh.get(_confirmed_name(w))
            line += (f"; worst regret {_fmt_num(w['search']['worst_regret'])} on the search's seeds, "
                     f"{_fmt_num(f.worst_regret) if f is not None else '–'} on the fresh ones; mean regret "
                     f"{_fmt_num(w['search']['mean_regret'])}, {_fmt_num(f.mean_regret) if f is not None else '–'}")
        lines.append(line)
    return "\n".join(lines) + "\n"


def _confirmed_name(winner: dict) -> str:
    """A winner's name across the confirmation's ladder: its algorithm and group (ladder.label)."""
    from sweeps.reports.ladder import label

    algo = winner["fields"].get("algo") or winner.get("name", "").split(" ")[0]
    return label({"algo": algo, "group": winner["group"], "param": "", "value": ""})


def _na(v) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))


def _plain(v):
    return v.item() if hasattr(v, "item") else v
