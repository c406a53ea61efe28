"""Learning curves of LAC (and of the baselines: ``algo=``) against the paper's numbers: the check
for any change that can alter what the agent learns (defaults, numerics, sampling).

    python benchmarks/fidelity.py --task SafetyPointGoal1-v0 --seeds 2 --timesteps 500000 \\
        --variant new --variant "old:langevin_grad_clip=None,nu_max_adaptive=False" \\
        --out docs/fidelity/pointgoal1

Each (variant, seed) is one ``lac-train`` run (a subprocess, niced, on ``--cpus`` CPUs: one by
default, two for ``lac-train --cpus 2``'s two env runners and learner threads), at most
``--parallel`` at a time (default: the machine's CPUs over ``--cpus``). A variant is ``NAME`` or
``NAME:field=value,...`` on top of the defaults and ``--set`` (``algo=ppo_lag`` or ``algo=sac_lag``
among them trains that baseline). Every run writes ``runs/<variant>/seed<k>/progress.jsonl``
one line per iteration and a checkpoint every ``--checkpoint-every`` iterations, and the report is rebuilt every
``--report-every`` seconds while runs go, so a run stopped mid-way (the machine gone, Ctrl-C) leaves
curves up to its last iteration; ``--resume`` continues such runs from their checkpoints (the same
command plus ``--resume``) and ``--report-only`` rebuilds the report from what is on disk. The
report (in ``--out``):

- ``curves.png``: return, cost (the limit drawn), ν and the chain's at-bound fraction against
  env steps, one colour per variant, one line style per seed;
- ``curves.csv``: every iteration of every run;
- ``table.md``: per variant, the mean over the final 10% of each run's env steps, then mean ± std
  over seeds, beside the paper's number for the task (docs/spec.md §7, docs/fidelity/README.md) and,
  for Safety-Gymnasium PointGoal1, OmniSafe's published SACLag/PPOLag (and the published figures of
  the baselines the variants run). Runs are compared at equal budget: every curve is cut at the
  smallest env-step count all runs reached; a published figure is the source's at that budget where
  it has one (OmniSafe's at 500k, 1M and 2.5M are read from its curves, ± the reading's tolerance),
  else its final one, its env steps named.

The commands a report shows (each run's ``command.txt`` and table.md's "Commands:" block) name the
run directory with the run root as a placeholder, ``RUN_DIR/<out dir name>/runs/<variant>/seed<k>``:
``RUN_DIR`` stands for the parent of ``--out``, so ``--out /data/fidelity-runs/pointgoal1`` writes
``--output RUN_DIR/pointgoal1/runs/new/seed0`` and no machine's paths reach the docs. The runs
themselves get the real path. Commands of included earlier reports (``--include-curves``) whose
``--output`` is an old absolute path are written the same way.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# Published figures: reward / cost (mean ± std), with the budget they were reached at.
PAPER = {  # the paper's Table 1-2, LAC after 2.5M steps (docs/spec.md §7)
    "SafetyPointGoal1-v0": ((14.20, 3.35), (22.21, 3.03)),
    "SafetyCarGoal1-v0": ((24.01, 2.21), (22.15, 4.71)),
    "SafetyPointButton1-v0": ((2.45, 1.36), (21.11, 6.74)),
    "SafetyCarButton1-v0": ((1.50, 1.44), (16.54, 13.83)),
    "focops/AntVelocity-v0": ((1940.71, 16.31), (103.04, 0.12)),
    "focops/SwimmerVelocity-v0": ((34.56, 4.94), (24.45, 1.30)),
    "focops/HumanoidVelocity-v0": ((5023.27, 107.99), (20.12, 0.58)),
    "focops/HumanoidCircle-v0": ((925.03, 111.95), (49.57, 1.16)),
}
#: OmniSafe's figures (sweeps/reports/published.yaml, cost limit 25) shown on a task whatever the variants
#: run, by the names the table prints (published.yaml's ``algorithms``): each at the runs' budget
#: where it has one there, else its final.
OMNISAFE = {"SafetyPointGoal1-v0": ("SAC-Lag", "PPO-L")}
#: OmniSafe's unconstrained SAC (its off-policy table, 3e6 steps), shown beside them: (label, return, cost).
UNCONSTRAINED_SAC = {"SafetyPointGoal1-v0": ("unconstrained SAC (OmniSafe), 3M steps", 27.04, 67.57)}
#: OmniSafe's unconstrained on-policy rows (10M steps, its on-policy table), shown beside a run of
#: the Lagrangian algorithm named (as sweeps/reports/published.yaml names it) with its multiplier pinned at 0.
UNCONSTRAINED = {"SafetyPointGoal1-v0": {"TRPO-L": ("unconstrained TRPO (OmniSafe), 10M steps", 27.20, 45.88),
                                         "PPO-L": ("unconstrained PPO (OmniSafe), 10M steps", 25.44, 55.72)}}
CURVE_KEYS = ("env_steps", "episode_return", "episode_cost", "cost_limit", "nu", "nu_max",
              "langevin_at_bound", "langevin_clip_fraction", "langevin_grad_norm", "actor_std_mean",
              "time_s")
TAIL = 0.10  # the final 10% of the env steps
RAY_STARTUP_S = 120  # a run is niced this long after its start (its Ray is up by then)


def split_algo(pairs: list[str]) -> tuple[str, list[str]]:
    """``["algo=sac_lag", "alpha=0.1"]`` → ("sac_lag", ["alpha=0.1"]): a variant's algorithm (LAC
    unless it names one) and its fields."""
    from lac_rllib.algorithms.registry import ALGO_FIELD, DEFAULT_ALGO, check_algo

    algos = [p.partition("=")[2].strip() for p in pairs if p.partition("=")[0].strip() == ALGO_FIELD]
    rest = [p for p in pairs if p.partition("=")[0].strip() != ALGO_FIELD]
    return check_algo(algos[-1] if algos else DEFAULT_ALGO), rest


def parse_variant(text: str, common: list[str] = ()) -> tuple[str, list[str]]:
    """``"old:a=1,b=None"`` → ("old", ["a=1", "b=None"]); ``algo=ppo_lag`` among them trains that
    baseline. The sets (and the ``--set`` ones, ``common``) are checked by lac-train's parser."""
    from lac_rllib.algorithms.registry import parse_sets

    name, _, sets = text.partition(":")
    pairs = [p.strip() for p in sets.split(",") if p.strip()]
    if not name or "/" in name:
        raise ValueError(f"--variant {text!r}: expected NAME or NAME:field=value,...")
    algo, fields = split_algo([*common, *pairs])
    parse_sets(algo, fields)  # unknown fields fail here, before anything runs
    return name, pairs


def run_dir(out: Path, variant: str, seed: int) -> Path:
    return out / "runs" / variant / f"seed{seed}"


RUN_ROOT = "RUN_DIR"  # the parent of --out, as the written commands name it


def portable_output(path: str) -> str:
    """A run directory as the written commands name it: ``/any/root/NAME/runs/V/seedK`` (or a
    relative path that resolves to it) → ``RUN_DIR/NAME/runs/V/seedK``; already so: unchanged."""
    if path == RUN_ROOT or path.startswith(RUN_ROOT + "/"):
        return path
    return "/".join((RUN_ROOT, *Path(os.path.abspath(path)).parts[-4:]))  # NAME, runs, V, seedK


def portable_command(line: str) -> str:
    """``line`` (a lac-train command) with its ``--output`` directory written by :func:`portable_output`."""
    words = line.split()
    for i, word in enumerate(words[:-1]):
        if word == "--output":
            words[i + 1] = portable_output(words[i + 1])
    return " ".join(words)


def launch(out: Path, task: str, variant: str, pairs: list[str], seed: int, timesteps: int,
           resume: bool = False, checkpoint_every: int = 2, cpus: int = 1):
    from lac_rllib.algorithms.registry import DEFAULT_ALGO
    from lac_rllib.train import resumable_checkpoint

    d = run_dir(out, variant, seed)
    d.mkdir(parents=True, exist_ok=True)
    algo, pairs = split_algo(pairs)
    cmd = [sys.executable, "-m", "lac_rllib.train", "--task", task, "--seed", str(seed),
           "--timesteps", str(timesteps), "--output", str(d), "--checkpoint-every", str(checkpoint_every)]
    if algo != DEFAULT_ALGO:
        cmd += ["--algo", algo]
    if cpus != 1:
        cmd += ["--cpus", str(cpus)]  # lac-train's: N env runners and N learner threads
    if resume and resumable_checkpoint(str(d)):
        cmd.append("--resume")  # lac-train checks that the settings are the run's
    else:
        for name in ("progress.jsonl", "config.json"):
            (d / name).unlink(missing_ok=True)  # a fresh run, not mixed with an old one
    for p in pairs:
        cmd += ["--set", p]
    (d / "command.txt").write_text(portable_command(" ".join(["lac-train", *cmd[3:]]).replace(" --resume", "")) + "\n")
    log = open(d / "train.log", "a" if "--resume" in cmd else "w")
    # One OpenMP thread for every process of the run: its env runners inherit this, and two runners
    # of two threads each oversubscribe two cores (half the time in the kernel); the learner sets its
    # own threads (torch_threads, which --cpus sets).
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    # Started at normal priority: Ray gives its raylet a fixed 30 s to register, which a niced
    # start on a busy machine misses; the run is niced once Ray is up (lower_priority).
    return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=ROOT, start_new_session=True)


def lower_priority(proc, nice: int) -> None:
    """Nice a run and its session. With autogroup scheduling (Linux's default) CPU is shared
    between sessions first and niceness only counts inside one: a session at nice 10 would
    still take an equal share against interactive work, so the session's group is niced too."""
    try:
        os.setpriority(os.PRIO_PROCESS, proc.pid, nice)
        Path(f"/proc/{proc.pid}/autogroup").write_text(str(nice))
    except OSError:
        pass


def load_curves(out: Path, include: list[Path] = ()):
    """Every iteration of the runs under ``out/runs``, then the rows of each ``include``d curves.csv
    (an earlier report's, e.g. of runs whose directories are gone) for the
    (variant, seed) pairs not on disk: a run on disk wins over its committed curve."""
    import pandas as pd

    rows = []
    for progress in sorted(out.glob("runs/*/seed*/progress.jsonl")):
        variant, seed = progress.parent.parent.name, int(progress.parent.name[4:])
        for line in progress.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                rows.append({"variant": variant, "seed": seed, "iteration": r["iteration"],
                             **{k: r.get(k, math.nan) for k in CURVE_KEYS}})
    df = pd.DataFrame(rows, columns=["variant", "seed", "iteration", *CURVE_KEYS])
    for csv in include:
        earlier = pd.read_csv(csv)
        missing = set(earlier.columns) ^ set(df.columns)
        if missing:
            raise ValueError(f"{csv}: not a curves.csv of this benchmark (columns {sorted(missing)} differ)")
        on_disk = set(zip(df["variant"], df["seed"]))
        keep = [(v, s) not in on_disk for v, s in zip(earlier["variant"], earlier["seed"])]
        df = pd.concat([df, earlier[keep]], ignore_index=True) if any(keep) else df
    return df


def earlier_commands(include: list[Path], runs: list[tuple[str, int]]) -> list[str]:
    """The commands of ``runs`` (variant, seed) as the earlier reports beside the included
    curves.csv files wrote them (their table.md's command block: the line whose output ends in
    runs/<variant>/seed<k>), their run directories written as :func:`portable_output` writes them."""
    wanted = tuple(f"/runs/{v}/seed{s}" for v, s in runs)
    found = []
    for csv in include:
        table = Path(csv).with_name("table.md")
        for line in table.read_text().splitlines() if table.exists() else []:
            if "--output" in line and line.split("--output", 1)[1].split()[0].endswith(wanted):
                found.append(portable_command(line.strip()))
    return list(dict.fromkeys(found))


def _fmt(mean: float, std: float | None) -> str:
    if mean is None or (isinstance(mean, float) and math.isnan(mean)):
        return "–"
    return f"{mean:.2f}" if std is None or math.isnan(std) else f"{mean:.2f} ± {std:.2f}"


def variant_algos(commands: list[str]) -> dict[str, tuple[str, bool]]:
    """variant → (its algorithm, whether it pins the multiplier at 0: ``lagrangian_lr=0.0`` and
    ``nu_init=0.0``), read from the runs' commands (``--output .../runs/<variant>/seed<k>``)."""
    from lac_rllib.algorithms.registry import DEFAULT_ALGO

    out = {}
    for line in commands:
        words = line.split()
        if "--output" not in words:
            continue
        variant = Path(words[words.index("--output") + 1]).parent.name
        algo = words[words.index("--algo") + 1] if "--algo" in words else DEFAULT_ALGO
        out[variant] = (algo, "lagrangian_lr=0.0" in words and "nu_init=0.0" in words)
    return out


def figure_row(name: str, f, budget: int | None) -> str:
    """A published figure (sweeps/reports/published.py's Figure) as a table row named ``name``: beside runs
    compared at ``budget`` env steps, its reading there (read from the source's curve, ± the
    reading's tolerance) where it has one, else its final figure, each named with its steps."""
    from sweeps.reports.table import steps_text

    r = f.at(budget)
    if r is None:
        return f"| {name}, {steps_text(f.steps)} steps | | {_fmt(*f.return_)} | {_fmt(*f.cost)} | | | |"
    cost = "–" if r.cost is None else f"{r.cost:g} (read ±{r.tolerance.cost:g})"
    return (f"| {name}, {steps_text(r.steps)} steps, read from a curve | | {r.return_:g} (read "
            f"±{r.tolerance.return_:g}) | {cost} | | | |")


def published_figures(task: str, variants: dict, shown=(), always: tuple[str, ...] = ()) -> list[tuple]:
    """(row name, figure) of the published figures (sweeps/reports/published.yaml: the paper's and OmniSafe's)
    of OmniSafe's ``always`` algorithms and of the algorithms the variants run (``variants``:
    :func:`variant_algos`), those whose name is not among ``shown``."""
    from lac_rllib.algorithms.registry import DEFAULT_ALGO
    from sweeps.reports.published import ROWS, published

    pub, out = published(), {}
    run = dict.fromkeys(a for a, pinned in variants.values() if a != DEFAULT_ALGO and not pinned)
    for algo, rows in [*((a, ("omnisafe",)) for a in always), *((a, tuple(ROWS)) for a in run)]:
        for row in rows:
            f, name = pub.find(row, task, algo), f"{ROWS[row]} {pub.algorithms.get(algo, algo)}"
            if f and name not in shown:
                out.setdefault(name, f)
    return list(out.items())


def published_rows(task: str, variants: dict, shown: list[str], budget: int | None = None) -> list[str]:
    """Table rows (:func:`figure_row`, at ``budget``) of :func:`published_figures` of the algorithms
    the variants run, those not already ``shown`` (row labels, ``"OmniSafe PPO-L, 10M steps"``);
    OmniSafe's unconstrained row beside a variant that pins the multiplier at 0."""
    from sweeps.reports.published import published

    pub = published()
    lines = [figure_row(name, f, budget) for name, f in
             published_figures(task, variants, [n.split(",")[0] for n in shown])]
    for algo, pinned in variants.values():
        entry = UNCONSTRAINED.get(task, {}).get(pub.algorithms.get(algo, algo))
        if pinned and entry:
            lines.append(f"| {entry[0]} | | {_fmt(entry[1], None)} | {_fmt(entry[2], None)} | | | |")
    return list(dict.fromkeys(lines))


def final_table(df, task: str, order: list[str], compare_at: int | None = None,
                variants: dict | None = None) -> tuple[str, int]:
    """Markdown table of the final 10% at the common budget; returns (markdown, common steps).

    The budget is the fewest env steps any run reached, or ``compare_at``: runs short of it are
    left out of the table and named under it."""
    reached = df.groupby(["variant", "seed"])["env_steps"].max()
    common = int(compare_at or reached.min())
    short = [f"{v} s{s_} ({int(n):,})" for (v, s_), n in reached.items() if n < common]
    df = df[df.set_index(["variant", "seed"]).index.map(lambda k: reached[k] >= common)]
    cut = df[df["env_steps"] <= common]
    how = "the fewest any run reached" if not compare_at else "--compare-at"
    lines = [f"Compared at {common:,} env steps ({how}); each run's score is the mean "
             f"over its iterations in the final {TAIL:.0%} of that budget (env steps > {int(common * (1 - TAIL)):,}),"
             " then mean ± std over seeds. Return and cost are means over the episodes completed in an iteration.",
             "", "| configuration | seeds | return | cost | ν | chain end points at a bound | per-seed return / cost |",
             "|---|---|---|---|---|---|---|"]
    for variant in order:
        runs = cut[cut["variant"] == variant]
        if runs.empty:
            continue
        per_seed = []
        for seed, run in runs.groupby("seed"):
            tail = run[run["env_steps"] > common * (1 - TAIL)]
            per_seed.append((seed, tail["episode_return"].mean(), tail["episode_cost"].mean(), tail["nu"].mean(),
                             tail["langevin_at_bound"].mean()))
        import numpy as np

        cols = np.array([p[1:] for p in per_seed], dtype=float)
        mean, std = cols.mean(0), cols.std(0, ddof=1) if len(cols) > 1 else [math.nan] * 4
        seeds = ", ".join(f"s{p[0]}: {p[1]:.2f} / {p[2]:.1f}" for p in per_seed)
        lines.append(f"| {variant} | {len(per_seed)} | {_fmt(mean[0], std[0])} | {_fmt(mean[1], std[1])} | "
                     f"{_fmt(mean[2], std[2])} | {_fmt(mean[3], std[3])} | {seeds} |")
    limit = float(df["cost_limit"].iloc[0])
    if task in PAPER:
        (r, rs), (c, cs) = PAPER[task]
        lines.append(f"| paper LAC, 2.5M steps | | {_fmt(r, rs)} | {_fmt(c, cs)} | | | |")
    from sweeps.reports.published import published

    pub = published()
    names = {shown: algo for algo, shown in pub.algorithms.items()}
    always = published_figures(task, {}, always=tuple(names[n] for n in OMNISAFE.get(task, ())))
    lines += [figure_row(name, f, common) for name, f in always]
    if task in UNCONSTRAINED_SAC:
        name, r, c = UNCONSTRAINED_SAC[task]
        lines.append(f"| {name} | | {_fmt(r, None)} | {_fmt(c, None)} | | | |")
    lines += published_rows(task, variants or {}, [name for name, _ in always], common)
    lines += ["", f"Cost limit {limit:g}."]
    images = dict.fromkeys(pub.sources[f.source].curves[f.curve]
                           for _, f in always + published_figures(task, variants or {}) if f.at(common))
    if images:
        lines += ["", "Read from a curve: the height of the source's mean curve at that budget in "
                  + ", ".join(f"[{Path(url).name}]({url})" for url in images)
                  + " (sweeps/reports/published.yaml), ± the reading's tolerance, not a std over seeds."]
    if short:
        lines += ["", f"Not yet at {common:,} steps, so not in the table: {', '.join(short)}."]
    return "\n".join(lines), common


def plot(df, task: str, order: list[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [("episode_return", "episode return"), ("episode_cost", "episode cost"), ("nu", "ν"),
              ("langevin_at_bound", "chain end points at a bound")]
    # A panel no run has values for (the chain's, in a report of baselines only) is left out.
    panels = [(k, t) for k, t in panels if k in df and df[k].notna().any()]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.4))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    styles = ["-", "--", ":", "-."]
    for ax, (key, title) in zip(axes, panels):
        for vi, variant in enumerate(order):
            for si, (seed, run) in enumerate(df[df["variant"] == variant].groupby("seed")):
                ax.plot(run["env_steps"] / 1e3, run[key], styles[si % len(styles)], color=colours[vi % len(colours)],
                        lw=1.3, label=f"{variant} s{seed}")
        if key == "episode_cost":
            ax.axhline(float(df["cost_limit"].iloc[0]), color="k", lw=1, ls="--", label="cost limit")
        ax.set_title(title)
        ax.set_xlabel("env steps (k)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(task)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def report(out: Path, task: str, order: list[str], timesteps: int | None, compare_at: int | None = None,
           include: list[Path] = ()) -> str | None:
    df = load_curves(out, include)
    if df.empty:
        return None
    order = [*order, *sorted(set(df["variant"]) - set(order))]  # runs of other invocations too
    df.to_csv(out / "curves.csv", index=False)
    plot(df, task, order, out / "curves.png")
    commands = sorted(portable_command(p.read_text().strip()) for p in out.glob("runs/*/seed*/command.txt"))
    reached = df.groupby(["variant", "seed"]).agg(steps=("env_steps", "max"), hours=("time_s", "max"))
    budget = "\n".join(f"- {v} seed {s}: {int(r.steps):,} env steps in {r.hours / 3600:.2f} h"
                       for (v, s), r in reached.iterrows())
    disk = {(p.parent.parent.name, int(p.parent.name[4:])) for p in out.glob("runs/*/seed*/progress.jsonl")}
    earlier = sorted({(v, int(s_)) for v, s_ in zip(df["variant"], df["seed"])} - disk)
    if earlier:
        # The included files named as the commands name runs: under the run root, no machine's path.
        named = ", ".join(f"{RUN_ROOT}/{Path(p).resolve().parent.name}/{Path(p).name}" for p in include)
        budget += ("\n\nFrom earlier reports' curves (" + named + "), their run "
                   "directories gone: " + ", ".join(f"{v} seed {s_}" for v, s_ in earlier) + ".")
        commands += sorted(earlier_commands(include, earlier))
    table, common = final_table(df, task, order, compare_at, variant_algos(commands))
    text = (f"# {task}: learning curves\n\n"
            f"Budget per run: {f'{timesteps:,} env steps' if timesteps else 'see the commands'}; reached:\n{budget}\n\n"
            f"{table}\n\n![curves](curves.png)\n\nCommands:\n\n```\n" + "\n".join(commands) + "\n```\n")
    (out / "table.md").write_text(text)
    return text


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--task", required=True)
    parser.add_argument("--seeds", type=int, default=2, help="seeds 0..N-1 per variant")
    parser.add_argument("--seed-list", default=None, help="explicit comma-separated seeds (overrides --seeds)")
    parser.add_argument("--timesteps", type=int, default=500_000)
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE", help="for every variant")
    parser.add_argument("--variant", action="append", default=[], metavar="NAME[:F=V,...]",
                        help="a configuration to run (repeatable; default: one variant 'defaults')")
    parser.add_argument("--out", required=True, help="report directory (e.g. docs/fidelity/pointgoal1)")
    parser.add_argument("--parallel", type=int, default=None, help="runs at a time (default: CPUs / --cpus)")
    parser.add_argument("--cpus", type=int, default=1,
                        help="CPUs per run (lac-train --cpus: env runners and learner threads); --parallel "
                             "counts runs, so --parallel 1 --cpus 2 fills two cores")
    parser.add_argument("--nice", type=int, default=10, help="niceness of the runs (Ray's workers use 15)")
    parser.add_argument("--checkpoint-every", type=int, default=2,
                        help="iterations between a run's checkpoints (what --resume continues from)")
    parser.add_argument("--report-every", type=float, default=120.0, help="seconds between report rebuilds")
    parser.add_argument("--report-only", action="store_true", help="rebuild the report from runs on disk")
    parser.add_argument("--compare-at", type=int, default=None, metavar="STEPS",
                        help="score runs at this many env steps (default: the fewest any run reached); "
                             "runs short of it are listed, not scored")
    parser.add_argument("--include-curves", action="append", default=[], metavar="CSV", type=Path,
                        help="an earlier report's curves.csv: its runs that are not on disk join the report "
                             "(their run directories are gone)")
    parser.add_argument("--resume", action="store_true",
                        help="continue runs from their latest checkpoint (lac-train --resume); "
                             "runs at the budget are skipped")
    args = parser.parse_args(argv)
    out = Path(args.out)
    try:
        from lac_rllib.tasks import get_task

        get_task(args.task)
        variants = [parse_variant(v, args.set) for v in args.variant or ["defaults"]]
        if len({v for v, _ in variants}) != len(variants):
            raise ValueError("--variant names must be distinct")
        seeds = [int(s) for s in args.seed_list.split(",")] if args.seed_list else list(range(args.seeds))
        missing = [str(c) for c in args.include_curves if not Path(c).is_file()]
        if missing:
            raise ValueError(f"--include-curves {', '.join(missing)}: no such file; "
                             "accepted: an earlier report's curves.csv")
        if args.parallel is None:
            args.parallel = max(1, (os.cpu_count() or 1) // max(args.cpus, 1))
        if not seeds or args.timesteps < 1 or args.parallel < 1 or args.checkpoint_every < 1 or args.cpus < 1:
            raise ValueError("need at least one seed, --timesteps, --parallel, --checkpoint-every and --cpus >= 1")
    except ValueError as e:
        parser.exit(2, f"fidelity: error: {e}\n")
    order = [v for v, _ in variants]
    out.mkdir(parents=True, exist_ok=True)
    if args.report_only:
        print(report(out, args.task, order, None, args.compare_at, args.include_curves) or "no runs on disk")
        return 0
    queue = [(v, pairs, s) for s in seeds for v, pairs in variants]  # seed-major: every variant gets seed 0 first
    if args.resume:
        done = load_curves(out)
        if not done.empty:
            reached = done.groupby(["variant", "seed"])["env_steps"].max()
            queue = [q for q in queue if reached.get((q[0], q[2]), 0) < args.timesteps]
    running: list = []
    last = time.time()
    print(f"{len(queue)} runs of {args.timesteps:,} env steps on {args.task}, {args.parallel} at a time -> {out}")
    try:
        while queue or running:
            while queue and len(running) < args.parallel:
                v, pairs, s = queue.pop(0)
                running.append((v, s, launch(out, args.task, v, [*args.set, *pairs], s, args.timesteps, args.resume,
                                             args.checkpoint_every, args.cpus), time.time()))
                print(f"started {v} seed {s}", flush=True)
            time.sleep(5)
            for item in running:
                if len(item) == 4 and time.time() - item[3] > RAY_STARTUP_S:
                    lower_priority(item[2], args.nice)
                    running[running.index(item)] = item[:3]
            for item in [r for r in running if r[2].poll() is not None]:
                running.remove(item)
                print(f"finished {item[0]} seed {item[1]} (exit {item[2].returncode})", flush=True)
            if time.time() - last > args.report_every:
                report(out, args.task, order, args.timesteps, include=args.include_curves)
                last = time.time()
    except KeyboardInterrupt:
        for item in running:
            os.killpg(item[2].pid, 15)
    print(report(out, args.task, order, args.timesteps, include=args.include_curves) or "no runs produced a curve")
    return 0


if __name__ == "__main__":
    sys.exit(main())
